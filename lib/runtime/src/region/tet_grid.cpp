#include "palpate/runtime/region/tet_grid.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/runtime/model/grid_shape.hpp"

namespace palpate::detail {

TetGrid::TetGrid(const Eigen::MatrixX3d& rest_m, const Eigen::MatrixX4i& tetrahedra) {
  const Eigen::Index nt = tetrahedra.rows();
  if (nt == 0) return;
  // Bounding boxes of the tetrahedra, and of them all.
  std::vector<Eigen::Vector3d> lo(static_cast<std::size_t>(nt)), hi(lo.size());
  Eigen::Vector3d all_lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d all_hi = -all_lo;
  double mean_side = 0;
  for (Eigen::Index t = 0; t < nt; ++t) {
    Eigen::Vector3d a = rest_m.row(tetrahedra(t, 0)).transpose(), b = a;
    for (int k = 1; k < 4; ++k) {
      a = a.cwiseMin(rest_m.row(tetrahedra(t, k)).transpose());
      b = b.cwiseMax(rest_m.row(tetrahedra(t, k)).transpose());
    }
    lo[static_cast<std::size_t>(t)] = a;
    hi[static_cast<std::size_t>(t)] = b;
    all_lo = all_lo.cwiseMin(a);
    all_hi = all_hi.cwiseMax(b);
    mean_side += (b - a).maxCoeff() / static_cast<double>(nt);
  }
  origin_ = all_lo;
  upper_ = all_hi;
  const Eigen::Vector3d extent = all_hi - all_lo;
  double cell = mean_side > 0 ? mean_side : 1;
  const GridShape shape = grid_shape(extent, cell);
  inverse_cell_ = shape.inverse_cell;
  dims_ = shape.dims;

  // Counting sort of (cell, tetrahedron) by cell, tetrahedra ascending in each.
  const auto for_each_cell = [&](Eigen::Index t, auto&& f) {
    const Cell a = cell_of(lo[static_cast<std::size_t>(t)]);
    const Cell b = cell_of(hi[static_cast<std::size_t>(t)]);
    for (int z = a[2]; z <= b[2]; ++z)
      for (int y = a[1]; y <= b[1]; ++y)
        for (int x = a[0]; x <= b[0]; ++x) f(flat({x, y, z}));
  };
  begin_.assign(static_cast<std::size_t>(cell_count()) + 1, 0);
  for (Eigen::Index t = 0; t < nt; ++t) for_each_cell(t, [&](std::size_t c) { ++begin_[c + 1]; });
  for (std::size_t c = 1; c < begin_.size(); ++c) begin_[c] += begin_[c - 1];
  tets_.resize(static_cast<std::size_t>(begin_.back()));
  std::vector<int> fill(begin_.begin(), begin_.end() - 1);
  for (Eigen::Index t = 0; t < nt; ++t)
    for_each_cell(t, [&](std::size_t c) {
      tets_[static_cast<std::size_t>(fill[c]++)] = static_cast<int>(t);
    });
}

TetGrid::Cell TetGrid::cell_of(const Eigen::Vector3d& x) const {
  return grid_cell({inverse_cell_, dims_}, origin_, x);
}

std::span<const int> TetGrid::tetrahedra_in(const Cell& cell) const {
  const std::size_t c = flat(cell);
  return {tets_.data() + begin_[c], static_cast<std::size_t>(begin_[c + 1] - begin_[c])};
}

Eigen::Vector3d TetGrid::cell_centre(const Cell& cell) const {
  return origin_ + (Eigen::Vector3d(cell[0], cell[1], cell[2]) + Eigen::Vector3d::Constant(0.5)) /
                       inverse_cell_;
}

}  // namespace palpate::detail
