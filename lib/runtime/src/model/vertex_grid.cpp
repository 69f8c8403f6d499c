#include "palpate/runtime/model/vertex_grid.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/runtime/model/grid_shape.hpp"

namespace palpate::detail {

VertexGrid::VertexGrid(std::span<const Eigen::Vector3d> points, double cell_m) {
  if (points.empty()) return;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (const auto& x : points) {
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  origin_ = lo;
  const Eigen::Vector3d extent = hi - lo;
  double cell = cell_m > 0 && std::isfinite(cell_m) ? cell_m : extent.maxCoeff();
  if (!(cell > 0)) cell = 1;  // every vertex at one place: one cell
  const GridShape shape = grid_shape(extent, cell);
  inverse_cell_ = shape.inverse_cell;
  dims_ = shape.dims;
  // Counting sort of the vertices by cell: each cell's ascending.
  begin_.assign(static_cast<std::size_t>(cell_count()) + 1, 0);
  for (const auto& x : points) ++begin_[flat(cell_of(x)) + 1];
  for (std::size_t c = 1; c < begin_.size(); ++c) begin_[c] += begin_[c - 1];
  vertices_.resize(points.size());
  std::vector<int> fill(begin_.begin(), begin_.end() - 1);
  for (std::size_t j = 0; j < points.size(); ++j)
    vertices_[static_cast<std::size_t>(fill[flat(cell_of(points[j]))]++)] = static_cast<int>(j);
}

std::array<int, 3> VertexGrid::cell_of(const Eigen::Vector3d& x) const {
  return grid_cell({inverse_cell_, dims_}, origin_, x);
}

std::span<const int> VertexGrid::vertices_in(const std::array<int, 3>& cell) const {
  const std::size_t c = flat(cell);
  return {vertices_.data() + begin_[c], static_cast<std::size_t>(begin_[c + 1] - begin_[c])};
}

}  // namespace palpate::detail
