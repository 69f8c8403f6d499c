#pragma once
// Private to palpate_runtime: the cells of a uniform grid over a box, shared
// by the grid of drawn vertices (vertex_grid.hpp) and of the region's
// tetrahedra (tet_grid.hpp).

#include <Eigen/Core>
#include <array>
#include <cmath>

namespace palpate::detail {

/// Cells of side 1 / inverse_cell over a box, dims along x, y, z.
struct GridShape {
  double inverse_cell = 1;
  std::array<int, 3> dims{1, 1, 1};
};

/// The grid of cells of side @p cell_m over a box of @p extent_m, the side
/// grown by 1.25 at a time until there are at most 2¹⁸ cells (memory stays
/// small whatever the box; a cell then holds more).
inline GridShape grid_shape(const Eigen::Vector3d& extent_m, double cell_m) {
  constexpr double kMaxCells = 1 << 18;
  const auto cells_for = [&](double side) {
    double count = 1;
    for (int k = 0; k < 3; ++k) count *= std::floor(extent_m[k] / side) + 1;
    return count;
  };
  while (cells_for(cell_m) > kMaxCells) cell_m *= 1.25;
  GridShape shape;
  shape.inverse_cell = 1 / cell_m;
  for (int k = 0; k < 3; ++k)
    shape.dims[static_cast<std::size_t>(k)] =
        static_cast<int>(std::floor(extent_m[k] * shape.inverse_cell)) + 1;
  return shape;
}

/// The cell of @p x in the grid of @p shape whose first cell starts at
/// @p origin_m: out-of-grid coordinates clamp to the nearest cell, a NaN to
/// the first (callers refuse non-finite input before or after).
inline std::array<int, 3> grid_cell(const GridShape& shape, const Eigen::Vector3d& origin_m,
                                    const Eigen::Vector3d& x) {
  std::array<int, 3> cell{};
  for (int k = 0; k < 3; ++k) {
    const double at = std::floor((x[k] - origin_m[k]) * shape.inverse_cell);
    const int last = shape.dims[static_cast<std::size_t>(k)] - 1;
    cell[static_cast<std::size_t>(k)] = at >= static_cast<double>(last) ? last
                                        : at > 0                        ? static_cast<int>(at)
                                                                        : 0;
  }
  return cell;
}

}  // namespace palpate::detail
