// The local contact model of every tool output (LocalContactModel,
// docs/tools.md "The local model"): the tick's contact wrench and its
// derivative K = ∂(F, τ)/∂(x, θ), read off the factor of the tick's solve.
// K is the derivative of the engine's own answer: one tick at a pose moved
// from a settled one by a small step answers w₀ + K q to first order, for
// presses with and without friction, a tilted capsule, a grasp (rotations
// included), two tools coupled through the organ, and a warped model.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <tuple>
#include <vector>

#include "palpate/core/rotation.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "support/box_model_suite.hpp"
#include "support/sphere_tool.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;
using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

constexpr double kAnswerTick = 0.001;  // s

// A step small enough that the contact set stays, large enough that the
// solve's round-off (~1e-12 of newtons) stays far below the change it
// causes. What remains is second order in the step (the surface's
// curvature across a 12.5 mm triangle, rotations of 1e-5 rad): measured
// within 3e-5 of the largest change a step of the same kind makes; 1e-4
// of it, plus 1e-10 N (N·m), is the bound.
constexpr double kStepM = 1e-6, kStepRad = 1e-5;
constexpr double kRelative = 1e-4, kAbsolute = 1e-10;

ToolGeometry probe(double friction) { return testing::sphere_tool("probe", 0.004, friction); }

ToolGeometry grasper() {
  ToolGeometry g;
  g.id = "grasper";
  g.force_limit_n = 100;
  g.max_force_rate_n_per_s = 1e6;
  return g;
}

/// The tool's +z along @p axis (unit): the shortest rotation from +z.
Eigen::Quaterniond pointing(const Vector3d& axis) {
  return palpate::rotation_taking(Vector3d::UnitZ(), axis);
}

/// One tool's path: where it goes, tick by tick, before the moved tick.
struct Step {
  Vector3d position;
  Eigen::Quaterniond orientation;
  double jaw;
};

/// A scene: the tools, their paths (the same number of steps each), and a
/// warped model or not.
struct Scene {
  std::vector<ToolGeometry> tools;
  std::vector<std::vector<Step>> paths;
  const RotationField* warping = nullptr;
  ContactSettings settings = {};
};

Vector6d wrench_of(const ToolOutput& out) {
  Vector6d w;
  w << out.local.force_n, out.local.torque_nm;
  return w;
}

/// Plays @p scene, holds the last poses for @p settle ticks, then moves
/// tool 0 by the generalized step @p q (δx, δθ) for one tick. Returns the
/// settled output of tool 0 and the moved one.
std::pair<ToolOutput, ToolOutput> play(const SurfaceModel& model, const Scene& scene,
                                       const Vector6d& q, int settle = 40) {
  ToolContactEngine engine(model, scene.tools, scene.settings, {}, scene.warping);
  std::vector<std::uint64_t> sequence(scene.tools.size(), 0);
  double now = 0;
  auto tick = [&](int t, const Step& s) {
    ToolPoseInput pose;
    pose.sequence = ++sequence[static_cast<std::size_t>(t)];
    pose.position_m = s.position;
    pose.orientation = s.orientation;
    pose.jaw_angle_rad = s.jaw;
    EXPECT_EQ(engine.check(t, pose), PoseProblem::kNone) << engine.problem_message();
    EXPECT_EQ(engine.update(t, pose, now), RequestStatus::kOk) << engine.solver_message();
  };
  const std::size_t steps = scene.paths.front().size();
  for (std::size_t i = 0; i < steps + static_cast<std::size_t>(settle); ++i) {
    for (std::size_t t = 0; t < scene.tools.size(); ++t)
      tick(static_cast<int>(t), scene.paths[t][std::min(i, steps - 1)]);
    now += kAnswerTick;
  }
  const ToolOutput settled = engine.output(0);
  Step moved = scene.paths.front().back();
  moved.position += q.head<3>();
  if (q.tail<3>().norm() > 0)
    moved.orientation =
        Eigen::Quaterniond(Eigen::AngleAxisd(q.tail<3>().norm(), q.tail<3>().normalized())) *
        moved.orientation;
  tick(0, moved);
  return {settled, engine.output(0)};
}

/// Checks every column of K against one moved tick of the scene.
void expect_stiffness_is_the_derivative(const SurfaceModel& model, const Scene& scene,
                                        bool rotations, double step = 1) {
  const auto [settled, unused] = play(model, scene, Vector6d::Zero());
  const LocalContactModel& local = settled.local;
  ASSERT_TRUE(local.valid);
  ASSERT_GT(settled.contacts, 0);
  EXPECT_GT(local.force_n.norm(), 0.05) << "a contact worth the name";
  // Pushed further along the force, the organ pushes back harder.
  const Vector3d along = local.force_n.normalized();
  EXPECT_LT(along.dot(local.stiffness.topLeftCorner<3, 3>() * along), 0);
  // Each column against one moved tick. The error is second order in the
  // step, so it is bounded against the largest change a step of the same
  // kind makes (a tangential step barely changes the force).
  const int columns = rotations ? 6 : 3;
  Matrix6d predicted = Matrix6d::Zero(), changed = Matrix6d::Zero();
  for (int c = 0; c < columns; ++c) {
    Vector6d q = Vector6d::Zero();
    q(c) = step * (c < 3 ? kStepM : kStepRad);
    const auto [before, after] = play(model, scene, q);
    ASSERT_EQ(after.contacts, before.contacts) << "column " << c << ": the set changed";
    changed.col(c) = wrench_of(after) - wrench_of(before);
    predicted.col(c) = local.stiffness * q;
  }
  for (int c = 0; c < columns; ++c) {
    const int first = c < 3 ? 0 : 3;
    for (const int rows : {0, 3}) {
      const double scale = changed.block(rows, first, 3, 3).colwise().norm().maxCoeff();
      const double error = (predicted - changed).block(rows, c, 3, 1).norm();
      EXPECT_LE(error, kRelative * scale + kAbsolute)
          << "column " << c << (rows == 0 ? ", force" : ", torque") << "\npredicted "
          << predicted.col(c).transpose() << "\nchanged   " << changed.col(c).transpose();
    }
  }
}

class LocalModelTest : public testing::BoxModelSuite<8> {
 protected:
  /// A straight press of @p g from 5 mm above the top face at (x, y) mm to
  /// @p depth_m below it, along @p axis (the tool's +z), in 0.05 mm steps.
  static std::vector<Step> press(const ToolGeometry& g, double x_mm, double y_mm, double depth_m,
                                 const Vector3d& axis = -Vector3d::UnitZ(), double jaw = 0) {
    const Vector3d surface = rest(top_vertex(x_mm, y_mm)) + Vector3d(0.3e-3, 0.2e-3, 0);
    const double reach = (g.tip == TipShape::kCapsule ? g.tip_length_m : 0) + g.tip_radius_m;
    const Vector3d to = surface - depth_m * Vector3d::UnitZ() - reach * axis;
    const Vector3d from = to - 0.005 * axis;
    std::vector<Step> path;
    for (int i = 1; i <= 100; ++i)
      path.push_back({from + (to - from) * (i / 100.0), pointing(axis), jaw});
    return path;
  }
};

TEST_F(LocalModelTest, AFreeToolHasNoWrenchAndNoStiffness) {
  Scene scene{
      {probe(0)},
      {{{rest(top_vertex(50, 25)) + Vector3d(0, 0, 0.02), pointing(-Vector3d::UnitZ()), 0}}}};
  const auto [settled, moved] = play(model(), scene, Vector6d::Zero());
  EXPECT_TRUE(settled.local.valid);
  EXPECT_EQ(settled.contacts, 0);
  EXPECT_EQ(settled.local.force_n.norm(), 0.0);
  EXPECT_EQ(settled.local.stiffness.norm(), 0.0);
}

TEST_F(LocalModelTest, ItAnswersThePoseItWasMadeAtWithTheWrenchBeforeTheLimits) {
  ToolGeometry g = probe(0);
  g.force_limit_n = 0.2;  // the fed-back force is clamped; the model's is not
  Scene scene{{g}, {press(g, 75, 25, 0.003)}};
  const auto [settled, moved] = play(model(), scene, Vector6d::Zero());
  EXPECT_TRUE(settled.force_limited);
  EXPECT_NEAR(settled.force_n.norm(), 0.2, 1e-12);
  EXPECT_GT(settled.local.force_n.norm(), 0.5);
  EXPECT_EQ(settled.local.position_m, scene.paths[0].back().position);
  EXPECT_LT(settled.local.orientation.angularDistance(scene.paths[0].back().orientation), 1e-12);
  EXPECT_FALSE(settled.local.holding);
}

TEST_F(LocalModelTest, AFrictionlessPressIsItsOwnDerivative) {
  const ToolGeometry g = probe(0);
  expect_stiffness_is_the_derivative(model(), {{g}, {press(g, 75, 25, 0.003)}}, true);
}

TEST_F(LocalModelTest, AStickingPressIsItsOwnDerivative) {
  const ToolGeometry g = probe(INFINITY);
  expect_stiffness_is_the_derivative(model(), {{g}, {press(g, 75, 25, 0.003)}}, true);
}

/// The smallest number of vertices a contact point of tool 0 lies on after
/// playing @p scene: 1 at a vertex, 2 on an edge, 3 inside a triangle.
int fewest_corners(const SurfaceModel& model, const Scene& scene) {
  ToolContactEngine engine(model, scene.tools, {}, {}, scene.warping);
  std::uint64_t sequence = 0;
  for (const Step& s : scene.paths.front()) {
    ToolPoseInput pose;
    pose.sequence = ++sequence;
    pose.position_m = s.position;
    pose.orientation = s.orientation;
    pose.jaw_angle_rad = s.jaw;
    engine.check(0, pose);
    engine.update(0, pose, 1e-3 * static_cast<double>(sequence));
  }
  int fewest = 3;
  for (const ContactPoint& p : engine.contact_points()) fewest = std::min(fewest, p.vertex_count);
  return fewest;
}

TEST_F(LocalModelTest, PressesOnTheBoxsRimAndCornerTurnTheirNormalsAndAreTheirOwnDerivative) {
  // Pressed into the rim where the top face meets the side y = 0, or into
  // the free end's corner, the tip meets the surface on edges and at a
  // vertex: there the normal from the tip's centre to the point turns as
  // the tip moves.
  const Vector3d rim(0.075, 0, 0.04), corner(0.1, 0, 0.04);
  const Vector3d into_rim = Vector3d(0, 1, -1).normalized();
  const Vector3d into_corner = Vector3d(-1, 1, -1).normalized();
  for (const auto& [point, axis, fewest] :
       {std::tuple{rim, into_rim, 2}, std::tuple{corner, into_corner, 1}})
    for (const double friction : {0.0, double{INFINITY}}) {
      const ToolGeometry g = probe(friction);
      const Vector3d to = point - (g.tip_radius_m - 0.0015) * axis, from = to - 0.005 * axis;
      std::vector<Step> path;
      for (int i = 1; i <= 100; ++i)
        path.push_back({from + (to - from) * (i / 100.0), pointing(axis), 0});
      const Scene scene{{g}, {path}};
      EXPECT_LE(fewest_corners(model(), scene), fewest) << "friction " << friction;
      // Second-order terms now scale with the step over the point's distance
      // to the tip's centre (2.5 mm), not over a triangle: a tenth of the step.
      expect_stiffness_is_the_derivative(model(), scene, true, 0.1);
    }
}

TEST_F(LocalModelTest, ATiltedCapsuleWithFrictionIsItsOwnDerivativeInRotationToo) {
  const ToolGeometry g = grasper();
  const Vector3d axis = Eigen::AngleAxisd(0.35, Vector3d::UnitY()) * -Vector3d::UnitZ();
  expect_stiffness_is_the_derivative(model(), {{g}, {press(g, 70, 25, 0.003, axis)}}, true);
}

TEST_F(LocalModelTest, AGraspIsItsOwnDerivativeAndMayPull) {
  const ToolGeometry g = grasper();
  std::vector<Step> path = press(g, 75, 25, 0.003, -Vector3d::UnitZ(), degrees(40));
  const Step in = path.back();
  for (int i = 1; i <= 40; ++i) path.push_back({in.position, in.orientation, degrees(40 - i)});
  for (int i = 1; i <= 80; ++i)  // pull 4 mm up
    path.push_back({in.position + Vector3d(0, 0, 4e-3 * i / 80.0), in.orientation, 0});
  const Scene scene{{g}, {path}};
  const auto [settled, moved] = play(model(), scene, Vector6d::Zero());
  ASSERT_EQ(settled.state, ToolState::kGrasping);
  EXPECT_TRUE(settled.local.holding);
  EXPECT_LT(settled.local.force_n.z(), -0.05) << "held tissue pulls the tool back";
  expect_stiffness_is_the_derivative(model(), scene, true);
}

TEST_F(LocalModelTest, TwoToolsFeelEachOtherThroughTheOrgan) {
  // Tool 1 presses beside tool 0: K of tool 0 is the coupled system's (tool
  // 1's contacts stay at its pose), stiffer than tool 0 pressing alone
  // would say is not the point; that its moved tick agrees is.
  const ToolGeometry a = probe(INFINITY);
  ToolGeometry b = probe(INFINITY);
  b.id = "other";
  const Scene scene{{a, b}, {press(a, 75, 20, 0.003), press(b, 75, 32, 0.003)}};
  expect_stiffness_is_the_derivative(model(), scene, false);
  // Alone, the same press is stiffer along z: the other tool's contact
  // holds the tissue around it down... or up. Either way different.
  const auto [together, unused1] = play(model(), scene, Vector6d::Zero());
  const auto [alone, unused2] = play(model(), Scene{{a}, {scene.paths[0]}}, Vector6d::Zero());
  EXPECT_GT(std::abs(together.local.stiffness(2, 2) - alone.local.stiffness(2, 2)),
            1e-3 * std::abs(alone.local.stiffness(2, 2)));
}

TEST_F(LocalModelTest, TheReferenceActiveSetGivesTheSameModel) {
  // Refactoring every solve (the reference path) reads G from the model
  // where the incremental path reuses the tick's blocks: the same K to
  // round-off (both solve the same SPD systems; 1e-10 of |K|).
  // Two tools pressing side by side: the coupled system, as in
  // TwoToolsFeelEachOtherThroughTheOrgan, one with friction.
  const ToolGeometry a = probe(0.3);
  ToolGeometry b = probe(0);
  b.id = "other";
  Scene scene{{a, b}, {press(a, 75, 20, 0.003), press(b, 75, 32, 0.003)}};
  const auto [incremental, unused1] = play(model(), scene, Vector6d::Zero());
  scene.settings.incremental_active_set = false;
  const auto [reference, unused2] = play(model(), scene, Vector6d::Zero());
  ASSERT_GT(incremental.contacts, 0);
  EXPECT_LE((incremental.local.stiffness - reference.local.stiffness).norm(),
            1e-10 * reference.local.stiffness.norm());
  EXPECT_LE((incremental.local.force_n - reference.local.force_n).norm(),
            1e-10 * reference.local.force_n.norm());
}

TEST_F(LocalModelTest, AWarpedModelsGraspIsItsOwnDerivative) {
  const RotationField field(model().surface, default_smoothing_radius(model().surface, kToolEdges));
  const ToolGeometry g = grasper();
  std::vector<Step> path = press(g, 85, 25, 0.003, -Vector3d::UnitZ(), degrees(40));
  const Step in = path.back();
  for (int i = 1; i <= 40; ++i) path.push_back({in.position, in.orientation, degrees(40 - i)});
  for (int i = 1; i <= 100; ++i)  // lift 6 mm and turn 10° about y
    path.push_back(
        {in.position + Vector3d(0, 0, 6e-3 * i / 100.0),
         Eigen::Quaterniond(Eigen::AngleAxisd(degrees(10) * i / 100.0, Vector3d::UnitY())) *
             in.orientation,
         0});
  Scene scene{{g}, {path}, &field};
  expect_stiffness_is_the_derivative(model(), scene, true);
}

}  // namespace
}  // namespace palpate
