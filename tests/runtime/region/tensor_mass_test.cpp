// The tensor-mass model of a cuttable region (runtime/tensor_mass): its
// tensors against the assembled K of the offline layer, rigid motions, cuts
// against a model built from the remaining tetrahedra, the segment query,
// bad input. Dynamics: tensor_mass_dynamics_test.cpp.

#include "palpate/runtime/tensor_mass.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"
#include "runtime/tensor_mass_meshes.hpp"
#include "support/allocation_counter.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace tensor_mass_test;
using Triangle = std::array<int, 3>;

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

// The tetrahedra a cutting segment sweeps through, against sampling the
// segment densely.
TEST(TensorMass, SegmentCrossesTheTetrahedraItMeets) {
  const TetMesh mesh = cube(true);
  Region r(mesh, mesh.tetrahedra, {});
  r.model.remove_tetrahedron(200);
  const Vector3d a(0.003, 0.011, 0.037), b(0.036, 0.027, 0.004);
  const auto crossed = r.model.tetrahedra_crossed_by_segment(a, b);
  // Barycentric coordinates of x in tetrahedron t: the rows of the inverse
  // of [vertices; 1], in plain doubles for the loop below (its 7.7 million
  // evaluations are this test's time, and the sanitizer build compiles the
  // tests' own code unoptimized: docs/sanitizers.md).
  std::vector<std::array<double, 16>> to_bary(mesh.tetrahedra.rows());
  for (int t = 0; t < mesh.tetrahedra.rows(); ++t) {
    Eigen::Matrix4d m;
    for (int q = 0; q < 4; ++q) m.col(q) << mesh.vertices.row(mesh.tetrahedra(t, q)).transpose(), 1;
    Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(to_bary[t].data()) = m.inverse();
  }
  const auto least_bary = [&](int t, const Vector3d& x) {
    const double* row = to_bary[t].data();
    double least = INFINITY;
    for (int q = 0; q < 4; ++q, row += 4)
      least = std::min(least, row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3]);
    return least;
  };
  // 20,001 samples 2.4 µm apart: a tetrahedron the segment meets has a sample
  // within 2.4 µm of it, barycentric coordinates ≥ −2.4 µm / 2 mm (its least
  // height) > −2e-3.
  std::set<int> inside, near;
  for (int n = 0; n <= 20000; ++n) {
    const Vector3d x = a + (b - a) * (n / 20000.0);
    for (int t = 0; t < mesh.tetrahedra.rows(); ++t) {
      if (r.model.is_removed(t)) continue;
      const double least = least_bary(t, x);
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
