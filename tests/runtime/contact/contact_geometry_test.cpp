// Closest points between a tip's axis and a surface triangle (the tip
// contacts of docs/tools.md, "One tick") against brute force: a fine sampling
// of the triangle and the segment finds no closer pair.

#include "palpate/runtime/contact/contact_geometry.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>

namespace palpate::detail {
namespace {

using Eigen::Vector3d;

/// The smallest distance between sampled points of the segment and the
/// triangle (n × n barycentric grid, n segment samples): an upper bound of
/// the true distance, within the samples' spacing of it. Plain doubles in
/// the loop: its 23 million points are this test's time, and the sanitizer
/// build compiles the tests' own code unoptimized (docs/sanitizers.md).
double sampled_distance(const Vector3d& s0, const Vector3d& axis, double length, const Vector3d& a,
                        const Vector3d& b, const Vector3d& c, int n) {
  const Vector3d ab = b - a, ac = c - a;
  double best_squared = INFINITY;
  for (int k = 0; k <= (length > 0 ? n : 0); ++k) {
    const Vector3d x = s0 + (length > 0 ? length * k / n : 0.0) * axis;
    const double ax = a.x() - x.x(), ay = a.y() - x.y(), az = a.z() - x.z();
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const double u = static_cast<double>(i) / n, v = static_cast<double>(j) / n;
        const double dx = ax + ab.x() * u + ac.x() * v;
        const double dy = ay + ab.y() * u + ac.y() * v;
        const double dz = az + ab.z() * u + ac.z() * v;
        best_squared = std::min(best_squared, dx * dx + dy * dy + dz * dz);
      }
  }
  return std::sqrt(best_squared);
}

TEST(ContactGeometry, ClosestPairsAgreeWithBruteForce) {
  std::mt19937 random(17);
  std::uniform_real_distribution<double> unit(-1, 1);
  auto point = [&] { return Vector3d(unit(random), unit(random), unit(random)); };
  for (int trial = 0; trial < 300; ++trial) {
    const Vector3d a = point(), b = point(), c = point();
    const Vector3d s0 = 1.5 * point();
    const Vector3d axis = point().normalized();
    const double length = trial % 3 == 0 ? 0.0 : 1.5 * (1 + unit(random));
    const SegmentTrianglePair pair = closest_segment_triangle(s0, axis, length, a, b, c);
    // The pair is what it says: a point of the segment, a point of the triangle.
    const auto& w = pair.on_triangle.weights;
    EXPECT_NEAR(w[0] + w[1] + w[2], 1.0, 1e-12);
    for (double wi : w) EXPECT_GE(wi, -1e-12);
    EXPECT_LT((w[0] * a + w[1] * b + w[2] * c - pair.on_triangle.point).norm(), 1e-12);
    const double t = (pair.on_segment - s0).dot(axis);
    EXPECT_GE(t, -1e-12);
    EXPECT_LE(t, length + 1e-12);
    EXPECT_LT((s0 + t * axis - pair.on_segment).norm(), 1e-12);
    EXPECT_NEAR((pair.on_triangle.point - pair.on_segment).norm(), pair.distance, 1e-12);
    // And the closest: sampling (spacing ≤ 2/60 of the sides) finds nothing
    // closer, and gets within that spacing of it.
    const double sampled = sampled_distance(s0, axis, length, a, b, c, 60);
    EXPECT_LE(pair.distance, sampled + 1e-12) << "trial " << trial;
    EXPECT_GE(pair.distance, sampled - 0.12) << "trial " << trial;
  }
}

TEST(ContactGeometry, PointsOnEdgesAndVerticesHaveExactZeroWeights) {
  // The same edge point from the two triangles sharing the edge, and the
  // same vertex point from every triangle around it: weights exactly 0, so
  // that the contact engine keeps the point once and a vertex contact is a
  // vertex constraint.
  // Two triangles folded down along their shared edge b-c (a ridge); a
  // point above the ridge is nearest its middle from both.
  const Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0), d(1, 1, -1);
  const Vector3d above(0.6, 0.6, 1);
  const TrianglePoint p1 = closest_on_triangle(above, a, b, c);
  const TrianglePoint p2 = closest_on_triangle(above, b, d, c);
  EXPECT_EQ(p1.weights[0], 0.0);
  EXPECT_EQ(p2.weights[1], 0.0);
  EXPECT_LT((p1.point - Vector3d(0.5, 0.5, 0)).norm(), 1e-15);
  EXPECT_LT((p1.point - p2.point).norm(), 1e-15);
  const TrianglePoint v = closest_on_triangle(Vector3d(-0.3, -0.2, 0.4), a, b, c);
  EXPECT_EQ(v.weights[0], 1.0);
  EXPECT_EQ(v.weights[1], 0.0);
  EXPECT_EQ(v.weights[2], 0.0);
  // A segment through the face: distance 0, the crossing point.
  const SegmentTrianglePair through =
      closest_segment_triangle(Vector3d(0.2, 0.3, 1), Vector3d(0, 0, -1), 2, a, b, c);
  EXPECT_EQ(through.distance, 0.0);
  EXPECT_LT((through.on_triangle.point - Vector3d(0.2, 0.3, 0)).norm(), 1e-15);
}

}  // namespace
}  // namespace palpate::detail
