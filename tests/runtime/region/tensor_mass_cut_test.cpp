// Cutting the tensor-mass region (runtime/tensor_mass): a sweep across the
// region leaving two parts that exchange no force, cutting through
// entirely, and 10,000 random cuts between explicit steps that keep the
// region finite, uninverted and within the energy the load put in
// (docs/model/tensor-mass.md, "The tensor-mass model: a cuttable region"). The queries
// a cut uses: tensor_mass_query_test.cpp.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "runtime/tensor_mass_meshes.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"
#include "support/time_scale.hpp"

namespace palpate {
namespace {

using namespace tensor_mass_test;

/// The part label of every remaining tetrahedron, with the side of x0 its
/// vertices are on (−1 below, +1 above, 0 straddling).
int side_of(const TensorMassModel& m, int t, double x0) {
  bool below = true, above = true;
  for (int k = 0; k < 4; ++k) {
    const double x = m.rest_positions_m()(m.tetrahedra()(t, k), 0);
    below = below && x < x0;
    above = above && x > x0;
  }
  return below ? -1 : above ? 1 : 0;
}

// 4. A blade swept over the whole cross-section x = 2.5 cm of the 4 cm cube
// held on x = 0 leaves two parts, one on each side; no force crosses the
// cut, and under a weight the free part falls as a rigid body while the
// held part stays within twice its static displacement.
TEST(TensorMassCut, SweepAcrossSeparatesTwoParts) {
  const TetMesh mesh = cube(false);
  constexpr double kX0 = 0.025, kG = 9.81;  // m, m/s²
  Region r(mesh, mesh.tetrahedra, face_x0(0), {1060, 20});
  EXPECT_EQ(r.model.connected_parts(), 1);
  // The blade spans z from −5 to 45 mm and moves in y from −5 to 45 mm in
  // ten ticks: the quadrilaterals tile the plane x = x0 over the section.
  std::vector<int> removed;
  removed.reserve(static_cast<std::size_t>(r.model.tetrahedron_count()));
  int total = 0;
  for (int tick = 0; tick < 10; ++tick) {
    const double y0 = -0.005 + 0.005 * tick, y1 = y0 + 0.005;
    total += r.model.cut_swept_blade({{kX0, y0, -0.005}, {kX0, y0, 0.045}},
                                     {{kX0, y1, -0.005}, {kX0, y1, 0.045}}, removed);
  }
  // The plane meets exactly the 16 cubes of the layer 2 cm ≤ x ≤ 3 cm.
  EXPECT_EQ(total, 16 * 6);
  ASSERT_EQ(r.model.connected_parts(), 2);
  const std::vector<int> label = r.model.part_labels();
  std::set<int> labels_below, labels_above;
  std::vector<int> part_of_vertex(r.model.vertex_count(), -1);
  for (int t = 0; t < r.model.tetrahedron_count(); ++t) {
    if (r.model.is_removed(t)) {
      EXPECT_EQ(label[t], -1);
      continue;
    }
    const int side = side_of(r.model, t, kX0);
    ASSERT_NE(side, 0) << "tetrahedron " << t << " straddles the cut";
    (side < 0 ? labels_below : labels_above).insert(label[t]);
    for (int k = 0; k < 4; ++k) {
      int& p = part_of_vertex[r.model.tetrahedra()(t, k)];
      EXPECT_TRUE(p < 0 || p == label[t]) << "a vertex in both parts";
      p = label[t];
    }
  }
  EXPECT_EQ(labels_below, std::set<int>{0});  // the held part has tetrahedron 0
  EXPECT_EQ(labels_above, std::set<int>{1});
  // No edge crosses the cut.
  for (const auto& [i, j] : r.model.edges())
    EXPECT_EQ(r.model.rest_positions_m()(i, 0) < kX0, r.model.rest_positions_m()(j, 0) < kX0);

  const double dt = 0.9 * r.model.stable_time_step().element_time_step_s;
  const int nv = r.model.vertex_count();
  const auto below = [&](int v) { return r.model.rest_positions_m()(v, 0) < kX0; };

  // A load on the free side only: the held side does not move at all.
  VectorXd load = VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v)
    if (!below(v)) load.segment<3>(3 * v) = Vector3d(0.001, 0.002, -0.005);  // N
  for (int n = 0; n < 500; ++n) r.model.step(dt, load);
  double free_moved = 0;
  for (int v = 0; v < nv; ++v) {
    const Vector3d u = r.model.displacement_m().segment<3>(3 * v);
    if (below(v))
      EXPECT_EQ(u, Vector3d::Zero()) << "vertex " << v;  // exactly: no term reaches it
    else
      free_moved = std::max(free_moved, u.norm());
  }
  EXPECT_GT(free_moved, 1e-3);  // 0.25 N on 17 g for 0.1 s: centimetres

  // A weight m_v g on every vertex, from rest.
  const VectorXd zero = VectorXd::Zero(3 * nv);
  r.model.set_state(zero, zero);
  VectorXd weight = VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v) weight[3 * v + 2] = -r.model.mass_kg(v) * kG;
  // The held part's static answer u_s = K_A⁻¹ f on its moving DOFs.
  std::vector<int> held_tets, held_moving;
  for (int t = 0; t < r.model.tetrahedron_count(); ++t)
    if (!r.model.is_removed(t) && side_of(r.model, t, kX0) < 0) held_tets.push_back(t);
  for (int v : moving_vertices(r.model))
    if (below(v)) held_moving.push_back(v);
  const auto dofs = dofs_of(held_moving);
  const MatrixXd k_a = full_stiffness(mesh, rows(mesh.tetrahedra, held_tets))(dofs, dofs);
  const VectorXd u_s = k_a.llt().solve(weight(dofs));
  const double static_norm = std::sqrt(u_s.dot(k_a * u_s));
  // The free part translates: every vertex follows the scalar recurrence of
  // the step for a = −g (the elastic force of a translation is round-off).
  const double c0 = 1 / (dt * dt), c1 = 20 / (2 * dt);
  double q = 0, q_prev = 0, largest_held = 0, worst_rigid = 0;
  const int steps = 2000;
  for (int n = 0; n < steps; ++n) {
    const VectorXd u_before = r.model.displacement_m()(dofs);
    r.model.step(dt, weight);
    const double next = (-kG + 2 * c0 * q - (c0 - c1) * q_prev) / (c0 + c1);
    q_prev = q;
    q = next;
    // The held part from rest under a constant load: the discrete energy
    // identity gives |ū|_K ≤ 2 |u_s|_K at the half steps (docs/model/tensor-mass.md).
    const VectorXd mid = 0.5 * (u_before + r.model.displacement_m()(dofs));
    largest_held = std::max(largest_held, std::sqrt(mid.dot(k_a * mid)));
    for (int v = 0; v < nv; ++v)
      if (!below(v))
        worst_rigid = std::max(
            worst_rigid, (r.model.displacement_m().segment<3>(3 * v) - Vector3d(0, 0, q)).norm());
  }
  std::printf(
      "cut in two: the free part fell %.4g m in %d steps (rigid to %.3g of it); held part "
      "|ū|_K up to %.3f |u_s|_K\n",
      -q, steps, worst_rigid / std::abs(q), largest_held / static_norm);
  EXPECT_LT(q, -1e-3);
  // Translation's elastic force is ~10⁻¹⁶ ‖K‖ |u| per step: 10⁻⁹ relative.
  EXPECT_LE(worst_rigid, 1e-9 * std::abs(q));
  EXPECT_LE(largest_held, 2 * static_norm * (1 + 1e-9));
  EXPECT_GE(largest_held, 0.5 * static_norm);  // it did carry its weight
}

// 5. Cutting through entirely: every tetrahedron removed leaves a defined,
// inert model.
TEST(TensorMassCut, CuttingThroughEntirely) {
  const TetMesh mesh = cube(true);
  Region r(mesh, mesh.tetrahedra, face_x0(0));
  const int nv = r.model.vertex_count(), nt = r.model.tetrahedron_count();
  const double dt = 0.9 * r.model.stable_time_step().element_time_step_s;
  const VectorXd load = VectorXd::Constant(3 * nv, -1e-3);
  for (int n = 0; n < 50; ++n) r.model.step(dt, load);
  const std::uint64_t version = r.model.boundary_version();
  // Half by a blade sweeping through the middle, the rest one by one.
  std::vector<int> removed;
  const int swept = r.model.cut_swept_blade({{-0.01, -0.01, 0.02}, {-0.01, 0.05, 0.02}},
                                            {{0.05, -0.01, 0.02}, {0.05, 0.05, 0.02}}, removed);
  EXPECT_GT(swept, 0);
  std::vector<int> order(nt);
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), std::mt19937(5));
  for (int t : order)
    if (!r.model.is_removed(t)) r.model.remove_tetrahedron(t);

  const TensorMassModel& m = r.model;
  EXPECT_EQ(m.remaining_tetrahedra(), 0);
  EXPECT_EQ(m.boundary_version(), version + static_cast<std::uint64_t>(nt));
  EXPECT_TRUE(m.boundary_triangles().empty());
  EXPECT_EQ(m.edge_count(), 0);
  EXPECT_EQ(m.connected_parts(), 0);
  EXPECT_EQ(m.part_labels(), std::vector<int>(nt, -1));
  for (int v = 0; v < nv; ++v) {
    EXPECT_TRUE(m.is_detached(v)) << "vertex " << v;
    EXPECT_EQ(m.mass_kg(v), 0.0);
    EXPECT_EQ(m.vertex_tensor(v), Eigen::Matrix3d::Zero());
  }
  // Nothing left to meet, nothing to cut.
  EXPECT_TRUE(m.tetrahedra_crossed_by_segment({0, 0, 0}, {0.04, 0.04, 0.04}).empty());
  EXPECT_EQ(r.model.cut_swept_blade({{0, 0, 0}, {0, 0.04, 0.04}},
                                    {{0.04, 0, 0}, {0.04, 0.04, 0.04}}, removed),
            0);
  // Nothing moves: ω_max 0 and any step stable.
  const StableTimeStep bound = m.stable_time_step();
  EXPECT_EQ(bound.omega_max_rad_s, 0.0);
  EXPECT_TRUE(std::isinf(bound.critical_time_step_s) && std::isinf(bound.element_time_step_s));
  // The step leaves every displacement where the cuts left it.
  const VectorXd u = m.displacement_m();
  EXPECT_GT(u.norm(), 0);
  r.model.step(dt, load);
  r.model.step(dt, -load);
  EXPECT_EQ(m.displacement_m(), u);
  EXPECT_EQ(m.previous_displacement_m(), u);
  VectorXd f(3 * nv);
  m.internal_force(u, f);
  EXPECT_EQ(f, VectorXd::Zero(3 * nv));
  // Removing again is refused, naming the tetrahedron.
  testing::expect_error<InputError>([&] { r.model.remove_tetrahedron(17); },
                                    {"tetrahedron 17", "already removed"});
  EXPECT_EQ(m.boundary_version(), version + static_cast<std::uint64_t>(nt));
}

/// Deformed signed volume over rest volume of tetrahedron t.
double volume_ratio(const TensorMassModel& m, const VectorXd& u, int t) {
  Vector3d x[4];
  for (int k = 0; k < 4; ++k) {
    const int v = m.tetrahedra()(t, k);
    x[k] = m.rest_positions_m().row(v).transpose() + u.segment<3>(3 * v);
  }
  const Matrix43d rest = corners(m, t);
  const Vector3d r0 = rest.row(0).transpose();
  const double rest_volume =
      (rest.row(1).transpose() - r0)
          .dot((rest.row(2).transpose() - r0).cross(rest.row(3).transpose() - r0));
  return (x[1] - x[0]).dot((x[2] - x[0]).cross(x[3] - x[0])) / rest_volume;
}

// 6. 10,000 random cuts (strokes of a blade of 2–10 mm moving 0.2–1.5 mm a
// tick, turning a little) on the 2,058-tetrahedron box held on x = 0,
// interleaved with explicit steps at 0.9 of the element step under a body
// load of 1 m/s² (a tenth of gravity: the heaviest part hanging on one
// tetrahedron strains it about 2 %, so no element inverts for physical
// reasons) and damping γ = 20/s; every seventh cut also removes a random
// tetrahedron by index, refused when already removed. The region is built
// again when a quarter of it remains. Checked after every cut and step:
//  - no exception but that refusal; u finite; every remaining tetrahedron's
//    deformed signed volume > 0;
//  - energy: with v = (u⁺ − u)/Δt and H = ½ vᵀ M v + ½ u⁺ᵀ K u, centred
//    differences give H⁺ − H = f·(u⁺ − u⁻)/2 − (γ/4Δt)|u⁺ − u⁻|²_M, so
//    H ≤ W, the work of the load so far; a cut lowers H (it removes
//    ½ v_tᵀ(M_t − Δt²K^t/4)v_t + ½ ū_tᵀK^tū_t ≥ 0 when Δt is below the
//    element step). And H = ½ vᵀ(M − Δt²K/4)v + ½ ūᵀKū (ū = (u⁺ + u)/2)
//    ≥ (1 − Ω²/4) E, E = ½ vᵀMv + ½ ūᵀKū the energy at the half step,
//    Ω = Δt ω_element ≤ 1.8: E ≤ W / (1 − 0.81).
TEST(TensorMassCut, RandomCutsStayPhysical) {
  const TetMesh mesh = big_box(false);
  const auto fixed = big_box_face_x0();
  const auto ke =
      element_stiffnesses(mesh, mesh.tetrahedra, std::vector<Lame>(mesh.tetrahedra.rows(), kLiver));
  const TensorMassMaterial material{1060, 20};
  constexpr int kCuts = 10000;
  constexpr double kAccel = 1.0;  // m/s², along −z
  // Under the sanitizers (PALPATE_TEST_TIME_SCALE > 1: Eigen checked and
  // instrumented, some 50 times slower) one step between cuts and the
  // energies and volumes checked at every 20th cut; the cuts stay 10,000,
  // the work W is summed at every step.
  const bool slow = testing::time_scale() > 1;
  const int steps_per_cut = slow ? 1 : 4, check_every = slow ? 20 : 1;
  const double side = kBoxCells * kBoxCell_m;

  std::mt19937 rng(2026);
  std::uniform_real_distribution<double> unit(0, 1);
  std::unique_ptr<TensorMassModel> model;
  double dt = 0, energy_factor = 0, work = 0;
  const int nv = static_cast<int>(mesh.vertices.rows()),
            nt = static_cast<int>(mesh.tetrahedra.rows());
  VectorXd force(3 * nv), ku(3 * nv), mid(3 * nv), velocity(3 * nv);
  std::vector<int> removed;
  removed.reserve(static_cast<std::size_t>(nt));
  // Counts.
  int episodes = 0, refused = 0, direct = 0, stroke_ticks = 0, checks = 0;
  long swept_away = 0, steps = 0;
  double worst_h_over_w = 0, worst_e_over_w = 0, least_volume = 1, largest_u = 0;
  Blade blade;
  Vector3d move = Vector3d::Zero(), turn_axis = Vector3d::UnitX();
  double turn = 0;

  // H = ½ vᵀMv + ½ u⁺ᵀKu and E = ½ vᵀMv + ½ ūᵀKū of the model's state.
  const auto energies = [&](const TensorMassModel& m) {
    const VectorXd& u1 = m.displacement_m();
    const VectorXd& u0 = m.previous_displacement_m();
    velocity = (u1 - u0) / dt;
    double kinetic = 0;
    for (int v = 0; v < nv; ++v)
      kinetic += 0.5 * m.mass_kg(v) * velocity.segment<3>(3 * v).squaredNorm();
    m.apply_stiffness(u0, ku);
    const double shadow = kinetic + 0.5 * u1.dot(ku);
    mid = 0.5 * (u1 + u0);
    m.apply_stiffness(mid, ku);
    return std::array<double, 2>{shadow, kinetic + 0.5 * mid.dot(ku)};
  };
  // What is wrong with the state, or nothing.
  const auto check_state = [&](const TensorMassModel& m) -> std::string {
    const VectorXd& u = m.displacement_m();
    if (!u.allFinite()) return "a non-finite displacement";
    largest_u = std::max(largest_u, u.cwiseAbs().maxCoeff());
    for (int t = 0; t < nt; ++t) {
      if (m.is_removed(t)) continue;
      const double ratio = volume_ratio(m, u, t);
      least_volume = std::min(least_volume, ratio);
      if (!(ratio > 0)) return "tetrahedron " + std::to_string(t) + " inverted";
    }
    return "";
  };

  for (int cut = 0; cut < kCuts; ++cut) {
    if (!model || model->remaining_tetrahedra() < nt / 4) {
      model =
          std::make_unique<TensorMassModel>(mesh.vertices, mesh.tetrahedra, ke, material, fixed);
      // The element bound only: one power iteration is enough.
      const StableTimeStep bound = model->stable_time_step(1e-6, 1);
      dt = 0.9 * bound.element_time_step_s;
      const double omega_dt = dt * bound.element_omega_rad_s;  // 1.8
      energy_factor = 1 / (1 - omega_dt * omega_dt / 4);
      work = 0;
      ++episodes;
    }
    TensorMassModel& m = *model;
    if (stroke_ticks == 0) {  // a new stroke
      const Vector3d centre =
          Vector3d(unit(rng), unit(rng), unit(rng)) * 1.1 * side - Vector3d::Constant(0.05 * side);
      const double length = 0.002 + 0.008 * unit(rng), speed = 0.0002 + 0.0013 * unit(rng);
      const Vector3d along = random_unit(rng);
      blade = {centre - 0.5 * length * along, centre + 0.5 * length * along};
      move = speed * random_unit(rng);
      turn_axis = random_unit(rng);
      turn = 0.1 * (unit(rng) - 0.5);  // rad a tick
      stroke_ticks = 3 + static_cast<int>(13 * unit(rng));
    }
    const Vector3d centre = 0.5 * (blade.a_m + blade.b_m) + move;
    const Eigen::AngleAxisd rotation(turn, turn_axis);
    const Vector3d half = rotation * (0.5 * (blade.b_m - blade.a_m));
    const Blade next{centre - half, centre + half};
    --stroke_ticks;

    const bool checked = cut % check_every == 0;
    const double h_before = checked ? energies(m)[0] : 0.0;
    try {
      swept_away += m.cut_swept_blade(blade, next, removed);
      if (cut % 7 == 0) {
        const int t = static_cast<int>(unit(rng) * nt);
        const bool was_removed = m.is_removed(t);
        ++direct;
        try {
          m.remove_tetrahedron(t);
          EXPECT_FALSE(was_removed) << "tetrahedron " << t << " removed twice";
        } catch (const InputError& e) {
          ++refused;
          EXPECT_TRUE(was_removed) << e.what();
          EXPECT_NE(std::string(e.what()).find("tetrahedron " + std::to_string(t) +
                                               " is already removed"),
                    std::string::npos)
              << e.what();
        }
      }
    } catch (const std::exception& e) {
      FAIL() << "cut " << cut << ": " << e.what();
    }
    blade = next;
    if (checked) {
      ++checks;
      // A cut takes energy away, never adds it (round-off: 10⁻⁹ of W).
      const double h_after = energies(m)[0];
      ASSERT_LE(h_after, h_before + 1e-9 * work) << "cut " << cut;
      const std::string after_cut = check_state(m);
      ASSERT_EQ(after_cut, "") << "after cut " << cut;
    }

    for (int s = 0; s < steps_per_cut; ++s) {
      force.setZero();
      for (int v = 0; v < nv; ++v)
        if (!m.is_fixed(v)) force[3 * v + 2] = -m.mass_kg(v) * kAccel;
      const VectorXd& u_minus = m.previous_displacement_m();
      // W += f·(u⁺ − u⁻)/2: u⁻ read before the step overwrites it.
      const double before_dot = force.dot(u_minus);
      m.step(dt, force);
      ++steps;
      work += 0.5 * (force.dot(m.displacement_m()) - before_dot);
      if (!checked) continue;
      const std::string after_step = check_state(m);
      ASSERT_EQ(after_step, "") << "after step " << steps << ", cut " << cut;
      const auto [shadow, energy] = energies(m);
      ASSERT_LE(shadow, work * (1 + 1e-9) + 1e-30) << "cut " << cut << ", step " << steps;
      ASSERT_LE(energy, energy_factor * work * (1 + 1e-9) + 1e-30) << "cut " << cut;
      if (work > 0) {
        worst_h_over_w = std::max(worst_h_over_w, shadow / work);
        worst_e_over_w = std::max(worst_e_over_w, energy / work);
      }
    }
  }
  std::printf(
      "%d cuts (%d steps each, Δt %.3g µs, %d checked): %ld tetrahedra swept away, %d removals "
      "by index (%d refused: already removed), %d regions, %ld steps; H/W up to %.4f, E/W up "
      "to %.4f (bound %.3f); least volume ratio %.4f; largest |u| %.3g mm\n",
      kCuts, steps_per_cut, dt * 1e6, checks, swept_away, direct, refused, episodes, steps,
      worst_h_over_w, worst_e_over_w, energy_factor, least_volume, largest_u * 1e3);
  EXPECT_GT(swept_away, 5000);  // the cuts did cut
  EXPECT_GT(refused, 0);
  EXPECT_GT(episodes, 2);
}

}  // namespace
}  // namespace palpate
