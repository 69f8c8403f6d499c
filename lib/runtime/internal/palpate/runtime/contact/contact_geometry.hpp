#pragma once
/// @file
/// Closest points between a tool's tip (a sphere: a point with a radius; a
/// capsule: a segment with a radius) and a surface triangle, with the
/// barycentric weights of the point on the triangle (docs/tools.md, "Tip
/// contacts"). The tip penetrates the triangle exactly when the distance
/// between the two closest points is below its radius: a triangle is
/// convex, so its closest point to the tip's axis is its deepest point.
/// Internal to the runtime layer.

#include <array>

#include "palpate/core/eigen.hpp"

namespace palpate::detail {

/// A point of triangle (a, b, c): weights[0] a + weights[1] b + weights[2] c.
/// A weight is exactly 0 when the point lies on the opposite edge (two
/// zeros: on a vertex), so that points on a shared edge or vertex computed
/// from different triangles are the same point.
struct TrianglePoint {
  Eigen::Vector3d point;
  std::array<double, 3> weights;
};

/// The point of triangle (a, b, c) nearest to @p x (by Voronoi regions of
/// its vertices, edges and face).
TrianglePoint closest_on_triangle(const Eigen::Vector3d& x, const Eigen::Vector3d& a,
                                  const Eigen::Vector3d& b, const Eigen::Vector3d& c);

/// The closest pair between the segment start + s·axis, s ∈ [0, length]
/// (axis unit; length 0: a point) and triangle (a, b, c).
struct SegmentTrianglePair {
  Eigen::Vector3d on_segment;
  TrianglePoint on_triangle;
  double distance;  ///< ‖on_triangle − on_segment‖, m; 0 when the segment crosses the triangle
};
SegmentTrianglePair closest_segment_triangle(const Eigen::Vector3d& start,
                                             const Eigen::Vector3d& axis, double length,
                                             const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                             const Eigen::Vector3d& c);

}  // namespace palpate::detail
