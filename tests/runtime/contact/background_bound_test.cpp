// The background loads' bound on how far they move the surface
// (lib/runtime/src/background_loads, DeformedSurface::far_from): a
// triangle left out as far from a segment must be farther than the reach
// under the loads as they are now, whether it was judged by the loads'
// energy or by its corners' last known u_b and the bound on the change
// since (with the loads' displacements given, and from the forces alone);
// and the known u_b must leave out more than the energy alone does. And
// u_b itself, read from the columns two backgrounds share, is G f.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cstdio>
#include <random>
#include <vector>

#include "palpate/runtime/contact/background_loads.hpp"
#include "palpate/runtime/contact/contact_geometry.hpp"
#include "palpate/runtime/contact/deformed_surface.hpp"
#include "support/box_model_suite.hpp"

namespace palpate::detail {
namespace {

using Eigen::Vector3d;
using Eigen::VectorXd;

class BackgroundBound : public testing::BoxModelSuite<4> {
 protected:
  // u_b = G f at every compliance vertex, summed here.
  static Vector3d exact_u(int v, const std::vector<int>& index, const VectorXd& f) {
    Vector3d u = Vector3d::Zero();
    for (std::size_t j = 0; j < index.size(); ++j)
      u += model().G_block(v, index[j]) * f.segment<3>(3 * static_cast<Eigen::Index>(j));
    return u;
  }

  // Runs a background that wanders for 40 sets, some vertices' u_b computed
  // on the way, then checks every triangle against random segments.
  // @returns the triangles left out, over all segments.
  static long check(bool with_displacements, bool compute_on_the_way) {
    const SurfaceModel& m = model();
    const int n = m.compliance_vertex_count();
    std::vector<int> index;
    for (int v = 0; v < n; v += 7) index.push_back(v);  // spread over the box
    const auto loads = static_cast<Eigen::Index>(index.size());
    DeformedSurface surface(m, nullptr);
    LoadColumns columns;
    columns.reserve(m, static_cast<int>(index.size()));
    BackgroundLoads background;
    background.reserve(m, static_cast<int>(index.size()), columns);
    surface.set_background(&background);
    const int no_index = 0;
    const double no_force[3] = {0, 0, 0};
    surface.set_loads(0, &no_index, no_force, 0);
    std::mt19937 rng(with_displacements ? 5 : 6);
    std::normal_distribution<double> normal;
    VectorXd f(3 * loads), u(3 * loads);
    for (auto& e : f) e = 0.3 * normal(rng);
    std::uniform_int_distribution<int> vertex(0, n - 1);
    for (int set = 0; set < 40; ++set) {
      // A wandering push (N), then a jump: the u_b known from before it are
      // millimetres off, which only the bound on the change covers.
      for (auto& e : f) e += (set == 39 ? 0.5 : 0.02) * normal(rng);
      for (Eigen::Index j = 0; j < loads; ++j)
        u.segment<3>(3 * j) = exact_u(index[static_cast<std::size_t>(j)], index, f);
      if (with_displacements)
        background.set(index, {f.data(), static_cast<std::size_t>(f.size())},
                       {u.data(), static_cast<std::size_t>(u.size())});
      else
        background.set(index, {f.data(), static_cast<std::size_t>(f.size())}, f.dot(u));
      surface.next_epoch();
      if (compute_on_the_way && set < 39)
        for (int k = 0; k < n / 4; ++k) surface.deformed(vertex(rng));
    }
    // Random segments from points a few millimetres off the surface as the
    // loads have it now, where triangles lie at every distance from them.
    std::uniform_real_distribution<double> offset(-0.004, 0.004);
    std::uniform_real_distribution<double> length(0, 0.01), reach(0.001, 0.004);
    const auto& corners = m.surface.triangles;
    long left_out = 0;
    for (int s = 0; s < 400; ++s) {
      const int at = vertex(rng);
      const Vector3d hinge = surface.rest(at) + exact_u(at, index, f) +
                             Vector3d(offset(rng), offset(rng), offset(rng));
      const Vector3d axis = Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
      const double l = length(rng), r = reach(rng);
      for (int tri = 0; tri < m.surface.triangle_count(); ++tri) {
        if (!surface.far_from(tri, hinge, axis, l, r, surface.spread())) continue;
        ++left_out;
        std::array<Vector3d, 3> p;
        for (int i = 0; i < 3; ++i) {
          const auto v = static_cast<int>(
              corners[3 * static_cast<std::size_t>(tri) + static_cast<std::size_t>(i)]);
          p[static_cast<std::size_t>(i)] =
              surface.rest(v) + (v < n ? exact_u(v, index, f) : Vector3d::Zero());
        }
        const double distance = closest_segment_triangle(hinge, axis, l, p[0], p[1], p[2]).distance;
        EXPECT_GE(distance, r) << "triangle " << tri << " left out at " << distance * 1e3
                               << " mm from a segment, reach " << r * 1e3 << " mm";
      }
    }
    return left_out;
  }
};

TEST_F(BackgroundBound, WithDisplacementsNoTriangleLeftOutIsNear) {
  const long by_energy = check(true, false), with_known = check(true, true);
  EXPECT_GT(by_energy, 0);
  std::printf("left out: by energy %ld, with the known u_b %ld\n", by_energy, with_known);
  EXPECT_GT(with_known, by_energy);  // the known u_b tighten the bound
}

TEST_F(BackgroundBound, FromTheForcesAloneNoTriangleLeftOutIsNear) {
  const long by_energy = check(false, false), with_known = check(false, true);
  EXPECT_GT(by_energy, 0);
  std::printf("left out: by energy %ld, with the known u_b %ld\n", by_energy, with_known);
  EXPECT_GE(with_known, by_energy);  // never looser: either bound leaves a triangle out
}

// Two backgrounds share one LoadColumns (as an engine's own and its
// surface's do): on different loaded vertices, taking turns, each one's u_b
// is still G f to round-off (G is symmetric to about 1e-15: the columns
// read G^{b v} transposed where the sum above reads G^{v b}).
TEST_F(BackgroundBound, SharedColumnsGiveGTimesFOnEitherSetOfLoads) {
  const SurfaceModel& m = model();
  const int n = m.compliance_vertex_count();
  std::vector<int> first, second;
  // As many loads on each, one vertex apart: only the vertices differ.
  for (int v = 0; v + 1 < n; v += 5) first.push_back(v), second.push_back(v + 1);
  LoadColumns columns;
  columns.reserve(m, static_cast<int>(std::max(first.size(), second.size())));
  BackgroundLoads a, b;
  a.reserve(m, static_cast<int>(first.size()), columns);
  b.reserve(m, static_cast<int>(second.size()), columns);
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  VectorXd fa(3 * static_cast<Eigen::Index>(first.size())),
      fb(3 * static_cast<Eigen::Index>(second.size()));
  double largest = 0, worst = 0;
  for (int set = 0; set < 3; ++set) {
    for (auto& e : fa) e = 0.3 * normal(rng);
    for (auto& e : fb) e = 0.3 * normal(rng);
    a.set(first, {fa.data(), static_cast<std::size_t>(fa.size())}, 1.0);
    b.set(second, {fb.data(), static_cast<std::size_t>(fb.size())}, 1.0);
    for (int v = 0; v < n; ++v) {
      const Vector3d want_a = exact_u(v, first, fa), want_b = exact_u(v, second, fb);
      worst = std::max({worst, (a.at(v) - want_a).norm(), (b.at(v) - want_b).norm()});
      largest = std::max({largest, want_a.norm(), want_b.norm()});
    }
  }
  EXPECT_GT(largest, 1e-4);  // loads that move the box
  EXPECT_LE(worst, 1e-12 * largest) << "u_b off by " << worst << " m of " << largest;
}

}  // namespace
}  // namespace palpate::detail
