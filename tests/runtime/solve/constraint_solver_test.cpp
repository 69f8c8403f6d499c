// The run-time algebra (docs/model/requests.md, "The reduced system of a request") against dense
// computations on the full G of a real compliance file, every request error, and the reuse of
// factorizations.

#include "palpate/runtime/constraint_solver.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <random>
#include <span>
#include <string>

#include "palpate/runtime/surface_model.hpp"
#include "support/allocation_counter.hpp"
#include "support/box_job.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

// G has entries of order 1e-4 m/N; the small systems are well conditioned
// (condition ≤ 1e4), so solves agree with dense references to ~1e-12
// relative; 1e-9 leaves three orders of margin.
constexpr double kSolverTolerance = 1e-9;

struct Request {
  std::uint32_t vertex;
  ConstraintKind kind;
  Eigen::Vector3d value;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
};

class ConstraintSolverTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    model_ =
        new SurfaceModel(load_surface_model("box", testing::write_box_compliance(dir_->path())));
  }
  static void TearDownTestSuite() {
    delete model_;
    delete dir_;
  }

  static const SurfaceModel& model() { return *model_; }
  /// Mesh id of compliance vertex i.
  static std::uint32_t vertex(int i) {
    return model_->surface.vertex_ids[static_cast<std::size_t>(i)];
  }

  static RequestStatus run(ConstraintSolver& solver, const std::vector<Request>& requests) {
    RequestStatus status = solver.begin(requests.size());
    for (const auto& r : requests) {
      if (status != RequestStatus::kOk) return status;
      status =
          solver.add(r.vertex, static_cast<std::int32_t>(r.kind), r.value.data(), r.normal.data());
    }
    return status == RequestStatus::kOk ? solver.solve() : status;
  }

  /// u = G f over the whole surface, f non-zero on the request's vertices only.
  static Eigen::VectorXd full_field(const ConstraintSolver& solver) {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(model().G.rows());
    for (int j = 0; j < solver.size(); ++j)
      f.segment<3>(3 * solver.load_indices()[j]) = solver.forces().segment<3>(3 * j);
    return model().G * f;
  }

  static double relative(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return (a - b).norm() / std::max(b.norm(), std::numeric_limits<double>::min());
  }

  inline static testing::TempDir* dir_ = nullptr;
  inline static SurfaceModel* model_ = nullptr;
};

TEST_F(ConstraintSolverTest, DescribesTheSurfaceForDrawing) {
  const SurfaceModel& m = model();
  const int n = m.compliance_vertex_count();
  ASSERT_GT(n, 10);
  EXPECT_EQ(m.G.rows(), 3 * n);
  EXPECT_GT(m.surface.vertex_ids.size(), static_cast<std::size_t>(n))
      << "fixed surface vertices are drawn after";
  EXPECT_EQ(m.surface.rest_positions_m.size(), 3 * m.surface.vertex_ids.size());
  for (std::uint32_t corner : m.surface.triangles) EXPECT_LT(corner, m.surface.vertex_ids.size());
  for (std::size_t i = 0; i < m.surface.vertex_ids.size(); ++i) {
    const std::int32_t role = m.compliance_index_of_vertex[m.surface.vertex_ids[i]];
    if (static_cast<int>(i) < n)
      EXPECT_EQ(role, static_cast<std::int32_t>(i));
    else
      EXPECT_EQ(role, static_cast<std::int32_t>(VertexRole::kFixed));
  }
  // The clamped face x = 0 is fixed: its vertices are drawn but not constrainable.
  for (std::size_t i = static_cast<std::size_t>(n); i < m.surface.vertex_ids.size(); ++i)
    EXPECT_NEAR(m.surface.rest_positions_m[3 * i], 0.0, 1e-12);
}

TEST_F(ConstraintSolverTest, ForcesGiveTheColumnsOfG) {
  ConstraintSolver solver(model(), {});
  const std::vector<Request> forces{{vertex(3), ConstraintKind::kForce, {0.1, -0.2, 0.3}},
                                    {vertex(17), ConstraintKind::kForce, {0, 0, -1.5}}};
  ASSERT_EQ(run(solver, forces), RequestStatus::kOk);
  EXPECT_EQ(solver.forces(), (Eigen::VectorXd(6) << 0.1, -0.2, 0.3, 0, 0, -1.5).finished());
  Eigen::VectorXd u(model().G.rows());
  solver.surface_displacement(u);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(model().G.rows());
  f.segment<3>(9) = forces[0].value;
  f.segment<3>(51) = forces[1].value;
  const Eigen::VectorXd expected = model().G * f;
  EXPECT_LT(relative(u, expected), kSolverTolerance);
  EXPECT_LT(relative(solver.displacements().segment<3>(0), expected.segment<3>(9)),
            kSolverTolerance);
  EXPECT_LT((solver.total_force() - Eigen::Vector3d(0.1, -0.2, -1.2)).norm(), 1e-15);
}

TEST_F(ConstraintSolverTest, ImposedDisplacementsSolveTheCompliance) {
  // docs/model/requests.md: G_CC F_C = U_C, U_S = G_SC F_C; the reference solves the same
  // system with Eigen's full-pivot LU.
  ConstraintSolver solver(model(), {});
  const std::vector<int> patch{5, 6, 12, 20};
  std::vector<Request> requests;
  Eigen::VectorXd U(3 * patch.size());
  for (std::size_t j = 0; j < patch.size(); ++j) {
    const Eigen::Vector3d u(0.001 * static_cast<double>(j), -0.002, 0.0005);
    U.segment<3>(3 * static_cast<Eigen::Index>(j)) = u;
    requests.push_back({vertex(patch[j]), ConstraintKind::kDisplacement, u});
  }
  ASSERT_EQ(run(solver, requests), RequestStatus::kOk);
  Eigen::MatrixXd G_CC(U.size(), U.size());
  for (std::size_t a = 0; a < patch.size(); ++a)
    for (std::size_t b = 0; b < patch.size(); ++b)
      G_CC.block<3, 3>(3 * static_cast<Eigen::Index>(a), 3 * static_cast<Eigen::Index>(b)) =
          model().G.block<3, 3>(3 * patch[a], 3 * patch[b]);
  const Eigen::VectorXd F = G_CC.fullPivLu().solve(U);
  EXPECT_LT(relative(solver.forces(), F), kSolverTolerance);
  EXPECT_LT(relative(solver.displacements(), U), kSolverTolerance);
  Eigen::VectorXd u(model().G.rows());
  solver.surface_displacement(u);
  EXPECT_LT(relative(u, full_field(solver)), kSolverTolerance);
  // The condition estimate (LAPACK dpocon) against the exact 1-norm condition:
  // a lower bound, usually within a factor 3.
  const double exact = G_CC.cwiseAbs().colwise().sum().maxCoeff() *
                       G_CC.inverse().cwiseAbs().colwise().sum().maxCoeff();
  EXPECT_LE(solver.condition_estimate(), exact * (1 + 1e-8));
  EXPECT_GE(solver.condition_estimate(), exact / 10);
}

TEST_F(ConstraintSolverTest, MixedConstraintsMeetTheirDefinitions) {
  // One vertex with a known force, one with an imposed displacement, two
  // sliding (normal displacement): check each condition on the result.
  ConstraintSolver solver(model(), {});
  const Eigen::Vector3d n1 = Eigen::Vector3d(0.2, 0.1, 1).normalized();
  const Eigen::Vector3d n2(0, -1, 0);
  const std::vector<Request> requests{
      {vertex(2), ConstraintKind::kForce, {0.5, 0, -0.25}},
      {vertex(9), ConstraintKind::kDisplacement, {0, 0.001, -0.003}},
      {vertex(14),
       ConstraintKind::kNormalDisplacement,
       {-0.002, 0, 0},
       3.0 * n1},  // unnormalized on purpose
      {vertex(30), ConstraintKind::kNormalDisplacement, {0.0015, 0, 0}, n2},
  };
  ASSERT_EQ(run(solver, requests), RequestStatus::kOk);
  const auto f = solver.forces();
  const Eigen::VectorXd u = full_field(solver);
  auto u_at = [&](int i) { return Eigen::Vector3d(u.segment<3>(3 * i)); };

  EXPECT_LT((f.segment<3>(0) - requests[0].value).norm(), 1e-15);
  EXPECT_LT((u_at(9) - requests[1].value).norm(), kSolverTolerance * requests[1].value.norm());
  EXPECT_NEAR(n1.dot(u_at(14)), -0.002, kSolverTolerance * 0.002);
  EXPECT_NEAR(n2.dot(u_at(30)), 0.0015, kSolverTolerance * 0.0015);
  // Sliding is frictionless: the force is along the normal.
  const Eigen::Vector3d f14 = f.segment<3>(6), f30 = f.segment<3>(9);
  EXPECT_LT((f14 - f14.dot(n1) * n1).norm(), 1e-12 * f14.norm());
  EXPECT_LT((f30 - f30.dot(n2) * n2).norm(), 1e-12 * f30.norm());
  // The reported displacements of the constrained vertices are those of u.
  for (int j : {0, 1, 2, 3})
    EXPECT_LT((solver.displacements().segment<3>(3 * j) - u_at(solver.load_indices()[j])).norm(),
              kSolverTolerance * u.norm());
}

TEST_F(ConstraintSolverTest, ReusesTheFactorizationWhileTheSetStaysTheSame) {
  ConstraintSolver solver(model(), {.max_constraints = 8, .cache_slots = 2, .max_condition = 1e12});
  ConstraintSolver fresh_solver(model(),
                                {.max_constraints = 8, .cache_slots = 1, .max_condition = 1e12});
  auto patch = [&](int first, double depth) {
    return std::vector<Request>{
        {vertex(first), ConstraintKind::kDisplacement, {0, 0, -depth}},
        {vertex(first + 1), ConstraintKind::kNormalDisplacement, {-depth, 0, 0}, {0, 0, 1}},
        {vertex(first + 2), ConstraintKind::kForce, {0, 0.1, 0}}};
  };
  ASSERT_EQ(run(solver, patch(0, 0.001)), RequestStatus::kOk);
  EXPECT_FALSE(solver.reused_factorization());
  // Three structures through two slots: 0 and 10 alternate, 20 evicts the older.
  for (int round = 0; round < 3; ++round)
    for (int first : {0, 10, 20, 10}) {
      const double depth = 0.001 * (1 + round) + 1e-4 * first;
      ASSERT_EQ(run(solver, patch(first, depth)), RequestStatus::kOk);
      ASSERT_EQ(run(fresh_solver, patch(first, depth)), RequestStatus::kOk);
      EXPECT_LT(relative(solver.forces(), fresh_solver.forces()), 1e-14) << "first " << first;
    }
  ASSERT_EQ(run(solver, patch(10, 0.002)), RequestStatus::kOk);
  EXPECT_TRUE(solver.reused_factorization());
  ASSERT_EQ(run(solver, patch(10, 0.003)), RequestStatus::kOk);
  EXPECT_TRUE(solver.reused_factorization()) << "only the right-hand side changed";
  // A different normal is a different system.
  auto tilted = patch(10, 0.003);
  tilted[1].normal = {0, 0.1, 1};
  ASSERT_EQ(run(solver, tilted), RequestStatus::kOk);
  EXPECT_FALSE(solver.reused_factorization());
}

TEST_F(ConstraintSolverTest, EveryBadRequestGetsItsStatusAndMessage) {
  ConstraintSolver solver(model(), {.max_constraints = 4, .cache_slots = 2, .max_condition = 1e12});
  const SurfaceModel& m = model();
  std::uint32_t interior = 0, fixed = 0;
  for (std::uint32_t v = 0; v < m.mesh_vertex_count(); ++v) {
    if (m.compliance_index_of_vertex[v] == static_cast<std::int32_t>(VertexRole::kInterior))
      interior = v;
    if (m.compliance_index_of_vertex[v] == static_cast<std::int32_t>(VertexRole::kFixed)) fixed = v;
  }
  ASSERT_LT(m.compliance_index_of_vertex[interior], 0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const Eigen::Vector3d push(0, 0, -0.001);
  struct Case {
    std::vector<Request> requests;
    RequestStatus status;
    std::string fragment;
  };
  const std::vector<Case> cases{
      {{{m.mesh_vertex_count(), ConstraintKind::kForce, push}},
       RequestStatus::kVertexOutOfRange,
       "is not a vertex"},
      {{{interior, ConstraintKind::kForce, push}},
       RequestStatus::kVertexNotOnSurface,
       "inside the organ"},
      {{{fixed, ConstraintKind::kDisplacement, push}}, RequestStatus::kVertexFixed, "is fixed"},
      {{{vertex(1), ConstraintKind::kForce, push}, {vertex(1), ConstraintKind::kForce, push}},
       RequestStatus::kDuplicateVertex,
       "appears twice"},
      {{{vertex(1), ConstraintKind::kDisplacement, {0, nan, 0}}},
       RequestStatus::kNonFiniteValue,
       "value[1]"},
      {{{vertex(1), ConstraintKind::kForce, {inf, 0, 0}}},
       RequestStatus::kNonFiniteValue,
       "finite"},
      {{{vertex(1), ConstraintKind::kNormalDisplacement, push, {nan, 0, 1}}},
       RequestStatus::kNonFiniteValue,
       "normal[0]"},
      {{{vertex(1), ConstraintKind::kNormalDisplacement, push, {0, 0, 0}}},
       RequestStatus::kBadConstraint,
       "no direction"},
      {{{vertex(1), static_cast<ConstraintKind>(7), push}},
       RequestStatus::kBadConstraint,
       "unknown kind 7"},
      {std::vector<Request>(5, {vertex(1), ConstraintKind::kForce, push}),
       RequestStatus::kTooManyConstraints, "at most 4"},
  };
  for (const auto& c : cases) {
    EXPECT_EQ(run(solver, c.requests), c.status) << c.fragment;
    EXPECT_NE(std::string(solver.message()).find(c.fragment), std::string::npos)
        << solver.message();
    EXPECT_STRNE(status_name(c.status), "unknown_status");
    EXPECT_EQ(solver.condition_estimate(), 1.0) << "no system was solved: no stale estimate";
    // The solver is usable after every refusal.
    ASSERT_EQ(run(solver, {{vertex(1), ConstraintKind::kDisplacement, push}}), RequestStatus::kOk);
    EXPECT_STREQ(solver.message(), "");
  }
}

TEST_F(ConstraintSolverTest, RefusesASolutionThatOverflows) {
  // Finite values so large that a force or the total force is infinite
  // (found by fuzz_request): refused, never an ok reply carrying inf or NaN.
  ConstraintSolver solver(model(), {.max_constraints = 4, .cache_slots = 2, .max_condition = 1e12});
  const std::vector<std::vector<Request>> cases{
      {{vertex(1), ConstraintKind::kDisplacement, {1e308, 0, 0}}},
      {{vertex(1), ConstraintKind::kForce, {1.5e308, 0, 0}},
       {vertex(2), ConstraintKind::kForce, {1.5e308, 0, 0}}}};
  for (const auto& requests : cases) {
    EXPECT_EQ(run(solver, requests), RequestStatus::kNonFiniteValue);
    EXPECT_NE(std::string(solver.message()).find("overflows"), std::string::npos)
        << solver.message();
    ASSERT_EQ(run(solver, {{vertex(1), ConstraintKind::kDisplacement, {0, 0, -0.001}}}),
              RequestStatus::kOk);
  }
}

TEST_F(ConstraintSolverTest, RefusesValuesBeyondTheModelsBoundsWithTheirOwnStatus) {
  // The box is 0.1 m long; palpated's default bound is 10 % of the organ's
  // size. 3 (mm typed as m) and 500 N are refused; 9 mm and 40 N are not.
  ConstraintSolver solver(model(), {.max_constraints = 4,
                                    .cache_slots = 2,
                                    .max_condition = 1e12,
                                    .max_displacement_m = 0.01,
                                    .max_force_n = 50});
  const struct {
    Request request;
    RequestStatus status;
    const char* says;
  } cases[] = {
      {{vertex(1), ConstraintKind::kDisplacement, {0, 0, -3}},
       RequestStatus::kDisplacementTooLarge,
       "a displacement of 3 m is larger than model 'box' accepts (0.01 m"},
      {{vertex(1), ConstraintKind::kNormalDisplacement, {-0.02, 0, 0}, {0, 0, 1}},
       RequestStatus::kDisplacementTooLarge,
       "0.02 m"},
      {{vertex(1), ConstraintKind::kForce, {300, 400, 0}},
       RequestStatus::kForceTooLarge,
       "a force of 500 N is larger than accepted (50 N"},
      {{vertex(1), ConstraintKind::kDisplacement, {0, 0, -0.009}}, RequestStatus::kOk, ""},
      {{vertex(1), ConstraintKind::kForce, {0, 0, -40}}, RequestStatus::kOk, ""},
  };
  for (const auto& c : cases) {
    EXPECT_EQ(run(solver, {c.request}), c.status) << c.says;
    EXPECT_NE(std::string(solver.message()).find(c.says), std::string::npos) << solver.message();
  }
  EXPECT_STREQ(status_name(RequestStatus::kDisplacementTooLarge), "displacement_too_large");
  EXPECT_STREQ(status_name(RequestStatus::kForceTooLarge), "force_too_large");
}

TEST_F(ConstraintSolverTest, FieldsAKindDoesNotUseAreIgnored) {
  // docs/dds.md: `normal` matters to normal-displacement constraints only; a
  // NaN there on a force or a displacement constraint changes nothing.
  ConstraintSolver solver(model(), {});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const ConstraintKind kind : {ConstraintKind::kForce, ConstraintKind::kDisplacement}) {
    const Eigen::Vector3d value(0, 0, kind == ConstraintKind::kForce ? -1.0 : -0.001);
    ASSERT_EQ(run(solver, {{vertex(1), kind, value, {0, 0, 0}}}), RequestStatus::kOk);
    const Eigen::VectorXd plain = full_field(solver);
    ASSERT_EQ(run(solver, {{vertex(1), kind, value, {nan, nan, nan}}}), RequestStatus::kOk);
    EXPECT_EQ(relative(full_field(solver), plain), 0.0);
  }
}

TEST_F(ConstraintSolverTest, RefusesSystemsAboveTheConditionLimit) {
  // Two neighbouring vertices with full imposed displacements give a system
  // whose condition is well above 1; a limit of 2 refuses it and says why.
  ConstraintSolver strict(model(), {.max_constraints = 4, .cache_slots = 2, .max_condition = 2});
  const std::vector<Request> requests{{vertex(0), ConstraintKind::kDisplacement, {0, 0, 0.001}},
                                      {vertex(1), ConstraintKind::kDisplacement, {0, 0, 0.001}}};
  EXPECT_EQ(run(strict, requests), RequestStatus::kIllConditioned);
  EXPECT_GT(strict.condition_estimate(), 2);
  EXPECT_NE(std::string(strict.message()).find("condition estimate"), std::string::npos)
      << strict.message();
  // The same request is accepted under the default limit, with the same estimate.
  ConstraintSolver lenient(model(), {});
  ASSERT_EQ(run(lenient, requests), RequestStatus::kOk);
  EXPECT_NEAR(lenient.condition_estimate(), strict.condition_estimate(),
              1e-12 * strict.condition_estimate());
}

TEST_F(ConstraintSolverTest, AllocatesNothingPerRequest) {
  // The daemon's request path: begin/add/solve and the surface field, with
  // factorizations reused and rebuilt, and refused requests.
  ConstraintSolver solver(
      model(),
      {.max_constraints = 8, .cache_slots = 2, .max_condition = 1e12, .surface_threads = 2});
  Eigen::VectorXd u(model().G.rows());
  auto request = [&](int first, double depth) {
    const std::vector<Request> patch{
        {vertex(first), ConstraintKind::kDisplacement, {0, 0, -depth}},
        {vertex(first + 1), ConstraintKind::kNormalDisplacement, {-depth, 0, 0}, {0, 0, 1}},
        {vertex(first + 2), ConstraintKind::kForce, {0, 0.1, 0}}};
    return patch;
  };
  const std::vector<std::vector<Request>> requests{
      request(0, 0.001),
      request(10, 0.002),
      request(20, 0.001),
      {{vertex(3), ConstraintKind::kForce, {0, 0, std::nan("")}}}};
  for (const auto& r : requests) run(solver, r);  // the vectors above are the only allocations
  const std::uint64_t before = testing::allocations_here();
  int refused = 0;
  for (int i = 0; i < 200; ++i) {
    if (run(solver, requests[static_cast<std::size_t>(i % 4)]) == RequestStatus::kOk)
      solver.surface_displacement(u);
    else
      ++refused;
  }
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  EXPECT_EQ(refused, 50);
  // The counter does count: one vector is one allocation.
  std::vector<double> one(static_cast<std::size_t>(u.size()), 1.0);
  EXPECT_EQ(testing::allocations_here() - before, 1u);
  EXPECT_EQ(one.back(), 1.0);
}

TEST_F(ConstraintSolverTest, SplitsTheSurfaceFieldOverTwoThreadsBitForBit) {
  // Each row is the same sum in the same order on either thread.
  ConstraintSolver one(model(), {.surface_threads = 1});
  ConstraintSolver two(model(), {.surface_threads = 2});
  Eigen::VectorXd u1(model().G.rows()), u2(model().G.rows());
  for (int first : {0, 7, 15, 7}) {
    const std::vector<Request> patch{
        {vertex(first), ConstraintKind::kDisplacement, {0, 0, -0.002}},
        {vertex(first + 3), ConstraintKind::kForce, {0.1, 0, 0}},
        {vertex(first + 9), ConstraintKind::kNormalDisplacement, {0.001, 0, 0}, {0, 1, 0}}};
    ASSERT_EQ(run(one, patch), RequestStatus::kOk);
    ASSERT_EQ(run(two, patch), RequestStatus::kOk);
    one.surface_displacement(u1);
    u2.setConstant(std::nan(""));
    two.surface_displacement(u2);
    EXPECT_EQ(u1, u2) << "first " << first;
    EXPECT_LT(relative(u2, full_field(two)), kSolverTolerance);
  }
}

TEST_F(ConstraintSolverTest, AnEmptyRequestIsTheRestState) {
  ConstraintSolver solver(model(), {});
  ASSERT_EQ(run(solver, {}), RequestStatus::kOk);
  Eigen::VectorXd u = Eigen::VectorXd::Ones(model().G.rows());
  solver.surface_displacement(u);
  EXPECT_EQ(u.norm(), 0.0);
  EXPECT_EQ(solver.total_force().norm(), 0.0);
}

/// A surface triangle of the model by mesh vertex ids: the first whose
/// vertices are all compliance vertices (@p with_fixed false), or the first
/// with exactly one fixed vertex.
std::array<std::uint32_t, 3> surface_triangle(const SurfaceModel& m, bool with_fixed,
                                              int skip = 0) {
  const DrawnSurface& s = m.surface;
  for (int t = 0; t < s.triangle_count(); ++t) {
    std::array<std::uint32_t, 3> ids{};
    int fixed = 0;
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t v = s.triangles[3 * static_cast<std::size_t>(t) + c];
      ids[static_cast<std::size_t>(c)] = s.vertex_ids[v];
      fixed += static_cast<int>(v) >= s.compliance_vertex_count ? 1 : 0;
    }
    if (fixed == (with_fixed ? 1 : 0) && skip-- == 0) return ids;
  }
  ADD_FAILURE() << "no such triangle";
  return {};
}

constexpr double kNoNormal[3] = {0, 0, 0};

TEST_F(ConstraintSolverTest, PointsOnTrianglesMeetTheirDefinitions) {
  // Against the dense definition: H maps the surface to the points
  // (u_p = Σ w_i u_{a_i}), the loads are f_S = Hᵀ f_C, u_S = G f_S.
  const SurfaceModel& m = model();
  ConstraintSolver solver(m, {});
  const auto t1 = surface_triangle(m, false, 0);
  const auto t2 = surface_triangle(m, false, 40);
  const auto t3 = surface_triangle(m, true);
  const std::array<double, 3> w1{0.2, 0.3, 0.5}, w2{0.6, 0.1, 0.3}, w3{0.25, 0.25, 0.5};
  const Eigen::Vector3d d1(0.0005, -0.001, -0.002), n2 = Eigen::Vector3d(0.1, -0.2, 1).normalized();
  const Eigen::Vector3d f3(0, 0.2, -0.3);
  ASSERT_EQ(solver.begin(3), RequestStatus::kOk);
  ASSERT_EQ(solver.add_point(t1, w1, 1, d1.data(), kNoNormal), RequestStatus::kOk)
      << solver.message();
  const double normal_value[3] = {-0.0015, 0, 0};
  ASSERT_EQ(solver.add_point(t2, w2, 2, normal_value, n2.data()), RequestStatus::kOk)
      << solver.message();
  ASSERT_EQ(solver.add_point(t3, w3, 0, f3.data(), kNoNormal), RequestStatus::kOk)
      << solver.message();
  ASSERT_EQ(solver.solve(), RequestStatus::kOk) << solver.message();

  const Eigen::Index rows = m.G.rows();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(9, rows);
  const std::array<std::array<std::uint32_t, 3>, 3> ids{t1, t2, t3};
  const std::array<std::array<double, 3>, 3> ws{w1, w2, w3};
  for (int p = 0; p < 3; ++p)
    for (int i = 0; i < 3; ++i) {
      const int a = m.compliance_index_of_vertex[ids[p][i]];
      if (a < 0) continue;  // fixed: no displacement, its share goes to the attachment
      H.block<3, 3>(3 * p, 3 * a) += ws[p][i] * Eigen::Matrix3d::Identity();
    }
  const Eigen::VectorXd f = solver.forces();
  const Eigen::VectorXd u_S = m.G * (H.transpose() * f);
  const Eigen::VectorXd u_C = H * u_S;
  EXPECT_LT((u_C.segment<3>(0) - d1).norm(), kSolverTolerance * d1.norm());
  EXPECT_NEAR(n2.dot(u_C.segment<3>(3)), -0.0015, kSolverTolerance * 0.0015);
  const Eigen::Vector3d fn = f.segment<3>(3);
  EXPECT_LT((fn - fn.dot(n2) * n2).norm(), 1e-12 * fn.norm()) << "sliding: along the normal";
  EXPECT_LT((f.segment<3>(6) - f3).norm(), 1e-15);
  EXPECT_LT(relative(solver.displacements(), u_C), kSolverTolerance);
  Eigen::VectorXd u(rows);
  solver.surface_displacement(u);
  EXPECT_LT(relative(u, u_S), kSolverTolerance);
  // The loads carry the whole force but the attachment's share.
  Eigen::Vector3d loads = Eigen::Vector3d::Zero();
  for (std::size_t l = 0; l < solver.load_indices().size(); ++l)
    loads += Eigen::Map<const Eigen::Vector3d>(&solver.load_forces()[3 * l]);
  const int fixed_corner = m.compliance_index_of_vertex[t3[0]] < 0   ? 0
                           : m.compliance_index_of_vertex[t3[1]] < 0 ? 1
                                                                     : 2;
  EXPECT_LT((loads + w3[fixed_corner] * f3 - solver.total_force()).norm(),
            1e-14 * solver.total_force().norm());
}

TEST_F(ConstraintSolverTest, APointAtAVertexIsTheVertexBitForBit) {
  // Weights (1, 0, 0) on a triangle, a one-vertex point and add(): the same
  // numbers, so that a contact at a vertex feels as it did.
  const SurfaceModel& m = model();
  const auto t = surface_triangle(m, false, 3);
  const Eigen::Vector3d d(0.0005, -0.001, -0.002), zero = Eigen::Vector3d::Zero();
  const std::uint32_t other = vertex(30);
  const double push[3] = {-0.001, 0, 0};
  const Eigen::Vector3d n(0, 0, 1);
  auto solve = [&](int how, ConstraintSolver& solver) {
    EXPECT_EQ(solver.begin(2), RequestStatus::kOk);
    const std::array<double, 3> corner{1, 0, 0};
    const std::array<double, 1> one{1};
    RequestStatus s = how == 0 ? solver.add(t[0], 1, d.data(), zero.data())
                      : how == 1
                          ? solver.add_point(std::span(t).first(1), one, 1, d.data(), zero.data())
                          : solver.add_point(t, corner, 1, d.data(), zero.data());
    EXPECT_EQ(s, RequestStatus::kOk) << solver.message();
    EXPECT_EQ(solver.add(other, 2, push, n.data()), RequestStatus::kOk);
    EXPECT_EQ(solver.solve(), RequestStatus::kOk) << solver.message();
  };
  ConstraintSolver a(m, {}), b(m, {}), c(m, {});
  solve(0, a);
  solve(1, b);
  solve(2, c);
  EXPECT_EQ(Eigen::VectorXd(a.forces()), Eigen::VectorXd(b.forces()));
  EXPECT_EQ(Eigen::VectorXd(a.forces()), Eigen::VectorXd(c.forces()));
  EXPECT_EQ(Eigen::VectorXd(a.displacements()), Eigen::VectorXd(c.displacements()));
  Eigen::VectorXd ua(m.G.rows()), uc(m.G.rows());
  a.surface_displacement(ua);
  c.surface_displacement(uc);
  EXPECT_EQ(ua, uc);
}

TEST_F(ConstraintSolverTest, EveryBadPointGetsItsStatusAndMessage) {
  const SurfaceModel& m = model();
  ConstraintSolver solver(m, {});
  const auto t = surface_triangle(m, false);
  const double value[3] = {0, 0, -0.001}, none[3] = {0, 0, 0};
  auto add = [&](std::vector<std::uint32_t> ids, std::vector<double> w) {
    EXPECT_EQ(solver.begin(1), RequestStatus::kOk);
    return solver.add_point(ids, w, 1, value, none);
  };
  EXPECT_EQ(add({t[0], t[1], t[2]}, {0.5, 0.4, 0.2}), RequestStatus::kBadConstraint);
  EXPECT_NE(std::string(solver.message()).find("sum to 1.1"), std::string::npos)
      << solver.message();
  EXPECT_EQ(add({t[0], t[1], t[2]}, {1.5, -0.5, 0}), RequestStatus::kBadConstraint);
  EXPECT_EQ(add({t[0], t[1], t[2]}, {0.5, 0.5, std::nan("")}), RequestStatus::kBadConstraint);
  EXPECT_EQ(add({t[0], t[1]}, {0.5}), RequestStatus::kBadConstraint);
  EXPECT_EQ(add({}, {}), RequestStatus::kBadConstraint);
  EXPECT_EQ(add({t[0], t[0], t[2]}, {0.2, 0.3, 0.5}), RequestStatus::kDuplicateVertex);
  EXPECT_EQ(add({t[0], t[1], m.mesh_vertex_count()}, {0.2, 0.3, 0.5}),
            RequestStatus::kVertexOutOfRange);
  // Three surface vertices that are not one triangle.
  const std::uint32_t far = vertex(m.compliance_vertex_count() - 1);
  ASSERT_NE(far, t[2]);
  EXPECT_EQ(add({t[0], t[1], far}, {0.2, 0.3, 0.5}), RequestStatus::kBadConstraint);
  EXPECT_NE(std::string(solver.message()).find("not a triangle"), std::string::npos)
      << solver.message();
  // Every vertex fixed: nothing can move.
  const DrawnSurface& s = m.surface;
  for (int tri = 0; tri < s.triangle_count(); ++tri) {
    const auto* v = &s.triangles[3 * static_cast<std::size_t>(tri)];
    if (static_cast<int>(std::min({v[0], v[1], v[2]})) < s.compliance_vertex_count) continue;
    EXPECT_EQ(add({s.vertex_ids[v[0]], s.vertex_ids[v[1]], s.vertex_ids[v[2]]}, {0.2, 0.3, 0.5}),
              RequestStatus::kVertexFixed);
    break;
  }
  // An edge of the surface is a point too.
  EXPECT_EQ(add({t[0], t[1]}, {0.25, 0.75}), RequestStatus::kOk) << solver.message();
  EXPECT_EQ(solver.solve(), RequestStatus::kOk);
}

}  // namespace
}  // namespace palpate
