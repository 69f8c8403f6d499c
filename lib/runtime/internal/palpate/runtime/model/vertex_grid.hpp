#pragma once
/// @file
/// The drawn surface's vertices at rest in a uniform grid of cubes, so that
/// the vertices near a tool are found by the cells around it rather than by
/// a scan of every vertex (ToolContactEngine's candidates). Internal to the
/// runtime layer; immutable once built, allocation-free to query.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate::detail {

class VertexGrid {
 public:
  VertexGrid() = default;
  /// @p points: the vertices at rest, m; @p cell_m: the cells' side, m
  /// (enlarged to keep at most 2^18 cells; the engine gives 1.5 × the
  /// mean edge of the surface, a few vertices per cell on it).
  VertexGrid(std::span<const Eigen::Vector3d> points, double cell_m);

  /// The cell holding @p x, each index clamped to the grid: monotone in
  /// each coordinate, so the cells between those of a box's corners hold
  /// every vertex in the box.
  std::array<int, 3> cell_of(const Eigen::Vector3d& x) const;
  /// The vertices in @p cell (indices into the points given), ascending.
  std::span<const int> vertices_in(const std::array<int, 3>& cell) const;
  std::int64_t cell_count() const { return std::int64_t{dims_[0]} * dims_[1] * dims_[2]; }

 private:
  std::size_t flat(const std::array<int, 3>& cell) const {
    return static_cast<std::size_t>(cell[0]) +
           static_cast<std::size_t>(dims_[0]) *
               (static_cast<std::size_t>(cell[1]) +
                static_cast<std::size_t>(dims_[1]) * static_cast<std::size_t>(cell[2]));
  }
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double inverse_cell_ = 1;  // 1 / the cell's side, 1/m
  std::array<int, 3> dims_{1, 1, 1};
  std::vector<int> begin_{0, 0};  // per cell, into vertices_; one more at the end
  std::vector<int> vertices_;
};

}  // namespace palpate::detail
