// The tensor-mass region's dynamics (runtime/tensor_mass): damped steps
// settle on the static answer, alone and coupled to the condensed rest of a
// cube; the stable time step is tight; nothing allocates per step or cut.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "runtime/tensor_mass_meshes.hpp"
#include "support/allocation_counter.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace tensor_mass_test;

// 4. From rest under a constant load, damped, the region settles where
// K_ff u = f says.
TEST(TensorMass, DampedDynamicsReachStaticAnswer) {
  const TetMesh mesh = cube(false);
  const auto fixed = face_x0(0);
  Region r(mesh, mesh.tetrahedra, fixed);
  const auto free = moving_vertices(r.model);
  const MatrixXd k_ff = full_stiffness(mesh, mesh.tetrahedra)(dofs_of(free), dofs_of(free));
  VectorXd load = VectorXd::Zero(3 * mesh.vertices.rows());
  load.segment<3>(3 * vertex(kCells, 2, kCells)) = Vector3d(0.02, 0.01, -0.1);  // N
  const VectorXd expected = k_ff.llt().solve(load(dofs_of(free)));
  const auto [omega_min, omega_max] = omega_range(r.model, k_ff);
  r.model = TensorMassModel(mesh.vertices, mesh.tetrahedra, r.ke, {1060, 2 * omega_min}, fixed);
  settle(r.model, load, omega_min);
  const VectorXd u = r.model.displacement_m()(dofs_of(free));
  EXPECT_LE((u - expected).norm(), 1e-6 * expected.norm());
  std::printf("static answer: relative error %.3g (ω %.4g..%.4g rad/s)\n",
              (u - expected).norm() / expected.norm(), omega_min, omega_max);
  for (int v : fixed) EXPECT_EQ(r.model.displacement_m().segment<3>(3 * v), Vector3d::Zero());
}

/// The cube cut at x = x0 into a region (centroid x > x0) and the outside,
/// held on x = 0; the outside condensed on the interface Γ (x = x0).
struct Split {
  TetMesh mesh = cube(false);
  std::vector<int> region_tets, outside_tets, interface, outside_rest;
  MatrixXd schur, g;  // S = K_ΓΓ − K_ΓI K_II⁻¹ K_IΓ; G = K_out⁻¹ ([Γ, I] order)
  Split() {
    for (int t = 0; t < mesh.tetrahedra.rows(); ++t) {
      double x = 0;
      for (int q = 0; q < 4; ++q) x += mesh.vertices(mesh.tetrahedra(t, q), 0) / 4;
      (x > kSide_m / 2 ? region_tets : outside_tets).push_back(t);
    }
    interface = face_x0(kCells / 2);
    for (int i = 1; i < kCells / 2; ++i)
      for (int v : face_x0(i)) outside_rest.push_back(v);
    const MatrixXd k_out = full_stiffness(mesh, rows(mesh.tetrahedra, outside_tets));
    const auto gam = dofs_of(interface), rest = dofs_of(outside_rest);
    const MatrixXd k_ii = k_out(rest, rest), k_ig = k_out(rest, gam);
    schur = k_out(gam, gam) - k_ig.transpose() * k_ii.llt().solve(k_ig);
    std::vector<int> all = gam;
    all.insert(all.end(), rest.begin(), rest.end());
    g = k_out(all, all).inverse();
  }
  Region region() const { return Region(mesh, rows(mesh.tetrahedra, region_tets), {}); }
  /// K + S of a region on its moving DOFs.
  MatrixXd coupled_stiffness(const Region& r) const {
    MatrixXd a = full_stiffness(r.mesh, r.tets);
    const auto gam = dofs_of(interface);
    a(gam, gam) += schur;
    const auto dofs = dofs_of(moving_vertices(r.model));
    return a(dofs, dofs);
  }
  /// The whole cube's static answer at the region's vertices.
  VectorXd whole(const VectorXd& load_n, const std::vector<int>& region_vertices) const {
    // Every vertex but the x = 0 face's moves.
    const auto dofs = dofs_of(moving_vertices(Region(mesh, mesh.tetrahedra, face_x0(0)).model));
    const VectorXd u = full_stiffness(mesh, mesh.tetrahedra)(dofs, dofs).llt().solve(load_n(dofs));
    VectorXd full = VectorXd::Zero(load_n.size());
    for (std::size_t q = 0; q < dofs.size(); ++q) full[dofs[q]] = u[q];
    const auto wanted = dofs_of(region_vertices);
    return full(wanted);
  }
};

// 5. The region coupled to the condensed outside settles on the whole cube's
// static answer, loaded on its own surface or on the outside's.
TEST(TensorMass, CoupledRegionReachesWholeOrganAnswer) {
  const Split split;
  // S is also the inverse of the interface block of the outside's compliance.
  const int ng = static_cast<int>(split.schur.rows());
  const MatrixXd s_from_g = split.g.topLeftCorner(ng, ng).inverse();
  EXPECT_LE((s_from_g - split.schur).norm(), 1e-9 * split.schur.norm());

  Region r = split.region();
  r.model.set_interface_coupling(split.interface, split.schur);
  const auto moving = moving_vertices(r.model);
  const double omega_min = omega_range(r.model, split.coupled_stiffness(r))[0];
  const TensorMassMaterial damped{1060, 2 * omega_min};

  // Loaded on the region's surface (the top edge at x = side).
  VectorXd load = VectorXd::Zero(3 * r.mesh.vertices.rows());
  load.segment<3>(3 * vertex(kCells, 1, kCells)) = Vector3d(0.01, 0.02, -0.1);
  Region on_region(r.mesh, r.tets, {}, damped);
  on_region.model.set_interface_coupling(split.interface, split.schur);
  settle(on_region.model, load, omega_min);
  const VectorXd expected = split.whole(load, moving);
  const VectorXd u = on_region.model.displacement_m()(dofs_of(moving));
  EXPECT_LE((u - expected).norm(), 1e-6 * expected.norm());
  std::printf("coupled, load on the region: relative error %.3g\n",
              (u - expected).norm() / expected.norm());

  // Loaded on the outside's surface: it enters as u_Γ⁰ = G_ΓS f_S.
  const int s = vertex(1, 2, kCells);
  const auto it = std::find(split.outside_rest.begin(), split.outside_rest.end(), s);
  const int column = ng + 3 * static_cast<int>(it - split.outside_rest.begin());
  const Vector3d f_s(-0.02, 0.01, -0.1);
  const VectorXd offset = split.g.block(0, column, ng, 3) * f_s;
  Region on_outside(r.mesh, r.tets, {}, damped);
  on_outside.model.set_interface_coupling(split.interface, split.schur);
  on_outside.model.set_interface_offset(offset);
  settle(on_outside.model, VectorXd::Zero(load.size()), omega_min);
  VectorXd outside_load = VectorXd::Zero(load.size());
  outside_load.segment<3>(3 * s) = f_s;
  const VectorXd expected_s = split.whole(outside_load, moving);
  const VectorXd u_s = on_outside.model.displacement_m()(dofs_of(moving));
  EXPECT_LE((u_s - expected_s).norm(), 1e-6 * expected_s.norm());
  std::printf("coupled, load on the outside: relative error %.3g\n",
              (u_s - expected_s).norm() / expected_s.norm());
}

// 6. Δt_crit = 2/ω_max with S included: below it the undamped step keeps its
// energy, above it the top mode grows.
TEST(TensorMass, StableStepIsTight) {
  const Split split;
  Region r = split.region();
  r.model.set_interface_coupling(split.interface, split.schur);
  const auto moving = moving_vertices(r.model);
  const auto dofs = dofs_of(moving);
  const MatrixXd a = split.coupled_stiffness(r);
  const StableTimeStep bound = r.model.stable_time_step(1e-8);
  ASSERT_TRUE(bound.converged);
  const double omega_max = omega_range(r.model, a)[1];
  // A Rayleigh quotient with residual ε has error ~ε², far below 1e-8.
  EXPECT_NEAR(bound.omega_max_rad_s, omega_max, 1e-8 * omega_max);
  EXPECT_GE(bound.gershgorin_omega_rad_s, omega_max * (1 - 1e-12));
  EXPECT_GE(bound.element_omega_rad_s, omega_max * (1 - 1e-12));
  std::printf("ω_max %.6g rad/s (%d iterations), Gershgorin %.6g, elements %.6g: Δt_crit %.4g s\n",
              bound.omega_max_rad_s, bound.iterations, bound.gershgorin_omega_rad_s,
              bound.element_omega_rad_s, bound.critical_time_step_s);

  VectorXd mass(dofs.size());
  for (std::size_t q = 0; q < dofs.size(); ++q) mass[q] = r.model.mass_kg(dofs[q] / 3);
  // H = ½ vᵀ M v + ½ u⁺ᵀ A u, v = (u⁺ − u)/Δt: what centred differences
  // conserve exactly without damping; a mode of Ω = ωΔt < 2 has potential
  // energy at most H / (1 − Ω²/4), 10.3 H at Ω = 1.9.
  const auto shadow = [&](const VectorXd& u1, const VectorXd& u0, double dt) {
    const VectorXd v = (u1 - u0) / dt;
    return 0.5 * v.dot(mass.cwiseProduct(v)) + 0.5 * u1.dot(a * u0);
  };
  const VectorXd zero = VectorXd::Zero(3 * r.model.vertex_count());
  for (const double factor : {0.95, 1.05}) {
    const double dt = factor * bound.critical_time_step_s;
    VectorXd u0 = zero;
    std::mt19937 rng(6);
    std::uniform_real_distribution<double> d(-1e-4, 1e-4);
    for (int q : dofs) u0[q] = d(rng);
    r.model.set_state(u0, u0);
    r.model.step(dt, zero);
    const double h0 = shadow(r.model.displacement_m()(dofs), u0(dofs), dt);
    ASSERT_GT(h0, 0);
    double largest_potential = 0, h_drift = 0;
    const int steps = factor < 1 ? 2000 : 300;
    for (int n = 0; n < steps; ++n) {
      const VectorXd before = r.model.displacement_m()(dofs);
      r.model.step(dt, zero);
      const VectorXd after = r.model.displacement_m()(dofs);
      largest_potential = std::max(largest_potential, 0.5 * after.dot(a * after));
      h_drift = std::max(h_drift, std::abs(shadow(after, before, dt) - h0));
    }
    std::printf("%.2f Δt_crit, %d steps: largest potential energy %.3g H0, |H − H0| ≤ %.3g H0\n",
                factor, steps, largest_potential / h0, h_drift / h0);
    if (factor < 1) {
      EXPECT_LE(largest_potential, 11 * h0);
      EXPECT_LE(h_drift, 1e-9 * h0);  // round-off over 2000 steps
    } else {
      EXPECT_GE(largest_potential, 1e12 * h0);  // the top mode grows ~1.9× a step
    }
  }
}

// After cuts (one of them detaching a corner) the power iteration still
// finds ω_max of what remains, on the moving vertices only, and Gershgorin
// still bounds it.
TEST(TensorMass, StableStepAfterCuts) {
  const TetMesh mesh = cube(false);
  Region r(mesh, mesh.tetrahedra, face_x0(0));
  const StableTimeStep before = r.model.stable_time_step(1e-8);
  const int corner = vertex(kCells, kCells, kCells);
  std::vector<int> keep;
  for (int t = 0; t < mesh.tetrahedra.rows(); ++t) {
    if ((mesh.tetrahedra.row(t).array() == corner).any() || t % 7 == 3)
      r.model.remove_tetrahedron(t);
    else
      keep.push_back(t);
  }
  ASSERT_TRUE(r.model.is_detached(corner));
  const auto dofs = dofs_of(moving_vertices(r.model));
  const MatrixXd k = full_stiffness(mesh, rows(mesh.tetrahedra, keep))(dofs, dofs);
  const double omega_max = omega_range(r.model, k)[1];
  const StableTimeStep bound = r.model.stable_time_step(1e-8);
  ASSERT_TRUE(bound.converged);
  EXPECT_NEAR(bound.omega_max_rad_s, omega_max, 1e-8 * omega_max);
  EXPECT_GE(bound.gershgorin_omega_rad_s, omega_max * (1 - 1e-12));
  // The element bound, computed before the cuts, still holds after them.
  EXPECT_EQ(bound.element_omega_rad_s, before.element_omega_rad_s);
  EXPECT_GE(before.element_omega_rad_s, omega_max * (1 - 1e-12));
  EXPECT_GE(before.element_omega_rad_s, before.omega_max_rad_s * (1 - 1e-12));
  std::printf("ω_max %.6g rad/s, after %zu cuts %.6g (%d iterations); element bound %.6g\n",
              before.omega_max_rad_s, mesh.tetrahedra.rows() - keep.size(), bound.omega_max_rad_s,
              bound.iterations, bound.element_omega_rad_s);
}

// No allocation in what runs every step, nor in a cut.
TEST(TensorMass, StepAndCutAllocateNothing) {
  const Split split;
  Region r = split.region();
  r.model.set_interface_coupling(split.interface, split.schur);
  const VectorXd load = VectorXd::Constant(3 * r.model.vertex_count(), 1e-3);
  const VectorXd offset = VectorXd::Constant(split.schur.rows(), 1e-5);
  VectorXd f(load.size());
  const double dt = 0.9 * r.model.stable_time_step().critical_time_step_s;
  const auto before = testing::allocations_here();
  for (int n = 0; n < 10; ++n) {
    r.model.set_interface_offset(offset);
    r.model.step(dt, load);
  }
  r.model.internal_force(r.model.displacement_m(), f);
  r.model.apply_stiffness(r.model.displacement_m(), f);
  r.model.add_coupling_force(r.model.displacement_m(), f);
  r.model.remove_tetrahedron(5);
  r.model.step(dt, load);
  EXPECT_EQ(testing::allocations_here() - before, 0u);
}

}  // namespace
}  // namespace palpate
