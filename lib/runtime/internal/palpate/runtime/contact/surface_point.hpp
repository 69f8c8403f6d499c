#pragma once
/// @file
/// A point of a drawn surface triangle, as barycentric weights on the
/// triangle's vertices that carry one (internal to the runtime): what a
/// tip's contact (TipCandidate, tip_contacts.hpp) and a point the jaws hold
/// (HeldPoint, jaw_grasp.hpp) have in common, and what the code that works
/// on "a point on a triangle" takes (its rows, its background displacement,
/// its rotation, the contact it becomes).

#include <Eigen/Core>
#include <array>

namespace palpate::detail {

/// A point p = Σ_i w_i x_i of a drawn triangle, on its `count` vertices of
/// non-zero weight (compliance vertices first, as in DrawnSurface; a vertex
/// from the model's compliance count on is fixed). A plain value: no
/// allocation.
struct SurfacePoint {
  int triangle = -1;                               ///< drawn triangle it lies on
  int count = 0;                                   ///< vertices with a non-zero weight, 1 to 3
  std::array<int, 3> vertices{};                   ///< drawn vertices (the first `count` hold)
  std::array<double, 3> weights{};                 ///< their barycentric weights, Σ = 1
  Eigen::Vector3d rest = Eigen::Vector3d::Zero();  ///< the point at rest, Σ w_i rest_i, m
};

}  // namespace palpate::detail
