#pragma once
/// @file
/// The organ of the cut-region tests (cut_region_test, precompute_region_test):
/// a 0.1 × 0.06 × 0.05 m box of 6 × 4 × 4 cells, and its region at the far
/// end under the top face.

#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/mesh.hpp"
#include "support/test_meshes.hpp"

namespace palpate::testing::region_box {

inline constexpr int kNx = 6, kNy = 4, kNz = 4;
inline constexpr double kLx = 0.1, kLy = 0.06, kLz = 0.05;

inline TetMesh organ() { return box_mesh(kLx, kLy, kLz, kNx, kNy, kNz); }

/// The block of cells i ≥ 4, 1 ≤ j ≤ 2, k ≥ 2: at the free end, under the top face.
inline RegionSpec far_top_box() {
  return RegionSpec::box({kLx * 4 / kNx, kLy * 1 / kNy, kLz * 2 / kNz}, {kLx, kLy * 3 / kNy, kLz});
}

}  // namespace palpate::testing::region_box
