// What the jaws may hold (lib/runtime/internal/palpate/runtime/contact/jaw_grasp.hpp): rows kept
// independent with a margin, the region between the jaws, and a flap held
// by both faces through the contact engine.

#include "palpate/runtime/contact/jaw_grasp.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <cmath>

#include "palpate/runtime/tool_contact.hpp"
#include "support/box_job.hpp"
#include "support/test_meshes.hpp"

namespace palpate::detail {
namespace {

using Eigen::Vector3d;

bool add(IndependentRows& rows, std::array<int, 3> vertices, std::array<double, 3> weights,
         double threshold = 0.5) {
  return rows.add(vertices, weights, threshold);
}

TEST(IndependentRows, AtMostAsManyRowsAsTheirVerticesCanTake) {
  IndependentRows rows(8);
  // Three points of one triangle, well apart: independent.
  EXPECT_TRUE(add(rows, {0, 1, 2}, {0.8, 0.1, 0.1}));
  EXPECT_TRUE(add(rows, {0, 1, 2}, {0.1, 0.8, 0.1}));
  EXPECT_TRUE(add(rows, {0, 1, 2}, {0.1, 0.1, 0.8}));
  // A fourth on the same three vertices is in their span, whatever its weights.
  EXPECT_FALSE(add(rows, {0, 1, 2}, {1.0 / 3, 1.0 / 3, 1.0 / 3}, 1e-9));
  EXPECT_FALSE(add(rows, {2, 0, 1}, {1, 0, 0}, 1e-9));
  EXPECT_EQ(rows.size(), 3);
  // A neighbouring triangle brings one more vertex, so one more row.
  EXPECT_TRUE(add(rows, {1, 2, 3}, {0.1, 0.1, 0.8}));
  EXPECT_FALSE(add(rows, {1, 2, 3}, {0.2, 0.2, 0.6}, 1e-9));
  EXPECT_EQ(rows.size(), 4);
}

TEST(IndependentRows, TheThresholdIsTheNormLeftOutsideTheKeptRows) {
  // (1, 0) kept; (0.9, 0.1) has 0.1 of its norm outside it.
  IndependentRows rows(4);
  EXPECT_TRUE(add(rows, {0, -1, -1}, {1, 0, 0}));
  EXPECT_FALSE(add(rows, {0, 1, -1}, {0.9, 0.1, 0}, 0.1 + 1e-9));
  EXPECT_TRUE(add(rows, {0, 1, -1}, {0.9, 0.1, 0}, 0.1 - 1e-9));
  EXPECT_EQ(rows.size(), 2);
  rows.clear();
  EXPECT_EQ(rows.size(), 0);
  EXPECT_TRUE(add(rows, {0, 1, -1}, {0.9, 0.1, 0}));
}

TEST(IndependentRows, FixedVerticesAreNoUnknownsAndCapacityIsKept) {
  IndependentRows rows(2);
  // A point whose weight is all on fixed vertices (−1) moves nothing.
  EXPECT_FALSE(add(rows, {-1, -1, -1}, {0.5, 0.25, 0.25}, 1e-9));
  // Only the movable share counts: 0.3 on vertex 4.
  EXPECT_FALSE(add(rows, {4, -1, -1}, {0.3, 0.7, 0}, 0.5));
  EXPECT_TRUE(add(rows, {4, -1, -1}, {0.3, 0.7, 0}, 0.25));
  EXPECT_TRUE(add(rows, {5, -1, -1}, {1, 0, 0}));
  EXPECT_FALSE(add(rows, {6, -1, -1}, {1, 0, 0})) << "full";
}

TEST(JawGrasp, BetweenTheJawsIsTheWedgeOfTheirFacesWidenedByTheTipsRadius) {
  ToolGeometry g;  // jaws 15 × 5 mm, r = 4 mm
  const JawsAtClosing jaws{Vector3d(0, 0, 0), Eigen::Matrix3d::Identity(), &g, 0.0};
  const double open = 40 * M_PI / 180, slope = std::tan(open / 2);
  EXPECT_TRUE(JawGrasp::between(jaws, Vector3d(10e-3 * slope + 3.9e-3, 0, 10e-3), open));
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(10e-3 * slope + 4.1e-3, 0, 10e-3), open));
  EXPECT_TRUE(JawGrasp::between(jaws, Vector3d(0, 2.5e-3 + 3.9e-3, 10e-3), open));
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(0, 2.5e-3 + 4.1e-3, 10e-3), open));
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(0, 0, -1e-4), open)) << "behind the hinge";
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(0, 0, 16e-3), open)) << "past the jaws";
  EXPECT_TRUE(JawGrasp::between(jaws, Vector3d(0, 0, 16e-3), open, 4e-3)) << "their rounded end";
  ToolGeometry probe;
  probe.jaw_length_m = 0;
  const JawsAtClosing none{Vector3d::Zero(), Eigen::Matrix3d::Identity(), &probe, 0.0};
  EXPECT_FALSE(JawGrasp::between(none, Vector3d(0, 0, 1e-3), open)) << "a probe never grasps";
}

}  // namespace
}  // namespace palpate::detail

namespace palpate {
namespace {

using Eigen::Vector3d;

// The jaws hold the tissue under both faces: a 6 mm plate's free edge
// taken between open jaws holds points of its top face under one jaw and of
// its bottom face under the other, squeezed between them (the grip comes
// from both faces), and lifting the pliers lifts the edge.
TEST(JawGrasp, AFlapBetweenTheJawsIsHeldByBothFacesAndLiftsWithThePliers) {
  testing::TempDir dir;
  // 100 × 50 × 6 mm, clamped on x = 0, 6.25 mm cells, one cell thick.
  const SurfaceModel flap = load_surface_model(
      "flap", testing::write_clamped_compliance(testing::box_mesh(0.1, 0.05, 0.006, 16, 8, 1),
                                                dir.path(), "flap", 85e3));
  const int n = flap.compliance_vertex_count();

  // A fine grasper: its 1 mm tip, 2 mm shorter than the jaws, stays clear
  // of the flap while open. (A tip reaching past the jaws meets the flap's
  // edge face head on, and with friction the face sticks to it and is
  // pushed along.)
  ToolGeometry g;
  g.id = "grasper";
  g.tip_radius_m = 0.001;
  g.tip_length_m = 0.012;
  g.force_limit_n = 100;
  g.max_force_rate_n_per_s = 1e6;
  ToolContactEngine engine(flap, {g}, {}, {});
  // Shaft along −x towards the edge, jaws opening in the x–z plane: the
  // tool's x is the model's z (above / below the flap), its z the model's −x.
  Eigen::Matrix3d r;
  r.col(0) = Vector3d::UnitZ();
  r.col(1) = Vector3d::UnitY();
  r.col(2) = -Vector3d::UnitX();
  ToolPoseInput pose;
  pose.orientation = Eigen::Quaterniond(r);
  pose.jaw_angle_rad = degrees(40);
  double now = 0;
  auto tick = [&](const Vector3d& hinge, double jaw) {
    ++pose.sequence;
    pose.position_m = hinge;
    pose.jaw_angle_rad = jaw;
    ToolPoseInput checked = pose;
    ASSERT_EQ(engine.check(0, checked), PoseProblem::kNone);
    ASSERT_EQ(engine.update(0, checked, now), RequestStatus::kOk) << engine.solver_message();
    now += 1e-3;
  };
  // Open, from beyond the edge to 10 mm over it, then closed.
  for (int i = 0; i <= 100; ++i) tick(Vector3d(0.125 - 2e-4 * i, 0.025, 0.003), degrees(40));
  EXPECT_EQ(engine.output(0).contacts, 0) << "open jaws around the flap do not push it";
  for (int i = 1; i <= 40; ++i) tick(Vector3d(0.105, 0.025, 0.003), degrees(40 - i));
  ASSERT_EQ(engine.output(0).state, ToolState::kGrasping);

  // Held points on both faces, on triangles (not only at vertices).
  int top = 0, bottom = 0, inside_triangles = 0;
  double top_fz = 0, bottom_fz = 0, squeeze = 0;
  for (const ContactPoint& p : engine.contact_points()) {
    ASSERT_TRUE(p.held);
    double sum = 0;
    for (int i = 0; i < p.vertex_count; ++i) sum += p.weights[i];
    EXPECT_NEAR(sum, 1, 1e-12);
    inside_triangles += p.vertex_count > 1 ? 1 : 0;
    Vector3d at_rest = Vector3d::Zero();
    for (int i = 0; i < p.vertex_count; ++i)
      at_rest += p.weights[i] *
                 Eigen::Map<const Vector3d>(
                     &flap.surface.rest_positions_m[3 * static_cast<std::size_t>(p.vertices[i])]);
    EXPECT_GE(at_rest.x(), 0.09 - 1e-9) << "held points lie under the jaws (x from 90 to 100 mm)";
    // Squeezed onto the jaws' mid-plane, 3 mm.
    EXPECT_NEAR(p.position_m.z(), 0.003, 1e-9);
    if (at_rest.z() > 0.006 - 1e-9) ++top, top_fz += p.force_n.z();
    if (at_rest.z() < 1e-9) ++bottom, bottom_fz += p.force_n.z();
    squeeze += 0.5 * std::abs(p.force_n.z());
  }
  EXPECT_GE(top, 1);
  EXPECT_GE(bottom, 1);
  EXPECT_GE(inside_triangles, 1);
  EXPECT_LT(top_fz, 0) << "the upper jaw pushes the top face down";
  EXPECT_GT(bottom_fz, 0) << "the lower jaw pushes the bottom face up";
  EXPECT_NEAR(engine.output(0).grip_n, squeeze, 1e-9 * squeeze);
  EXPECT_GT(engine.output(0).grip_n, 0.05);

  // Lift the pliers 5 mm: the held tissue follows, the flap holds them back.
  for (int i = 1; i <= 50; ++i) tick(Vector3d(0.105, 0.025, 0.003 + 1e-4 * i), 0.0);
  for (const ContactPoint& p : engine.contact_points())
    EXPECT_NEAR(p.position_m.z(), 0.008, 1e-9) << "a held point follows the jaws";
  EXPECT_LT(engine.output(0).force_n.z(), -0.01) << "the flap pulls the pliers down";
  // The edge between the held points rises too (the flap bends, it does not tear).
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * n);
  const auto idx = engine.contact_indices();
  for (std::size_t l = 0; l < idx.size(); ++l)
    f.segment<3>(3 * idx[l]) += Eigen::Map<const Vector3d>(&engine.contact_forces()[3 * l]);
  const Eigen::VectorXd u = flap.G * f;
  double edge_lift = INFINITY;
  for (int j = 0; j < n; ++j) {
    const double* x = &flap.surface.rest_positions_m[3 * static_cast<std::size_t>(j)];
    if (std::abs(x[0] - 0.1) < 1e-9 && std::abs(x[1] - 0.025) < 0.004)
      edge_lift = std::min(edge_lift, u(3 * j + 2));
  }
  // Only points between the vertices are held, so the edge's vertices rise
  // less than the jaws (2.3 mm of 5 when written): at least a quarter.
  EXPECT_GT(edge_lift, 0.25 * 0.005) << "the edge under the jaws rises with them";
}

}  // namespace
}  // namespace palpate
