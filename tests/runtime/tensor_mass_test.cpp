// The tensor-mass model of a cuttable region (runtime/tensor_mass): its
// tensors against the assembled K of the offline layer, rigid motions, cuts
// against a model built from the remaining tetrahedra, damped dynamics
// against the static answer (alone and coupled to the condensed rest of a
// cube), the stable time step, the segment query, bad input.

#include "palpate/runtime/tensor_mass.hpp"

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
#include "support/allocation_counter.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;
using Triangle = std::array<int, 3>;

constexpr int kCells = 4;                         // 4 × 4 × 4 cells, 384 tetrahedra, 125 vertices
constexpr double kSide_m = 0.04;                  // a 4 cm cube: 1 cm cells
const Lame kLiver = lame_parameters(85e3, 0.45);  // docs/configuration.md's organ
const TensorMassMaterial kTissue{1060, 0};

int vertex(int i, int j, int k) { return testing::box_vertex(i, j, k, kCells, kCells); }

/// The cube, interior vertices moved by up to 0.1 cell (a generic mesh)
/// when @p jitter; the tetrahedra stay positive.
TetMesh cube(bool jitter) {
  TetMesh mesh = testing::box_mesh(kSide_m, kSide_m, kSide_m, kCells, kCells, kCells);
  if (jitter) {
    std::mt19937 rng(20);
    std::uniform_real_distribution<double> d(-0.1 * kSide_m / kCells, 0.1 * kSide_m / kCells);
    for (int i = 1; i < kCells; ++i)
      for (int j = 1; j < kCells; ++j)
        for (int k = 1; k < kCells; ++k)
          mesh.vertices.row(vertex(i, j, k)) += Eigen::RowVector3d(d(rng), d(rng), d(rng));
  }
  return mesh;
}

std::vector<Matrix12d> element_stiffnesses(const TetMesh& mesh, const Eigen::MatrixX4i& tets,
                                           const std::vector<Lame>& lame_of_tet) {
  std::vector<Matrix12d> out;
  for (Eigen::Index t = 0; t < tets.rows(); ++t) {
    Matrix43d p;
    for (int q = 0; q < 4; ++q) p.row(q) = mesh.vertices.row(tets(t, q));
    out.push_back(element_stiffness(p, lame_of_tet[t]));
  }
  return out;
}

MatrixXd full_stiffness(const TetMesh& mesh, const Eigen::MatrixX4i& tets) {
  return MatrixXd(
      assemble_full_stiffness(mesh.vertices, tets, Eigen::VectorXi::Zero(tets.rows()), {kLiver}));
}

Eigen::MatrixX4i rows(const Eigen::MatrixX4i& tets, const std::vector<int>& keep) {
  Eigen::MatrixX4i out(keep.size(), 4);
  for (std::size_t r = 0; r < keep.size(); ++r) out.row(r) = tets.row(keep[r]);
  return out;
}

std::vector<int> face_x0(int i) {
  std::vector<int> out;
  for (int j = 0; j <= kCells; ++j)
    for (int k = 0; k <= kCells; ++k) out.push_back(vertex(i, j, k));
  return out;
}

/// The triangle turned so that its least index comes first (orientation kept).
Triangle canonical(Triangle t) {
  std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
  return t;
}

std::set<Triangle> canonical_set(const std::vector<Triangle>& tris) {
  std::set<Triangle> out;
  for (const auto& t : tris) out.insert(canonical(t));
  return out;
}

/// A tensor-mass model with its own copy of the mesh and element blocks.
struct Region {
  TetMesh mesh;
  Eigen::MatrixX4i tets;
  std::vector<Matrix12d> ke;
  TensorMassModel model;
  Region(TetMesh m, Eigen::MatrixX4i t, const std::vector<int>& fixed,
         TensorMassMaterial material = kTissue)
      : mesh(std::move(m)),
        tets(std::move(t)),
        ke(element_stiffnesses(mesh, tets, std::vector<Lame>(tets.rows(), kLiver))),
        model(mesh.vertices, tets, ke, material, fixed) {}
};

/// The DOFs of a list of vertices, in its order.
std::vector<int> dofs_of(const std::vector<int>& vertices) {
  std::vector<int> out;
  for (int v : vertices)
    for (int a = 0; a < 3; ++a) out.push_back(3 * v + a);
  return out;
}

/// The vertices that move in the model (neither fixed nor detached).
std::vector<int> moving_vertices(const TensorMassModel& m) {
  std::vector<int> out;
  for (int v = 0; v < m.vertex_count(); ++v)
    if (!m.is_fixed(v) && !m.is_detached(v)) out.push_back(v);
  return out;
}

/// ω_min and ω_max of M⁻¹ A on the moving DOFs, A given on them (dense).
std::array<double, 2> omega_range(const TensorMassModel& m, const MatrixXd& a) {
  const auto moving = moving_vertices(m);
  VectorXd s(3 * moving.size());
  for (std::size_t r = 0; r < moving.size(); ++r)
    s.segment<3>(3 * r).setConstant(1 / std::sqrt(m.mass_kg(moving[r])));
  const VectorXd w2 = Eigen::SelfAdjointEigenSolver<MatrixXd>(s.asDiagonal() * a * s.asDiagonal(),
                                                              Eigen::EigenvaluesOnly)
                          .eigenvalues();
  return {std::sqrt(w2.minCoeff()), std::sqrt(w2.maxCoeff())};
}

/// Steps from rest under a constant load until every mode has decayed by
/// e⁻³⁰: γ = 2 ω_min damps the slowest mode critically and the others at
/// the rate γ/2 = ω_min.
void settle(TensorMassModel& m, const VectorXd& load_n, double omega_min) {
  const double dt = 0.9 * m.stable_time_step().critical_time_step_s;
  const int steps = static_cast<int>(std::ceil(30 / (omega_min * dt)));
  for (int n = 0; n < steps; ++n) m.step(dt, load_n);
}

// 1. The two passes of the lecture give K u, K assembled by the offline layer.
TEST(TensorMass, ForceEqualsAssembledStiffness) {
  const TetMesh mesh = cube(true);
  // Two materials, alternating, so that neighbouring blocks differ.
  const Lame soft = lame_parameters(20e3, 0.3);
  std::vector<Lame> lame_of_tet;
  Eigen::VectorXi material(mesh.tetrahedra.rows());
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    material[t] = static_cast<int>(t % 2);
    lame_of_tet.push_back(t % 2 == 0 ? kLiver : soft);
  }
  const auto ke = element_stiffnesses(mesh, mesh.tetrahedra, lame_of_tet);
  const TensorMassModel model(mesh.vertices, mesh.tetrahedra, ke, kTissue, {});
  const SparseMatrixd k =
      assemble_full_stiffness(mesh.vertices, mesh.tetrahedra, material, {kLiver, soft});
  std::mt19937 rng(1);
  std::normal_distribution<double> d(0, 1e-3);
  VectorXd u(k.cols());
  for (auto& x : u) x = d(rng);
  VectorXd f(u.size()), ku(u.size());
  model.internal_force(u, f);
  model.apply_stiffness(u, ku);
  const VectorXd expected = k * u;
  // Sums of ~20 blocks in another order: ~1e-15 relative.
  EXPECT_LE((f + expected).norm(), 1e-12 * expected.norm());
  EXPECT_LE((ku - expected).norm(), 1e-12 * expected.norm());
  std::printf("K u: relative error %.3g\n", (ku - expected).norm() / expected.norm());
  std::set<std::array<int, 2>> edges;
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
    for (int p = 0; p < 4; ++p)
      for (int q = p + 1; q < 4; ++q)
        edges.insert({std::min(mesh.tetrahedra(t, p), mesh.tetrahedra(t, q)),
                      std::max(mesh.tetrahedra(t, p), mesh.tetrahedra(t, q))});
  EXPECT_EQ(model.edge_count(), std::ssize(edges));
}

// 2. Rigid motions have no strain, hence no force (the patch test's null space).
TEST(TensorMass, RigidMotionsGiveNoForce) {
  const TetMesh mesh = cube(true);
  const Region r(mesh, mesh.tetrahedra, {});
  const double k_norm = full_stiffness(mesh, mesh.tetrahedra).norm();
  const Vector3d translation(1e-3, -2e-3, 0.5e-3), omega(0.01, -0.02, 0.03);  // rad
  VectorXd shift(3 * mesh.vertices.rows()), turn(shift.size()), f(shift.size());
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) {
    shift.segment<3>(3 * v) = translation;
    turn.segment<3>(3 * v) = omega.cross(Vector3d(mesh.vertices.row(v)));
  }
  // Cancellation of terms of size ‖K‖‖u‖ leaves round-off: 1e-13 of it.
  r.model.internal_force(shift, f);
  EXPECT_LE(f.norm(), 1e-13 * k_norm * shift.norm());
  std::printf("translation: ‖f‖ = %.3g ‖K‖‖u‖", f.norm() / (k_norm * shift.norm()));
  r.model.internal_force(turn, f);
  EXPECT_LE(f.norm(), 1e-13 * k_norm * turn.norm());
  std::printf(", rotation: %.3g ‖K‖‖u‖\n", f.norm() / (k_norm * turn.norm()));
}

// The boundary of a set of tetrahedra computed here, independently: faces of
// one tetrahedron, oriented so the normal points away from its centroid.
std::set<Triangle> boundary_of(const TetMesh& mesh, const Eigen::MatrixX4i& tets) {
  std::map<std::array<int, 3>, std::vector<Triangle>> faces;
  for (Eigen::Index t = 0; t < tets.rows(); ++t) {
    Vector3d centroid = Vector3d::Zero();
    for (int q = 0; q < 4; ++q) centroid += mesh.vertices.row(tets(t, q)).transpose() / 4;
    for (int skip = 0; skip < 4; ++skip) {
      Triangle tri;
      for (int q = 0, n = 0; q < 4; ++q)
        if (q != skip) tri[n++] = tets(t, q);
      const Vector3d a = mesh.vertices.row(tri[0]), b = mesh.vertices.row(tri[1]),
                     c = mesh.vertices.row(tri[2]);
      if ((b - a).cross(c - a).dot((a + b + c) / 3 - centroid) < 0) std::swap(tri[1], tri[2]);
      std::array<int, 3> key = tri;
      std::sort(key.begin(), key.end());
      faces[key].push_back(tri);
    }
  }
  std::set<Triangle> out;
  for (const auto& [key, list] : faces)
    if (list.size() == 1) out.insert(canonical(list[0]));
  return out;
}

// 3. Cuts: all tetrahedra around an edge, all around a corner vertex (which
// detaches it), a few more; the result is the model of what remains.
TEST(TensorMass, RemovalEqualsRebuiltModel) {
  const TetMesh mesh = cube(true);
  Region cut(mesh, mesh.tetrahedra, face_x0(0));
  const int a = vertex(2, 2, 2), b = vertex(3, 2, 2), corner = vertex(kCells, kCells, kCells);
  ASSERT_GT(cut.model.tetrahedra_at_edge(a, b), 2);
  std::set<int> removed = {7, 100, 101, 250};
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    const auto row = mesh.tetrahedra.row(t);
    const bool has_a = (row.array() == a).any(), has_b = (row.array() == b).any();
    if ((has_a && has_b) || (row.array() == corner).any()) removed.insert(static_cast<int>(t));
  }
  const std::uint64_t version = cut.model.boundary_version();
  for (int t : removed) cut.model.remove_tetrahedron(t);
  EXPECT_EQ(cut.model.boundary_version(), version + removed.size());
  EXPECT_EQ(cut.model.remaining_tetrahedra(), mesh.tetrahedra.rows() - std::ssize(removed));

  std::vector<int> keep;
  for (int t = 0; t < mesh.tetrahedra.rows(); ++t)
    if (!removed.contains(t)) keep.push_back(t);
  const Region rebuilt(mesh, rows(mesh.tetrahedra, keep), face_x0(0));
  const TensorMassModel& m = cut.model;
  const TensorMassModel& ref = rebuilt.model;

  // The same blocks summed over the same tetrahedra: equal to round-off of
  // the largest tensor.
  double scale = 0;
  for (int v = 0; v < m.vertex_count(); ++v) scale = std::max(scale, ref.vertex_tensor(v).norm());
  const double tol = 1e-13 * scale, mass_tol = 1e-13 * ref.mass_kg(vertex(2, 2, 2));
  EXPECT_TRUE(m.is_detached(corner));
  EXPECT_EQ(m.mass_kg(corner), 0.0);
  EXPECT_EQ(m.vertex_tensor(corner), Eigen::Matrix3d::Zero());
  double largest = 0;
  for (int v = 0; v < m.vertex_count(); ++v) {
    largest = std::max(largest, (m.vertex_tensor(v) - ref.vertex_tensor(v)).norm());
    EXPECT_LE((m.vertex_tensor(v) - ref.vertex_tensor(v)).norm(), tol) << "vertex " << v;
    EXPECT_NEAR(m.mass_kg(v), ref.mass_kg(v), mass_tol) << "vertex " << v;
    EXPECT_EQ(m.tetrahedra_at_vertex(v), ref.tetrahedra_at_vertex(v)) << "vertex " << v;
    EXPECT_EQ(m.is_detached(v), ref.is_detached(v)) << "vertex " << v;
  }
  auto edges = m.edges(), ref_edges = ref.edges();
  std::sort(edges.begin(), edges.end());
  std::sort(ref_edges.begin(), ref_edges.end());
  ASSERT_EQ(edges, ref_edges);
  for (const auto& [i, j] : edges) {
    Eigen::Matrix3d k, k_ref;
    ASSERT_TRUE(m.edge_tensor(i, j, k) && ref.edge_tensor(i, j, k_ref));
    largest = std::max(largest, (k - k_ref).norm());
    EXPECT_LE((k - k_ref).norm(), tol) << "edge " << i << "–" << j;
    EXPECT_EQ(m.tetrahedra_at_edge(i, j), ref.tetrahedra_at_edge(i, j));
  }
  std::printf("%zu tetrahedra cut: tensors differ by at most %.3g of the largest\n", removed.size(),
              largest / scale);
  Eigen::Matrix3d gone;
  EXPECT_FALSE(m.edge_tensor(a, b, gone));
  EXPECT_EQ(m.tetrahedra_at_edge(a, b), 0);

  const auto boundary = canonical_set(m.boundary_triangles());
  EXPECT_EQ(boundary.size(), m.boundary_triangles().size());
  EXPECT_EQ(boundary, canonical_set(ref.boundary_triangles()));
  EXPECT_EQ(boundary, boundary_of(mesh, rows(mesh.tetrahedra, keep)));

  // And the force is that of the remaining tetrahedra's K.
  VectorXd u = VectorXd::LinSpaced(3 * m.vertex_count(), -1e-3, 1e-3), f(u.size());
  m.internal_force(u, f);
  const VectorXd expected = full_stiffness(mesh, rows(mesh.tetrahedra, keep)) * u;
  EXPECT_LE((f + expected).norm(), 1e-12 * expected.norm());

  // Removing again, or what never was: an error and nothing changes.
  const std::uint64_t after = m.boundary_version();
  testing::expect_error<InputError>([&] { cut.model.remove_tetrahedron(7); },
                                    {"tetrahedron 7", "already removed", "remaining"});
  testing::expect_error<InputError>([&] { cut.model.remove_tetrahedron(384); },
                                    {"tetrahedron 384", "does not exist", "0..383"});
  EXPECT_EQ(m.boundary_version(), after);
  EXPECT_EQ(m.remaining_tetrahedra(), rebuilt.tets.rows());
}

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
    std::vector<int> free;
    for (int i = 1; i <= kCells; ++i)
      for (int v : face_x0(i)) free.push_back(v);
    const auto dofs = dofs_of(free);
    const VectorXd u = full_stiffness(mesh, mesh.tetrahedra)(dofs, dofs).llt().solve(load_n(dofs));
    VectorXd full = VectorXd::Zero(load_n.size());
    full(dofs) = u;
    return full(dofs_of(region_vertices));
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
  std::printf("ω_max %.6g rad/s (%d iterations), Gershgorin %.6g: Δt_crit %.4g s\n",
              bound.omega_max_rad_s, bound.iterations, bound.gershgorin_omega_rad_s,
              bound.critical_time_step_s);

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

// No allocation in what runs every step, nor in a cut.
TEST(TensorMass, StepAndCutAllocateNothing) {
  const Split split;
  Region r = split.region();
  r.model.set_interface_coupling(split.interface, split.schur);
  const VectorXd load = VectorXd::Constant(3 * r.model.vertex_count(), 1e-3);
  const VectorXd offset = VectorXd::Constant(split.schur.rows(), 1e-5);
  VectorXd f(load.size());
  const double dt = 0.9 * r.model.stable_time_step().critical_time_step_s;
  const auto before = testing::allocations();
  for (int n = 0; n < 10; ++n) {
    r.model.set_interface_offset(offset);
    r.model.step(dt, load);
  }
  r.model.internal_force(r.model.displacement_m(), f);
  r.model.apply_stiffness(r.model.displacement_m(), f);
  r.model.add_coupling_force(r.model.displacement_m(), f);
  r.model.remove_tetrahedron(5);
  r.model.step(dt, load);
  EXPECT_EQ(testing::allocations() - before, 0u);
}

// The tetrahedra a cutting segment sweeps through, against sampling the
// segment densely.
TEST(TensorMass, SegmentCrossesTheTetrahedraItMeets) {
  const TetMesh mesh = cube(true);
  Region r(mesh, mesh.tetrahedra, {});
  r.model.remove_tetrahedron(200);
  const Vector3d a(0.003, 0.011, 0.037), b(0.036, 0.027, 0.004);
  const auto crossed = r.model.tetrahedra_crossed_by_segment(a, b);
  // Barycentric coordinates of x in tetrahedron t.
  std::vector<Eigen::Matrix4d> to_bary(mesh.tetrahedra.rows());
  for (int t = 0; t < mesh.tetrahedra.rows(); ++t) {
    Eigen::Matrix4d m;
    for (int q = 0; q < 4; ++q) m.col(q) << mesh.vertices.row(mesh.tetrahedra(t, q)).transpose(), 1;
    to_bary[t] = m.inverse();
  }
  const auto bary = [&](int t, const Vector3d& x) {
    return Eigen::Vector4d(to_bary[t] * Eigen::Vector4d(x[0], x[1], x[2], 1));
  };
  // 20,001 samples 2.4 µm apart: a tetrahedron the segment meets has a sample
  // within 2.4 µm of it, barycentric coordinates ≥ −2.4 µm / 2 mm (its least
  // height) > −2e-3.
  std::set<int> inside, near;
  for (int n = 0; n <= 20000; ++n) {
    const Vector3d x = a + (b - a) * (n / 20000.0);
    for (int t = 0; t < mesh.tetrahedra.rows(); ++t) {
      if (r.model.is_removed(t)) continue;
      const double least = bary(t, x).minCoeff();
      if (least >= 0) inside.insert(t);
      if (least >= -2e-3) near.insert(t);
    }
  }
  const std::set<int> got(crossed.begin(), crossed.end());
  EXPECT_TRUE(std::ranges::is_sorted(crossed));
  EXPECT_TRUE(std::ranges::includes(got, inside));
  EXPECT_TRUE(std::ranges::includes(near, got));
  EXPECT_FALSE(got.contains(200));
  EXPECT_GT(got.size(), 10u);
}

// 7. Bad input: what, where, what is accepted.
TEST(TensorMass, BadInputIsNamed) {
  using testing::expect_error;
  const TetMesh mesh = cube(false);
  const auto ke =
      element_stiffnesses(mesh, mesh.tetrahedra, std::vector<Lame>(mesh.tetrahedra.rows(), kLiver));
  const auto build = [&](Eigen::MatrixX3d x, Eigen::MatrixX4i t, std::vector<Matrix12d> k,
                         TensorMassMaterial mat, std::vector<int> fixed) {
    return [=] { (void)TensorMassModel(x, t, k, mat, fixed); };
  };
  const auto& x = mesh.vertices;
  const auto& t = mesh.tetrahedra;
  auto bad_t = t;
  bad_t(3, 2) = 999;
  expect_error<InputError>(build(x, bad_t, ke, kTissue, {}),
                           {"tetrahedron 3", "vertex index 999", "0..124"});
  bad_t = t;
  bad_t(4, 1) = bad_t(4, 0);
  expect_error<InputError>(build(x, bad_t, ke, kTissue, {}),
                           {"tetrahedron 4", "twice", "four distinct"});
  bad_t = t;
  std::swap(bad_t(5, 2), bad_t(5, 3));
  expect_error<InputError>(build(x, bad_t, ke, kTissue, {}),
                           {"tetrahedron 5", "volume -", "positively oriented"});
  auto bad_x = x;
  bad_x(6, 1) = std::nan("");
  expect_error<InputError>(build(bad_x, t, ke, kTissue, {}),
                           {"vertex 6", "non-finite", "finite coordinates"});
  auto bad_k = ke;
  bad_k[2](0, 5) += 1e-6 * bad_k[2].cwiseAbs().maxCoeff();
  expect_error<InputError>(build(x, t, bad_k, kTissue, {}),
                           {"tetrahedron 2", "not symmetric", "1e-10 relative"});
  bad_k = ke;
  bad_k[9](1, 1) = INFINITY;
  expect_error<InputError>(build(x, t, bad_k, kTissue, {}),
                           {"tetrahedron 9", "non-finite", "finite values"});
  bad_k.pop_back();
  expect_error<InputError>(build(x, t, bad_k, kTissue, {}),
                           {"383 element stiffnesses for 384 tetrahedra", "one 12 × 12"});
  expect_error<InputError>(build(x, t, ke, {0, 0}, {}), {"density 0", "> 0"});
  expect_error<InputError>(build(x, t, ke, {1060, -1}, {}), {"γ = -1", "γ ≥ 0"});
  expect_error<InputError>(build(x, t, ke, kTissue, {3, 125}),
                           {"fixed vertex 125", "does not exist", "0..124"});
  expect_error<InputError>(build(x, t, ke, kTissue, {3, 3}), {"fixed vertex 3", "twice"});
  // Three tetrahedra on one face.
  Eigen::MatrixX3d fan(6, 3);
  fan << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0.2, 0.2, 1, 0.2, 0.2, -1, 0.3, 0.3, 2;
  Eigen::MatrixX4i three(3, 4);
  three << 0, 1, 2, 3, 0, 2, 1, 4, 0, 1, 2, 5;
  TetMesh fan_mesh;
  fan_mesh.vertices = fan;
  const auto fan_k = element_stiffnesses(fan_mesh, three, std::vector<Lame>(3, kLiver));
  expect_error<InputError>(build(fan, three, fan_k, kTissue, {}),
                           {"face (0, 1, 2)", "tetrahedra 0, 1 and 2", "at most two"});

  TensorMassModel m(x, t, ke, kTissue, {0});
  const MatrixXd s = MatrixXd::Identity(6, 6);
  expect_error<InputError>(
      [&] {
        m.set_interface_coupling({7, 200}, s);
      },
      {"interface vertex 200", "does not exist"});
  expect_error<InputError>(
      [&] {
        m.set_interface_coupling({7, 7}, s);
      },
      {"interface vertex 7", "twice"});
  expect_error<InputError>(
      [&] {
        m.set_interface_coupling({0, 7}, s);
      },
      {"interface vertex 0", "is fixed", "must be free"});
  expect_error<InputError>(
      [&] {
        m.set_interface_coupling({7, 8, 9}, s);
      },
      {"6 × 6 for 3 interface vertices", "9 × 9"});
  MatrixXd skew = s;
  skew(0, 1) = 0.5;
  expect_error<InputError>(
      [&] {
        m.set_interface_coupling({7, 8}, skew);
      },
      {"not symmetric", "symmetric to 1e-10"});
  expect_error<InputError>(
      [&] {
        m.set_interface_coupling({7, 8}, -s);
      },
      {"eigenvalue -1", "positive semi-definite"});
  EXPECT_TRUE(m.interface_vertices().empty());  // nothing set by a refusal
}

}  // namespace
}  // namespace palpate
