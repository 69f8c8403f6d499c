// The served region's implicit step (lib/runtime/src/region_implicit_step):
// its solve against A assembled densely here from the mesh (the offline
// layer's stiffness, masses from the tetrahedra's volumes), with no
// tensor-mass tensors, before and after tetrahedra are removed, whichever
// way the change reaches the factor: a Woodbury update, the worker's
// factorization adopted, or a factorization on the spot
// (docs/model/hybrid-serving.md, "The implicit step").

#include "palpate/runtime/region/region_implicit_step.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>
#include <vector>

#include "runtime/tensor_mass_meshes.hpp"

namespace palpate::tensor_mass_test {
namespace {

constexpr double kStep_s = 1e-3, kDamping = 20, kSkin = 200;

struct Fixture {
  Region region{cube(true), cube(true).tetrahedra, face_x0(0)};
  std::vector<int> gamma = face_x0(kCells);  // the far face: the rest holds it
  MatrixXd s;                                // a stiff SPD S on it, N/m
  std::vector<char> skin_as_built, on_skin;
  std::vector<int> removed;

  Fixture() {
    std::mt19937 rng(7);
    std::normal_distribution<double> normal;
    const auto n = static_cast<Eigen::Index>(3 * gamma.size());
    MatrixXd b(n, n);
    for (Eigen::Index i = 0; i < b.size(); ++i) b.data()[i] = normal(rng);
    s = 50.0 * (b * b.transpose() / static_cast<double>(n)) + 100.0 * MatrixXd::Identity(n, n);
    // The sides y = 0 and y = 4 cm are touchable, Γ and the held face not.
    skin_as_built.assign(static_cast<std::size_t>(region.model.vertex_count()), 0);
    for (int i = 1; i < kCells; ++i)
      for (int k = 0; k <= kCells; ++k) {
        skin_as_built[vertex(i, 0, k)] = 1;
        skin_as_built[vertex(i, kCells, k)] = 1;
      }
    refresh_skin();
  }
  void refresh_skin() {
    on_skin = skin_as_built;
    for (int v = 0; v < region.model.vertex_count(); ++v)
      if (region.model.is_detached(v)) on_skin[v] = 0;
  }
  /// Removes tetrahedra @p tets; @returns the vertices they had.
  std::vector<int> remove(const std::vector<int>& tets) {
    std::vector<int> touched;
    for (int t : tets) {
      region.model.remove_tetrahedron(t);
      removed.push_back(t);
      for (int c = 0; c < 4; ++c) touched.push_back(region.tets(t, c));
    }
    refresh_skin();
    return touched;
  }

  /// A on every DOF (fixed ones too, their rows unused), from the mesh.
  MatrixXd dense_a(double hold_n_per_m) const {
    std::vector<int> kept;
    for (int t = 0; t < region.tets.rows(); ++t)
      if (std::find(removed.begin(), removed.end(), t) == removed.end()) kept.push_back(t);
    const Eigen::MatrixX4i tets = rows(region.tets, kept);
    const int nv = region.model.vertex_count();
    MatrixXd a = kept.empty() ? MatrixXd::Zero(3 * nv, 3 * nv) : full_stiffness(region.mesh, tets);
    std::vector<double> mass(static_cast<std::size_t>(nv), 0.0);
    std::vector<int> count(static_cast<std::size_t>(nv), 0);
    for (Eigen::Index t = 0; t < tets.rows(); ++t) {
      const Vector3d p0 = region.mesh.vertices.row(tets(t, 0)).transpose();
      const double volume =
          (Vector3d(region.mesh.vertices.row(tets(t, 1)).transpose()) - p0)
              .dot((Vector3d(region.mesh.vertices.row(tets(t, 2)).transpose()) - p0)
                       .cross(Vector3d(region.mesh.vertices.row(tets(t, 3)).transpose()) - p0)) /
          6;
      for (int c = 0; c < 4; ++c) {
        mass[tets(t, c)] += kTissue.density_kg_m3 * volume / 4;
        ++count[tets(t, c)];
      }
    }
    const double c = 1 / (kStep_s * kStep_s) + kDamping / kStep_s;
    std::vector<char> on_gamma(static_cast<std::size_t>(nv), 0);
    for (int v : gamma) on_gamma[v] = 1;
    for (int v = 0; v < nv; ++v) {
      const double held = count[v] == 0 && on_gamma[v] == 0 ? hold_n_per_m : 0.0;
      a.block<3, 3>(3 * v, 3 * v) +=
          (c * mass[v] + (on_skin[v] != 0 ? kSkin : 0.0) + held) * Eigen::Matrix3d::Identity();
    }
    for (std::size_t p = 0; p < gamma.size(); ++p)
      for (std::size_t q = 0; q < gamma.size(); ++q)
        a.block<3, 3>(3 * gamma[p], 3 * gamma[q]) += s.block<3, 3>(3 * p, 3 * q);
    return a;
  }
};

/// The implicit step's solve against the dense A's (on the free DOFs) for a
/// random right-hand side, relative; and its Γ rows of (A − S) x.
double solve_error(Fixture& f, detail::ImplicitRegionStep& step, double* rows_error) {
  const TensorMassModel& m = f.region.model;
  const MatrixXd a = f.dense_a(step.hold_stiffness());
  std::vector<int> free_dofs;
  for (int v = 0; v < m.vertex_count(); ++v)
    if (!m.is_fixed(v))
      for (int c = 0; c < 3; ++c) free_dofs.push_back(3 * v + c);
  const auto n = static_cast<Eigen::Index>(free_dofs.size());
  MatrixXd a_free(n, n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j) a_free(i, j) = a(free_dofs[i], free_dofs[j]);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> d(-1, 1);
  VectorXd b = VectorXd::Zero(3 * m.vertex_count()), b_free(n);
  for (Eigen::Index i = 0; i < n; ++i) b[free_dofs[i]] = b_free[i] = d(rng);
  const VectorXd expected_free = a_free.ldlt().solve(b_free);
  VectorXd expected = VectorXd::Zero(b.size());
  for (Eigen::Index i = 0; i < n; ++i) expected[free_dofs[i]] = expected_free[i];
  VectorXd x(b.size());
  step.solve(b, x);

  // (A − S) x on Γ's rows.
  MatrixXd a_minus_s = a;
  for (std::size_t p = 0; p < f.gamma.size(); ++p)
    for (std::size_t q = 0; q < f.gamma.size(); ++q)
      a_minus_s.block<3, 3>(3 * f.gamma[p], 3 * f.gamma[q]) -= f.s.block<3, 3>(3 * p, 3 * q);
  const VectorXd full = a_minus_s * x;
  VectorXd rows_expected(3 * f.gamma.size()), rows(3 * f.gamma.size());
  for (std::size_t k = 0; k < f.gamma.size(); ++k)
    rows_expected.segment<3>(3 * k) = full.segment<3>(3 * f.gamma[k]);
  step.interface_rows(x, rows);
  *rows_error = (rows - rows_expected).norm() / rows_expected.norm();
  return (x - expected).norm() / expected.norm();
}

detail::ImplicitRegionStep make_step(Fixture& f, int refactor_rank) {
  return detail::ImplicitRegionStep(f.region.model, f.gamma, f.s, {kStep_s, kDamping, kSkin},
                                    f.on_skin, refactor_rank);
}

TEST(ImplicitRegionStep, SolvesTheAssembledSystem) {
  Fixture f;
  auto step = make_step(f, 96);
  double rows = 0;
  EXPECT_LE(solve_error(f, step, &rows), 1e-11);
  EXPECT_LE(rows, 1e-11);
  EXPECT_EQ(step.factorizations(), 1);
  EXPECT_EQ(step.update_rank(), 0);
}

// Cuts that stay under the bound: Woodbury corrections on one factor.
TEST(ImplicitRegionStep, ACutIsALowRankUpdateOfTheFactor) {
  Fixture f;
  auto step = make_step(f, 3000);
  for (int t = 0; t < 60; t += 3) {
    step.update(f.remove({t, t + 1, t + 2}), f.on_skin);
    double rows = 0;
    ASSERT_LE(solve_error(f, step, &rows), 1e-10) << "after tetrahedron " << t;
    ASSERT_LE(rows, 1e-10);
  }
  EXPECT_EQ(step.factorizations(), 1) << "no factorization: updates only";
  EXPECT_GT(step.update_rank(), 60);
  int detached = 0;
  for (int v = 0; v < f.region.model.vertex_count(); ++v) detached += step.holds(v);
  EXPECT_GT(detached, 0) << "the cuts left vertices without a tetrahedron, held";
}

// Past the bound the worker factors A again; what was cut meanwhile is an
// update of its factor. Past four times the bound, A is factored at once.
TEST(ImplicitRegionStep, PastTheBoundAIsFactoredAgain) {
  Fixture f;
  auto step = make_step(f, 18);
  step.update(f.remove({200, 201, 202, 203}), f.on_skin);  // inside the cube
  ASSERT_GE(step.update_rank(), 18) << "past the bound: the worker starts";
  step.update(f.remove({300}), f.on_skin);  // a cut while it works
  step.finish_background_work(f.on_skin);
  EXPECT_EQ(step.factorizations(), 2);
  EXPECT_EQ(step.background_factorizations(), 1);
  EXPECT_EQ(step.update_rank(), 12) << "tetrahedron 300, cut after the snapshot: an update";
  double rows = 0;
  EXPECT_LE(solve_error(f, step, &rows), 1e-10);
  EXPECT_LE(rows, 1e-10);

  std::vector<int> many;
  for (int t = 100; t < 160; ++t) many.push_back(t);
  step.update(f.remove(many), f.on_skin);  // far past 4 × 18 DOFs at once
  step.finish_background_work(f.on_skin);
  EXPECT_GE(step.factorizations(), 3);
  EXPECT_LE(solve_error(f, step, &rows), 1e-10);
  EXPECT_LE(rows, 1e-10);
}

// Cut after cut while the worker factors, and when its factorization is
// adopted with the cuts made since its snapshot as the update: every solve
// stays exact, whichever update and factor it goes through.
TEST(ImplicitRegionStep, CutsWhileTheWorkerFactorsStayExact) {
  Fixture f;
  auto step = make_step(f, 18);
  for (int t = 150; t < 230; t += 2) {
    step.update(f.remove({t, t + 1}), f.on_skin);
    double rows = 0;
    ASSERT_LE(solve_error(f, step, &rows), 1e-10) << "after tetrahedron " << t;
    ASSERT_LE(rows, 1e-10);
  }
  EXPECT_GE(step.background_factorizations(), 1);
  EXPECT_GE(step.factorizations(), 2);
}

}  // namespace
}  // namespace palpate::tensor_mass_test
