// Warped compliance (docs/model/warped.md, "Large rotations: warped compliance"):
// the rotations of the surface, the integrated rotation, and warped requests
// against their definitions on a real compliance file. The comparison with a
// nonlinear reference is tests/runtime/nonlinear_reference/ (lift_warped).

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/warped_solver.hpp"
#include "support/box_job.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

class WarpingTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    // 100 × 50 × 40 mm, 8 × 4 × 4 cubes of 12.5 mm, clamped on x = 0.
    model_ = new SurfaceModel(
        load_surface_model("box", testing::write_box_compliance(dir_->path(), "box", 8)));
  }
  static void TearDownTestSuite() {
    delete model_;
    delete dir_;
  }
  static const SurfaceModel& model() { return *model_; }
  static const DrawnSurface& surface() { return model_->surface; }
  static std::uint32_t vertex(int i) { return surface().vertex_ids[static_cast<std::size_t>(i)]; }

  /// The compliance vertices of the top face (z = 40 mm) with x ≥ x_min_mm.
  static std::vector<int> top_face(double x_min_mm) {
    std::vector<int> out;
    for (int v = 0; v < surface().compliance_vertex_count; ++v) {
      const Eigen::Vector3d p = surface().rest_position(v);
      if (p.z() > 0.04 - 1e-9 && p.x() >= x_min_mm * 1e-3 - 1e-9) out.push_back(v);
    }
    return out;
  }

  /// Imposes on @p grasped the rotation by @p degrees about the y axis
  /// through (0, ·, 20 mm), lifting the free end.
  template <typename Solver>
  static RequestStatus lift(Solver& solver, const std::vector<int>& grasped, double degrees) {
    const Eigen::Vector3d a(0, 0, 0.02);
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(degrees * M_PI / 180, -Eigen::Vector3d::UnitY()).toRotationMatrix();
    RequestStatus status = solver.begin(grasped.size());
    for (const int v : grasped) {
      const Eigen::Vector3d p = surface().rest_position(v);
      const Eigen::Vector3d d = a + R * (p - a) - p;
      if (status == RequestStatus::kOk)
        status = solver.add(vertex(v), 1, d.data(), Eigen::Vector3d::Zero().eval().data());
    }
    return status == RequestStatus::kOk ? solver.solve() : status;
  }

  inline static testing::TempDir* dir_ = nullptr;
  inline static SurfaceModel* model_ = nullptr;
};

// R̃(ω) (ω × r) = (exp([ω]×) − I) r: an infinitesimal rotation becomes the
// finite one, on both sides of the series' switch at 1e-4 rad. Round-off of
// a few 3 × 3 products on |r| = 1: 1e-14.
TEST(IntegratedRotation, TurnsAnInfinitesimalRotationIntoTheFiniteOne) {
  std::mt19937 random(7);
  std::normal_distribution<double> normal;
  for (const double angle : {1e-9, 0.99e-4, 1.01e-4, 0.3, 1.0, 2.5}) {
    for (int trial = 0; trial < 5; ++trial) {
      const Eigen::Vector3d axis =
          Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
      const Eigen::Vector3d omega = angle * axis;
      const Eigen::Vector3d r =
          Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
      const Eigen::Matrix3d R = rotation_matrix(omega);
      const Eigen::Matrix3d expected = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
      EXPECT_LT((R - expected).norm(), 1e-14) << angle;
      EXPECT_LT(
          (integrated_rotation(omega) * omega.cross(r) - (R - Eigen::Matrix3d::Identity()) * r)
              .norm(),
          1e-14)
          << angle;
    }
  }
}

// A rigid rotation û = θ × (p − c) gives ω = θ wherever the fit and its
// smoothing neighbourhood see only moving vertices (the clamped face does
// not follow a rigid field): flat faces, edges and corners alike.
TEST_F(WarpingTest, RotationsOfARigidFieldAreItsRotation) {
  const double radius = default_smoothing_radius(surface());
  EXPECT_NEAR(radius, 1.5 * 0.0125, 1e-12);  // the box's median edge is the cube's
  const RotationField field(surface(), radius);
  const int n = surface().compliance_vertex_count;
  const Eigen::Vector3d theta(0.01, -0.02, 0.015), c(0.03, 0.01, -0.02);
  std::vector<double> u(3 * static_cast<std::size_t>(n)), omega(u.size());
  for (int v = 0; v < n; ++v) {
    Eigen::Map<Eigen::Vector3d> uv(&u[3 * static_cast<std::size_t>(v)]);
    uv = theta.cross(surface().rest_position(v) - c);
  }
  field.rotations(u, omega);
  int checked = 0;
  for (int v = 0; v < n; ++v) {
    if (surface().rest_position(v).x() < 2 * radius + 0.0125 + 1e-9) continue;
    ++checked;
    const Eigen::Map<const Eigen::Vector3d> w(&omega[3 * static_cast<std::size_t>(v)]);
    EXPECT_LT((w - theta).norm(), 1e-12 * theta.norm()) << v;
  }
  EXPECT_GT(checked, 50);
}

TEST_F(WarpingTest, ARadiusThatIsNoLengthIsRefused) {
  for (const double radius : {0.0, -1.0, std::nan("")})
    testing::expect_error<InputError>([&] { RotationField(surface(), radius); },
                                      {"smoothing radius", "positive length in metres"});
}

// Small loads: the warped answer tends to the linear one, and the
// difference is first order in the rotation (R̃ = I + ½[ω]× + …): ten times
// smaller for a ten times smaller displacement (within 1 %).
TEST_F(WarpingTest, SmallLoadsGiveTheLinearAnswer) {
  const RotationField field(surface(), default_smoothing_radius(surface()));
  const auto grasped = top_face(87.5);
  SolverLimits limits;
  ConstraintSolver linear(model(), limits);
  WarpedSolver warped(model(), limits, field);
  std::vector<double> differences;
  for (const double degrees : {1e-4, 1e-5}) {
    ASSERT_EQ(lift(linear, grasped, degrees), RequestStatus::kOk);
    ASSERT_EQ(lift(warped, grasped, degrees), RequestStatus::kOk) << warped.message();
    const Eigen::Vector3d f_linear = linear.total_force(), f_warped = warped.total_force();
    differences.push_back((f_warped - f_linear).norm() / f_linear.norm());
  }
  EXPECT_LT(differences[0], 1e-5);
  EXPECT_NEAR(differences[0] / differences[1], 10.0, 0.1);
}

// A lift of 30°: the imposed displacements are met in the world (to the
// fixed point's tolerance on ω times |û|), and the reported point
// displacements are the warped field at the points.
TEST_F(WarpingTest, ALiftMeetsItsDisplacementsInTheWorld) {
  const RotationField field(surface(), default_smoothing_radius(surface()));
  const auto grasped = top_face(87.5);
  SolverLimits limits;
  ConstraintSolver linear(model(), limits);
  WarpedSolver warped(model(), limits, field);
  ASSERT_EQ(lift(linear, grasped, 30), RequestStatus::kOk);
  ASSERT_EQ(lift(warped, grasped, 30), RequestStatus::kOk) << warped.message();
  EXPECT_GT(warped.iterations(), 2);
  Eigen::VectorXd field_m(model().G.rows());
  warped.surface_displacement(field_m);
  const Eigen::Vector3d a(0, 0, 0.02);
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(30 * M_PI / 180, -Eigen::Vector3d::UnitY()).toRotationMatrix();
  for (std::size_t j = 0; j < grasped.size(); ++j) {
    const Eigen::Vector3d p = surface().rest_position(grasped[j]);
    const Eigen::Vector3d imposed = a + R * (p - a) - p;
    const Eigen::Map<const Eigen::Vector3d> x(&warped.displacements()[3 * j]);
    EXPECT_LT((x - imposed).norm(), 1e-7 * imposed.norm()) << j;
    EXPECT_LT((field_m.segment<3>(3 * grasped[j]) - x).norm(), 1e-12 * imposed.norm()) << j;
  }
  // Not the linear answer: this stubby block cannot swing, but its frames turn.
  EXPECT_GT((warped.total_force() - linear.total_force()).norm(),
            0.05 * linear.total_force().norm());
}

// A point inside a surface triangle (add_point): its imposed world
// displacement is met (R̃ of the weighted mean ω carries its û), and a small
// one gives the linear answer.
TEST_F(WarpingTest, APointOnATriangleMeetsItsDisplacement) {
  const RotationField field(surface(), default_smoothing_radius(surface()));
  int triangle = -1;
  for (int t = 0; t < surface().triangle_count() && triangle < 0; ++t) {
    bool free_end_top = true;
    for (int i = 0; i < 3; ++i) {
      const auto v = static_cast<int>(surface().triangles[3 * std::size_t(t) + std::size_t(i)]);
      free_end_top = free_end_top && v < surface().compliance_vertex_count &&
                     surface().rest_position(v).z() > 0.04 - 1e-9 &&
                     surface().rest_position(v).x() > 0.08;
    }
    if (free_end_top) triangle = t;
  }
  ASSERT_GE(triangle, 0);
  std::array<std::uint32_t, 3> ids{};
  for (int i = 0; i < 3; ++i)
    ids[std::size_t(i)] =
        vertex(static_cast<int>(surface().triangles[3 * std::size_t(triangle) + std::size_t(i)]));
  const std::array<double, 3> weights{0.2, 0.3, 0.5};
  SolverLimits limits;
  ConstraintSolver linear(model(), limits);
  WarpedSolver warped(model(), limits, field);
  for (const double scale : {1.0, 1e-6}) {
    const Eigen::Vector3d d = scale * Eigen::Vector3d(-0.004, 0.0, 0.012);
    auto impose = [&](auto& solver) {
      ASSERT_EQ(solver.begin(1), RequestStatus::kOk);
      ASSERT_EQ(solver.add_point(ids, weights, 1, d.data(), d.data()), RequestStatus::kOk);
      ASSERT_EQ(solver.solve(), RequestStatus::kOk) << solver.message();
    };
    impose(linear);
    impose(warped);
    const Eigen::Map<const Eigen::Vector3d> x(&warped.displacements()[0]);
    EXPECT_LT((x - d).norm(), 1e-7 * d.norm()) << scale;
    const Eigen::Vector3d fl = linear.forces().segment<3>(0), fw(&warped.forces()[0]);
    if (scale < 1)
      EXPECT_LT((fw - fl).norm(), 1e-4 * fl.norm()) << "a small load: the linear answer";
    else
      EXPECT_GT((fw - fl).norm(), 0.01 * fl.norm()) << "a large one: warped";
  }
}

// A normal displacement on a rotated part of the surface acts along the
// normal it was given in the world, and moves the point by exactly δ along
// it: the direction is rotated into the point's frame for the solve and its
// answer rotated back, not one without the other (which would give a force
// off the normal, or a displacement along it that is not δ).
TEST_F(WarpingTest, ANormalDisplacementStaysNormalOnARotatedPart) {
  const RotationField field(surface(), default_smoothing_radius(surface()));
  auto grasped = top_face(100);
  // The point: on the top face 25 mm from the free end, in the lifted part.
  int probe = -1;
  for (const int v : top_face(75))
    if (std::abs(surface().rest_position(v).x() - 0.075) < 1e-9 &&
        std::abs(surface().rest_position(v).y() - 0.025) < 1e-9)
      probe = v;
  ASSERT_GE(probe, 0);
  SolverLimits limits;
  WarpedSolver warped(model(), limits, field);
  const Eigen::Vector3d a(0, 0, 0.02);
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(25 * M_PI / 180, -Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Vector3d n = R * Eigen::Vector3d::UnitZ();  // the lifted top face's normal
  const double delta = -0.001;
  ASSERT_EQ(warped.begin(grasped.size() + 1), RequestStatus::kOk);
  for (const int v : grasped) {
    const Eigen::Vector3d p = surface().rest_position(v);
    const Eigen::Vector3d d = a + R * (p - a) - p;
    ASSERT_EQ(warped.add(vertex(v), 1, d.data(), n.data()), RequestStatus::kOk);
  }
  const double value[3] = {delta, 0, 0};
  ASSERT_EQ(warped.add(vertex(probe), 2, value, n.data()), RequestStatus::kOk);
  ASSERT_EQ(warped.solve(), RequestStatus::kOk) << warped.message();
  const auto j = grasped.size();
  const Eigen::Map<const Eigen::Vector3d> f(&warped.forces()[3 * j]);
  const Eigen::Map<const Eigen::Vector3d> x(&warped.displacements()[3 * j]);
  EXPECT_GT(f.norm(), 1e-4);
  EXPECT_LT(f.cross(n).norm(), 1e-12 * f.norm());
  EXPECT_NEAR(n.dot(x), delta, 1e-9 * std::abs(delta));
  // The rotation there is the lift's, roughly: the frame is not the rest one.
  const Eigen::Map<const Eigen::Vector3d> w(
      &warped.rotations()[3 * static_cast<std::size_t>(probe)]);
  EXPECT_GT(w.norm(), 0.2);
}

// The first solve is the linear solver's, with its checks and words; a
// request whose rotations do not settle is refused, never answered.
TEST_F(WarpingTest, BadRequestsAndUnsettledOnesAreRefusedWithAMessage) {
  const RotationField field(surface(), default_smoothing_radius(surface()));
  SolverLimits limits;
  WarpedSolver warped(model(), limits, field);
  ASSERT_EQ(warped.begin(1), RequestStatus::kOk);
  const double value[3] = {0, 0, 0.001};
  EXPECT_EQ(warped.add(model().mesh_vertex_count() + 5, 1, value, value),
            RequestStatus::kVertexOutOfRange);
  EXPECT_NE(std::string(warped.message()).find("not a vertex of model"), std::string::npos)
      << warped.message();

  WarpingLimits two;
  two.max_iterations = 2;
  WarpedSolver hurried(model(), limits, field, two);
  EXPECT_EQ(lift(hurried, top_face(87.5), 30), RequestStatus::kIllConditioned);
  EXPECT_NE(std::string(hurried.message()).find("did not settle"), std::string::npos)
      << hurried.message();
}

}  // namespace
}  // namespace palpate
