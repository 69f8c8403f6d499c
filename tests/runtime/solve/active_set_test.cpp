// The contact engine's active set (lib/runtime/internal/palpate/runtime/solve/active_set.hpp): the
// incremental factorization (Givens removal, block append) against the
// reference that refactors every solve, on random contact problems of a
// real compliance file whose rows leave, slide and join; and the engine
// driven both ways.

#include "palpate/runtime/solve/active_set.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "palpate/runtime/tool_contact.hpp"
#include "support/allocation_counter.hpp"
#include "support/box_job.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using detail::ActiveRow;
using detail::ActiveSet;
using detail::ActiveSetMethod;
using Eigen::Vector3d;

// Both paths solve the same SPD systems (condition ≤ ~1e5 here) in a
// different order of unknowns and of operations: they agree to ~1e-12
// relative to the largest force; 1e-10 is the bound the change promises.
constexpr double kActiveSetTolerance = 1e-10;

class ActiveSetTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    // A 100 × 50 × 40 mm box clamped on x = 0, 12.5 mm cubes.
    model_ = new SurfaceModel(
        load_surface_model("box", testing::write_box_compliance(dir_->path(), "box", 8)));
  }
  static void TearDownTestSuite() {
    delete model_;
    delete dir_;
  }
  static const SurfaceModel& model() { return *model_; }

  /// Surface triangles whose three vertices all move.
  static std::vector<int> free_triangles() {
    const DrawnSurface& s = model().surface;
    std::vector<int> out;
    for (int t = 0; t < s.triangle_count(); ++t) {
      bool free = true;
      for (int c = 0; c < 3; ++c)
        free = free &&
               static_cast<int>(
                   s.triangles[3 * static_cast<std::size_t>(t) + static_cast<std::size_t>(c)]) <
                   model().compliance_vertex_count();
      if (free) out.push_back(t);
    }
    return out;
  }

  /// A random problem: n points on distinct triangles, pressed along the
  /// triangle's inward normal by −0.3 to 1 mm (the negative ones pull:
  /// they leave), with a tangential displacement up to 0.6 mm (beyond the
  /// cone: they slide); a fifth held (three components, never change), a
  /// fifth dormant just outside the tip (they join when neighbours pull
  /// them in).
  static std::vector<ActiveRow> random_problem(std::mt19937& rng, int n,
                                               const std::vector<int>& triangles) {
    const DrawnSurface& s = model().surface;
    std::uniform_real_distribution<double> unit(0, 1);
    std::vector<int> pick = triangles;
    std::shuffle(pick.begin(), pick.end(), rng);
    const double friction = std::array<double, 3>{0, 0.3, 1}[rng() % 3];
    std::vector<ActiveRow> rows(static_cast<std::size_t>(n));
    for (int r = 0; r < n; ++r) {
      ActiveRow& row = rows[static_cast<std::size_t>(r)];
      const int t = pick[static_cast<std::size_t>(r)];
      Vector3d x[3];
      double w[3] = {unit(rng) + 0.05, unit(rng) + 0.05, unit(rng) + 0.05};
      const double sum = w[0] + w[1] + w[2];
      row.count = 3;
      for (int c = 0; c < 3; ++c) {
        const auto v = static_cast<int>(
            s.triangles[3 * static_cast<std::size_t>(t) + static_cast<std::size_t>(c)]);
        row.index[static_cast<std::size_t>(c)] = v;
        row.weights[static_cast<std::size_t>(c)] = w[c] / sum;
        x[c] = s.rest_position(v);
      }
      const Vector3d inward = -(x[1] - x[0]).cross(x[2] - x[0]).normalized();
      const Vector3d tangent = inward.unitOrthogonal();
      const Vector3d bitangent = inward.cross(tangent);
      const double kind = unit(rng);
      row.friction = friction;
      row.join_gap_m = 1e-6;
      if (kind < 0.2) {  // held: three components, towards the tool or into the organ
        row.tip = false;
        row.kind = ConstraintKind::kDisplacement;
        row.value = (unit(rng) * 2.0 - 1.2) * 1e-3 * inward + (unit(rng) - 0.5) * 1e-3 * tangent;
        continue;
      }
      row.tip = true;
      row.normal = inward;
      row.depth = (unit(rng) * 1.3 - 0.3) * 1e-3;
      row.value = row.depth * inward + (unit(rng) - 0.5) * 1.2e-3 * tangent +
                  (unit(rng) - 0.5) * 1.2e-3 * bitangent;
      if (kind < 0.4) {  // watched: 0.05 mm outside the tip
        row.depth = -5e-5;
        row.value = row.depth * inward;
        row.state = ActiveRow::kDormant;
      }
      row.kind = friction > 0 ? ConstraintKind::kDisplacement : ConstraintKind::kNormalDisplacement;
      if (row.kind == ConstraintKind::kNormalDisplacement)
        row.value = Vector3d(inward.dot(row.value), 0, 0);
    }
    return rows;
  }

  inline static testing::TempDir* dir_ = nullptr;
  inline static SurfaceModel* model_ = nullptr;
};

double largest(const ActiveSet& set, const std::vector<ActiveRow>& rows, bool force) {
  double m = 0;
  for (int r = 0; r < static_cast<int>(rows.size()); ++r)
    if (rows[static_cast<std::size_t>(r)].state == ActiveRow::kActive)
      m = std::max(m, force ? set.force(r).norm() : set.displacement(r).norm());
  return m;
}

TEST_F(ActiveSetTest, IncrementalEqualsRefactoringOnRandomProblems) {
  const std::vector<int> triangles = free_triangles();
  ASSERT_GE(triangles.size(), 64u);
  SolverLimits limits;
  ActiveSet incremental(model(), limits), reference(model(), limits);
  std::mt19937 rng(20261125);
  int leaves = 0, slides = 0, joins = 0, extra_solves = 0;
  for (int problem = 0; problem < 300; ++problem) {
    const int n = 4 + static_cast<int>(rng() % 40);
    std::vector<ActiveRow> a = random_problem(rng, n, triangles);
    std::vector<ActiveRow> b = a;
    const std::vector<ActiveRow> initial = a;
    const std::uint64_t solves_before = reference.solves();
    const RequestStatus sa = incremental.solve(a, 8, ActiveSetMethod::kIncremental);
    const RequestStatus sb = reference.solve(b, 8, ActiveSetMethod::kRefactor);
    ASSERT_EQ(sa, sb) << "problem " << problem << ": " << incremental.message() << " / "
                      << reference.message();
    ASSERT_EQ(incremental.solves(), reference.solves()) << "problem " << problem;
    extra_solves += static_cast<int>(reference.solves() - solves_before) - 1;
    if (sa != RequestStatus::kOk) continue;
    const double f_scale = largest(reference, b, true);
    const double u_scale = largest(reference, b, false);
    for (int r = 0; r < n; ++r) {
      const auto rr = static_cast<std::size_t>(r);
      ASSERT_EQ(a[rr].state, b[rr].state) << "problem " << problem << " row " << r;
      ASSERT_EQ(a[rr].kind, b[rr].kind) << "problem " << problem << " row " << r;
      leaves += b[rr].state == ActiveRow::kReleased ? 1 : 0;
      joins += initial[rr].state == ActiveRow::kDormant && b[rr].state == ActiveRow::kActive;
      slides += b[rr].kind != initial[rr].kind ? 1 : 0;
      if (b[rr].state != ActiveRow::kActive) continue;
      EXPECT_LE((incremental.force(r) - reference.force(r)).norm(), kActiveSetTolerance * f_scale)
          << "problem " << problem << " row " << r;
      EXPECT_LE((incremental.displacement(r) - reference.displacement(r)).norm(),
                kActiveSetTolerance * u_scale)
          << "problem " << problem << " row " << r;
    }
  }
  std::printf("leaves %d slides %d joins %d extra solves %d\n", leaves, slides, joins,
              extra_solves);
  // The problems exercise every change of the set: rows that leave, slide
  // and join, over several solves per problem.
  EXPECT_GT(leaves, 50);
  EXPECT_GT(slides, 50);
  EXPECT_GT(joins, 10);
  EXPECT_GT(extra_solves, 300);
}

TEST_F(ActiveSetTest, ASolveAllocatesNothing) {
  const std::vector<int> triangles = free_triangles();
  ActiveSet set(model(), SolverLimits{});
  std::mt19937 rng(7);
  const std::vector<ActiveRow> problem = random_problem(rng, 40, triangles);
  std::vector<ActiveRow> rows = problem;
  set.solve(rows, 8, ActiveSetMethod::kIncremental);
  rows = problem;
  const std::uint64_t solves = set.solves();
  const auto before = testing::allocations_here();
  EXPECT_EQ(set.solve(rows, 8, ActiveSetMethod::kIncremental), RequestStatus::kOk);
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  EXPECT_GT(set.solves() - solves, 1u);  // the factor was edited, not only built
}

/// A wide frictionless sphere pressed 12 mm into the box's top: the engine
/// with the incremental active set against the one that refactors, tick by
/// tick. Each tick finds its contacts on the surface the previous one
/// deformed, so round-off carries from tick to tick; this press stays
/// equal to 1e-10. (With friction 0.3 on this coarse box the sticking
/// points of the 30 mm sphere make nearly singular systems, point forces of
/// kilonewtons that cancel to 2 N, and the contact set jumps between 0 and
/// 20 points from tick to tick: there the two drift apart by 1e-8 and then
/// take different sets, round-off amplified, not a different solution.)
TEST_F(ActiveSetTest, EngineFeelsTheSameEitherWay) {
  ToolGeometry g;
  g.id = "finger";
  g.tip = TipShape::kSphere;
  g.tip_length_m = 0;
  g.tip_radius_m = 0.03;
  g.jaw_length_m = 0;
  g.friction = 0;
  ContactSettings incremental_settings, refactor_settings;
  refactor_settings.incremental_active_set = false;
  ToolContactEngine incremental(model(), {g}, incremental_settings, {});
  ToolContactEngine reference(model(), {g}, refactor_settings, {});
  ToolPoseInput pose;
  const Vector3d above(0.06, 0.025, 0.040 + g.tip_radius_m + 0.001);
  double now = 0;
  int most_contacts = 0;
  for (int i = 1; i <= 200; ++i) {
    pose.sequence = static_cast<std::uint64_t>(i);
    pose.position_m = above - Vector3d(0, 0, i * 6e-5);
    now += 0.001;
    ASSERT_EQ(incremental.update(0, pose, now), RequestStatus::kOk) << incremental.solver_message();
    ASSERT_EQ(reference.update(0, pose, now), RequestStatus::kOk) << reference.solver_message();
    const ToolOutput& a = incremental.output(0);
    const ToolOutput& b = reference.output(0);
    ASSERT_EQ(a.contacts, b.contacts) << "tick " << i;
    EXPECT_LE((a.force_n - b.force_n).norm(), kActiveSetTolerance * b.force_n.norm())
        << "tick " << i;
    most_contacts = std::max(most_contacts, b.contacts);
  }
  EXPECT_GE(most_contacts, 3);
  EXPECT_GT(reference.solves(), 220u);  // sets that changed within ticks
  EXPECT_EQ(incremental.solves(), reference.solves());
}

}  // namespace
}  // namespace palpate
