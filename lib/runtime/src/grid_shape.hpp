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

}  // namespace palpate::detail
