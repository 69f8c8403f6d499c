// The cuttable region of issue 20: the split of a mesh (box, sphere, group),
// the outside's compliance on Γ and its surface, and the static hybrid
// (region K + coupling S) against the whole organ's K u = f.

#include "palpate/offline/cut_region.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <memory>
#include <set>

#include "offline/region_box.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "palpate/offline/sparse_cholesky.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace testing::region_box;  // NOLINT: the organ and its region

std::vector<int> clamped_at_x0(const TetMesh& mesh) {
  std::vector<int> fixed;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    if (mesh.vertices(v, 0) == 0) fixed.push_back(static_cast<int>(v));
  return fixed;
}

Eigen::Vector3d centroid(const TetMesh& mesh, int t) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int i = 0; i < 4; ++i) c += mesh.vertices.row(mesh.tetrahedra(t, i)).transpose();
  return c / 4;
}

// Checks that do not depend on how the region was chosen, computed here
// from the tetrahedra independently of split_region().
void expect_consistent_split(const TetMesh& mesh, const RegionSplit& split) {
  const auto nt = static_cast<size_t>(mesh.tetrahedra.rows());
  ASSERT_EQ(split.region_tets.size() + split.outside_tets.size(), nt);
  std::vector<int> side(nt, 0);
  for (int t : split.region_tets) ++side[t];
  for (int t : split.outside_tets) ++side[t];
  for (size_t t = 0; t < nt; ++t) EXPECT_EQ(side[t], 1) << "tetrahedron " << t;

  std::set<int> in_region, in_outside;
  for (int t : split.region_tets)
    for (int i = 0; i < 4; ++i) in_region.insert(mesh.tetrahedra(t, i));
  for (int t : split.outside_tets)
    for (int i = 0; i < 4; ++i) in_outside.insert(mesh.tetrahedra(t, i));
  std::vector<int> shared;
  std::set_intersection(in_region.begin(), in_region.end(), in_outside.begin(), in_outside.end(),
                        std::back_inserter(shared));
  EXPECT_EQ(split.interface_vertices, shared);
  EXPECT_EQ(split.region_vertices, std::vector<int>(in_region.begin(), in_region.end()));
  EXPECT_EQ(split.outside_to_mesh, std::vector<int>(in_outside.begin(), in_outside.end()));

  // The outside mesh is the outside tetrahedra, renumbered.
  ASSERT_EQ(static_cast<size_t>(split.outside.tetrahedra.rows()), split.outside_tets.size());
  for (size_t i = 0; i < split.outside_tets.size(); ++i)
    for (int k = 0; k < 4; ++k)
      EXPECT_EQ(split.outside_to_mesh[split.outside.tetrahedra(static_cast<Eigen::Index>(i), k)],
                mesh.tetrahedra(split.outside_tets[i], k));
  for (size_t o = 0; o < split.outside_to_mesh.size(); ++o) {
    EXPECT_EQ(split.mesh_to_outside[split.outside_to_mesh[o]], static_cast<int>(o));
    EXPECT_EQ(split.outside.vertices.row(static_cast<Eigen::Index>(o)),
              mesh.vertices.row(split.outside_to_mesh[o]));
  }
  // Γ lies on the outside's boundary (its faces shared with the region).
  const Boundary b = extract_boundary(split.outside);
  for (int v : split.interface_vertices)
    EXPECT_TRUE(b.on_surface[split.mesh_to_outside[v]]) << "interface vertex " << v;
}

TEST(CutRegion, BoxTakesTheTetrahedraWhoseCentroidIsInside) {
  const TetMesh mesh = organ();
  const RegionSpec spec = far_top_box();
  const RegionSplit split = split_region(mesh, spec, clamped_at_x0(mesh));
  expect_consistent_split(mesh, split);
  // 2 × 2 × 2 cells of 6 tetrahedra; 3 × 3 × 3 grid vertices, of which
  // those with i ≥ 5, j = 2, k ≥ 3 touch no outside cell.
  EXPECT_EQ(split.region_tets.size(), 48u);
  EXPECT_EQ(split.region_vertices.size(), 27u);
  EXPECT_EQ(split.interface_vertices.size(), 23u);
  EXPECT_TRUE(split.fixed_region.empty());
  EXPECT_EQ(split.fixed_outside.size(), static_cast<size_t>((kNy + 1) * (kNz + 1)));
  EXPECT_TRUE(split.warnings.empty());
  for (int t : split.region_tets) {
    const Eigen::Vector3d c = centroid(mesh, t);
    EXPECT_TRUE((c.array() >= spec.min_m.array()).all() && (c.array() <= spec.max_m.array()).all());
  }
}

TEST(CutRegion, SphereTakesTheTetrahedraWhoseCentroidIsInside) {
  const TetMesh mesh = organ();
  const RegionSpec spec = RegionSpec::sphere({0.07, 0.03, 0.05}, 0.02);
  const RegionSplit split = split_region(mesh, spec, clamped_at_x0(mesh));
  expect_consistent_split(mesh, split);
  size_t inside = 0;
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
    inside += (centroid(mesh, static_cast<int>(t)) - spec.center_m).norm() <= spec.radius_m;
  EXPECT_EQ(split.region_tets.size(), inside);
  EXPECT_GT(inside, 0u);
  EXPECT_GT(split.interface_vertices.size(), 0u);
}

TetMesh two_group_organ() {
  TetMesh mesh = organ();
  // Cells i = 5 (x > 5/6 of the length): the "tumour".
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
    mesh.tet_group[t] = centroid(mesh, static_cast<int>(t)).x() > kLx * 5 / kNx ? 2 : 1;
  mesh.group_names = {{1, "parenchyma"}, {2, "tumour"}};
  return mesh;
}

TEST(CutRegion, GroupTakesItsTetrahedra) {
  const TetMesh mesh = two_group_organ();
  for (const std::string name : {"tumour", "#2"}) {
    const RegionSplit split =
        split_region(mesh, RegionSpec::physical_group(name), clamped_at_x0(mesh));
    expect_consistent_split(mesh, split);
    EXPECT_EQ(split.region_tets.size(), static_cast<size_t>(6 * kNy * kNz));
    // Γ is the grid plane i = 5.
    EXPECT_EQ(split.interface_vertices.size(), static_cast<size_t>((kNy + 1) * (kNz + 1)));
    for (int v : split.interface_vertices) EXPECT_NEAR(mesh.vertices(v, 0), kLx * 5 / kNx, 1e-15);
    for (int t : split.region_tets) EXPECT_EQ(mesh.tet_group[t], 2);
  }
}

// ---- the static hybrid against the whole organ ------------------------------------

struct Whole {
  DofMap dofs;
  SparseMatrixd K;  // upper triangle, free DOFs
  std::unique_ptr<SparseCholesky> cholesky;
};

Whole whole_organ(const TetMesh& mesh, const std::vector<int>& fixed,
                  const Eigen::VectorXi& material_of_tet, const std::vector<Lame>& materials) {
  Whole w;
  w.dofs = make_dof_map(extract_boundary(mesh).on_surface, fixed);
  w.K = assemble_stiffness(mesh.vertices, mesh.tetrahedra, material_of_tet, materials, w.dofs);
  w.cholesky = std::make_unique<SparseCholesky>(w.K);
  return w;
}

// The hybrid: the region's K from its element blocks on its free vertices,
// plus S on its free Γ; the outside through its compliance.
struct Hybrid {
  RegionModel region;
  OutsideCompliance outside;
  std::vector<int> dof;  // region vertex → first DOF, or −1 when fixed
  Eigen::MatrixXd K;
};

Hybrid hybrid(const TetMesh& mesh, const RegionSplit& split, const Eigen::VectorXi& material_of_tet,
              const std::vector<Lame>& materials) {
  Hybrid h;
  h.region = region_model(mesh, split, material_of_tet, materials);
  h.outside = outside_compliance(split, material_of_tet, materials, OutsideMethod::condensation);
  const auto nr = static_cast<size_t>(h.region.vertices_m.rows());
  std::vector<bool> fixed(nr, false);
  for (int v : h.region.fixed) fixed[v] = true;
  int n = 0;
  for (size_t v = 0; v < nr; ++v) h.dof.push_back(fixed[v] ? -1 : 3 * n++);
  h.K = Eigen::MatrixXd::Zero(3 * n, 3 * n);
  for (size_t e = 0; e < h.region.element_stiffness.size(); ++e)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const int da = h.dof[h.region.tetrahedra(static_cast<Eigen::Index>(e), a)];
        const int db = h.dof[h.region.tetrahedra(static_cast<Eigen::Index>(e), b)];
        if (da >= 0 && db >= 0)
          h.K.block<3, 3>(da, db) += h.region.element_stiffness[e].block<3, 3>(3 * a, 3 * b);
      }
  const Eigen::MatrixXd& S = h.outside.coupling_stiffness;
  for (size_t a = 0; a < h.region.interface.size(); ++a)
    for (size_t b = 0; b < h.region.interface.size(); ++b)
      h.K.block<3, 3>(h.dof[h.region.interface[a]], h.dof[h.region.interface[b]]) +=
          S.block<3, 3>(3 * a, 3 * b);
  return h;
}

// Displacements (#V × 3, zero where not computed) of the hybrid under a
// force f_n on one mesh vertex, in the region or on the outside's surface.
Eigen::MatrixX3d hybrid_response(const TetMesh& mesh, const Hybrid& h, int loaded,
                                 const Eigen::Vector3d& f_n) {
  const OutsideCompliance& o = h.outside;
  const std::vector<int>& surface = o.surface;
  Eigen::VectorXd f_S = Eigen::VectorXd::Zero(3 * surface.size());
  Eigen::VectorXd f_R = Eigen::VectorXd::Zero(h.K.rows());
  const auto in_region = std::find(h.region.to_mesh.begin(), h.region.to_mesh.end(), loaded);
  if (in_region != h.region.to_mesh.end()) {
    f_R.segment<3>(h.dof[in_region - h.region.to_mesh.begin()]) = f_n;
  } else {
    const auto s = std::find_if(surface.begin(), surface.end(),
                                [&](int a) { return o.vertices[a] == loaded; });
    EXPECT_NE(s, surface.end());
    f_S.segment<3>(3 * (s - surface.begin())) = f_n;
  }
  // A load on the outside moves Γ by u_Γ⁰ = G_ΓS f_S; the region feels
  // −S (u_Γ − u_Γ⁰), i.e. K_h u = f_R + S u_Γ⁰ on the Γ rows.
  const Eigen::VectorXd u0 = vertex_block(o.G, o.interface, surface) * f_S;
  const Eigen::VectorXd Su0 = o.coupling_stiffness * u0;
  for (size_t a = 0; a < h.region.interface.size(); ++a)
    f_R.segment<3>(h.dof[h.region.interface[a]]) += Su0.segment<3>(3 * a);
  const Eigen::VectorXd u_R = h.K.llt().solve(f_R);
  Eigen::VectorXd u_G(3 * h.region.interface.size());
  for (size_t a = 0; a < h.region.interface.size(); ++a)
    u_G.segment<3>(3 * a) = u_R.segment<3>(h.dof[h.region.interface[a]]);
  // The force the region exerts on the outside, f_Γ = S (u_Γ − u_Γ⁰), and
  // the outside's surface u_S = G_SΓ f_Γ + G_SS f_S.
  const Eigen::VectorXd f_G = o.coupling_stiffness * (u_G - u0);
  const Eigen::VectorXd u_S =
      vertex_block(o.G, surface, o.interface) * f_G + vertex_block(o.G, surface, surface) * f_S;
  Eigen::MatrixX3d u = Eigen::MatrixX3d::Zero(mesh.vertices.rows(), 3);
  for (size_t v = 0; v < h.region.to_mesh.size(); ++v)
    if (h.dof[v] >= 0) u.row(h.region.to_mesh[v]) = u_R.segment<3>(h.dof[v]).transpose();
  for (size_t a = 0; a < surface.size(); ++a)
    u.row(o.vertices[surface[a]]) = u_S.segment<3>(3 * a).transpose();
  return u;
}

Eigen::MatrixX3d whole_response(const Whole& w, int loaded, const Eigen::Vector3d& f_n,
                                Eigen::Index nv) {
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(w.K.rows(), 1), u(w.K.rows(), 1);
  f.col(0).segment<3>(w.dofs.first_dof[loaded]) = f_n;
  w.cholesky->solve(f, u);
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(nv, 3);
  for (Eigen::Index v = 0; v < nv; ++v)
    if (w.dofs.first_dof[v] >= 0) out.row(v) = u.col(0).segment<3>(w.dofs.first_dof[v]).transpose();
  return out;
}

// max over the rows the hybrid computed of |u_h − u_w|, over max |u_w| there.
double relative_error(const Eigen::MatrixX3d& hybrid_u, const Eigen::MatrixX3d& whole_u,
                      const std::vector<int>& rows) {
  double diff = 0, scale = 0;
  for (int v : rows) {
    diff = std::max(diff, (hybrid_u.row(v) - whole_u.row(v)).cwiseAbs().maxCoeff());
    scale = std::max(scale, whole_u.row(v).cwiseAbs().maxCoeff());
  }
  return diff / scale;
}

class StaticHybrid : public ::testing::TestWithParam<int> {};

TEST_P(StaticHybrid, EqualsTheWholeOrgan) {
  const TetMesh mesh = organ();
  const std::vector<int> fixed = clamped_at_x0(mesh);
  // 0: the far top block; 1: a block at the clamp, so Γ holds fixed vertices.
  const RegionSpec spec =
      GetParam() == 0 ? far_top_box()
                      : RegionSpec::box({-1, kLy * 1 / kNy, kLz * 2 / kNz}, {kLx * 2 / kNx, 1, 1});
  const RegionSplit split = split_region(mesh, spec, fixed);
  ASSERT_EQ(split.fixed_region.empty(), GetParam() == 0);
  const Eigen::VectorXi mat = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());
  const std::vector<Lame> materials = {lame_parameters(85e3, 0.45)};
  const Hybrid h = hybrid(mesh, split, mat, materials);
  const Whole w = whole_organ(mesh, fixed, mat, materials);

  // S is symmetric positive definite, G_ΓΓ⁻¹.
  const Eigen::MatrixXd& S = h.outside.coupling_stiffness;
  EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(S).info(), Eigen::Success);
  EXPECT_LE((S * h.outside.interface_compliance - Eigen::MatrixXd::Identity(S.rows(), S.cols()))
                .cwiseAbs()
                .maxCoeff(),
            1e-8);

  std::vector<int> computed = split.region_vertices;
  for (int a : h.outside.surface) computed.push_back(h.outside.vertices[a]);
  const Boundary organ_surface = extract_boundary(mesh);
  // A region surface vertex (top face, middle of the block) and an outside
  // surface vertex (top face, middle of the organ), pushed down and sideways.
  const int in_region = testing::box_vertex(GetParam() == 0 ? 5 : 1, 2, kNz, kNx, kNy);
  const int on_outside = testing::box_vertex(3, 2, kNz, kNx, kNy);
  ASSERT_TRUE(
      std::binary_search(split.region_vertices.begin(), split.region_vertices.end(), in_region));
  ASSERT_FALSE(
      std::binary_search(split.region_vertices.begin(), split.region_vertices.end(), on_outside));
  // The whole organ's surface compliance by the existing method.
  const Eigen::MatrixXd G_whole = compliance_by_solves(w.K, w.dofs.surface_dofs(), {}, nullptr);
  const Eigen::Vector3d f_n(0.05, -0.02, -0.3);  // N: a small load
  for (const int loaded : {in_region, on_outside}) {
    ASSERT_TRUE(organ_surface.on_surface[loaded]);
    const Eigen::MatrixX3d u_h = hybrid_response(mesh, h, loaded, f_n);
    const Eigen::MatrixX3d u_w = whole_response(w, loaded, f_n, mesh.vertices.rows());
    // Exact algebra (block elimination) on a κ(K) ≈ 1e4 system: measured
    // 5e-15 to 4e-14; 1e-9 leaves room for other BLAS and compilers.
    EXPECT_LE(relative_error(u_h, u_w, split.region_vertices), 1e-9) << "loaded " << loaded;
    std::vector<int> surface;
    for (int a : h.outside.surface) surface.push_back(h.outside.vertices[a]);
    EXPECT_LE(relative_error(u_h, u_w, surface), 1e-9) << "loaded " << loaded;
    // Against G_SS of the whole organ, on the surface vertices both compute.
    const Eigen::VectorXd column = G_whole.middleCols<3>(w.dofs.first_dof[loaded]) * f_n;
    Eigen::MatrixX3d u_g = Eigen::MatrixX3d::Zero(mesh.vertices.rows(), 3);
    std::vector<int> both;
    for (size_t a = 0; a < w.dofs.compliance_vertices.size(); ++a) {
      const int v = w.dofs.compliance_vertices[a];
      u_g.row(v) = column.segment<3>(3 * static_cast<Eigen::Index>(a)).transpose();
      if (std::find(computed.begin(), computed.end(), v) != computed.end()) both.push_back(v);
    }
    EXPECT_GT(both.size(), 50u);
    EXPECT_LE(relative_error(u_h, u_g, both), 1e-9) << "loaded " << loaded;
  }
}
INSTANTIATE_TEST_SUITE_P(CutRegion, StaticHybrid, ::testing::Values(0, 1));

// The sample organ (Gmsh, two materials): the tumour as the region, enclosed
// (Γ is its whole surface), and a ball cutting the surface at the far end.
TEST(CutRegion, StaticHybridEqualsTheWholeSampleOrgan) {
  testing::TempDir dir;
  write_sample_organ(dir / "organ.msh", 0.012);
  TetMesh mesh = read_mesh(dir / "organ.msh", {});
  validate_and_compact(mesh);
  std::vector<int> fixed;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    if ((mesh.vertices.row(v) - Eigen::RowVector3d(-0.03, 0, 0.04)).norm() < 0.025)
      fixed.push_back(static_cast<int>(v));
  const Eigen::VectorXi mat = (mesh.tet_group.array() == 2).cast<int>();
  const std::vector<Lame> materials = {lame_parameters(85e3, 0.45), lame_parameters(340e3, 0.45)};
  const Whole w = whole_organ(mesh, fixed, mat, materials);
  auto nearest = [&](const std::vector<int>& among, const Eigen::RowVector3d& x) {
    return *std::min_element(among.begin(), among.end(), [&](int a, int b) {
      return (mesh.vertices.row(a) - x).norm() < (mesh.vertices.row(b) - x).norm();
    });
  };
  const Eigen::Vector3d f_n(0.1, 0.05, -0.4);  // N
  for (const RegionSpec& spec :
       {RegionSpec::physical_group("tumour"), RegionSpec::sphere({0.065, 0, 0.015}, 0.015)}) {
    SCOPED_TRACE(spec.describe());
    const RegionSplit split = split_region(mesh, spec, fixed);
    const Hybrid h = hybrid(mesh, split, mat, materials);
    std::vector<int> surface, region_surface;
    for (int a : h.outside.surface) surface.push_back(h.outside.vertices[a]);
    for (int v : split.region_vertices)
      if (split.on_organ_surface[v]) region_surface.push_back(v);
    std::vector<int> loads = {nearest(surface, {0.03, -0.005, 0.04})};
    if (spec.kind == RegionSpec::Kind::group) {
      // Enclosed: no organ surface in the region, its boundary all on Γ.
      EXPECT_TRUE(region_surface.empty());
      for (Eigen::Index f = 0; f < h.region.boundary_triangles.size(); ++f)
        EXPECT_TRUE(std::binary_search(split.interface_vertices.begin(),
                                       split.interface_vertices.end(),
                                       h.region.to_mesh[h.region.boundary_triangles.data()[f]]));
    } else {
      ASSERT_FALSE(region_surface.empty());
      loads.push_back(nearest(region_surface, {0.08, 0, 0.01}));
    }
    EXPECT_GT(split.interface_vertices.size(), 20u);
    for (const int loaded : loads) {
      const Eigen::MatrixX3d u_h = hybrid_response(mesh, h, loaded, f_n);
      const Eigen::MatrixX3d u_w = whole_response(w, loaded, f_n, mesh.vertices.rows());
      // Measured 1e-13 to 2e-13 (κ(K) is larger than the box's: two
      // materials, graded elements); the box's reason for 1e-9.
      EXPECT_LE(relative_error(u_h, u_w, split.region_vertices), 1e-9) << "loaded " << loaded;
      EXPECT_LE(relative_error(u_h, u_w, surface), 1e-9) << "loaded " << loaded;
    }
  }
}

TEST(CutRegion, OutsideComplianceMethodsAgree) {
  const TetMesh mesh = organ();
  const RegionSplit split = split_region(mesh, far_top_box(), clamped_at_x0(mesh));
  const Eigen::VectorXi mat = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());
  const std::vector<Lame> materials = {lame_parameters(85e3, 0.49)};
  const OutsideCompliance a = outside_compliance(split, mat, materials, OutsideMethod::solves);
  const OutsideCompliance b =
      outside_compliance(split, mat, materials, OutsideMethod::condensation);
  EXPECT_EQ(a.vertices, b.vertices);
  // As compliance_test's box (ν = 0.49 here); measured 7e-14 for G, 2e-14 for S.
  EXPECT_LE(max_relative_difference(a.G, b.G), 1e-10);
  EXPECT_LE(max_relative_difference(a.coupling_stiffness, b.coupling_stiffness), 1e-9);
  // Every free Γ vertex and every outside organ-surface vertex, once.
  EXPECT_EQ(a.interface.size() + a.surface.size(), a.vertices.size());
  EXPECT_EQ(a.interface.size(), split.interface_vertices.size());  // no fixed vertex on Γ
  for (int p : a.interface)
    EXPECT_TRUE(std::binary_search(split.interface_vertices.begin(), split.interface_vertices.end(),
                                   a.vertices[p]));
}

TEST(CutRegion, RegionModelBoundaryIsClosedAndOutward) {
  const TetMesh mesh = organ();
  const RegionSplit split = split_region(mesh, far_top_box(), clamped_at_x0(mesh));
  const Lame material = lame_parameters(85e3, 0.45);
  const RegionModel r =
      region_model(mesh, split, Eigen::VectorXi::Zero(mesh.tetrahedra.rows()), {material});
  ASSERT_EQ(r.element_stiffness.size(), split.region_tets.size());
  Matrix43d P;
  double volume = 0;
  for (Eigen::Index e = 0; e < r.tetrahedra.rows(); ++e) {
    for (int k = 0; k < 4; ++k) P.row(k) = r.vertices_m.row(r.tetrahedra(e, k));
    volume += signed_volume(P);
    EXPECT_LE((r.element_stiffness[e] - element_stiffness(P, material)).norm(), 0.0);
  }
  // Closed: the area vectors sum to zero; outward: the divergence theorem
  // (V = Σ (a · n) / 3 over the faces, n the area vector) gives +V.
  Eigen::Vector3d area = Eigen::Vector3d::Zero();
  double flux = 0;
  for (Eigen::Index f = 0; f < r.boundary_triangles.rows(); ++f) {
    const Eigen::Vector3d a = r.vertices_m.row(r.boundary_triangles(f, 0)).transpose();
    const Eigen::Vector3d b = r.vertices_m.row(r.boundary_triangles(f, 1)).transpose();
    const Eigen::Vector3d c = r.vertices_m.row(r.boundary_triangles(f, 2)).transpose();
    const Eigen::Vector3d n = 0.5 * (b - a).cross(c - a);
    area += n;
    flux += a.dot(n) / 3;
  }
  EXPECT_LE(area.norm(), 1e-15);
  EXPECT_NEAR(flux, volume, 1e-12 * volume);
  EXPECT_NEAR(volume, (kLx / 3) * (kLy / 2) * (kLz / 2), 1e-12 * volume);
  EXPECT_EQ(r.interface.size(), split.interface_vertices.size());
  for (size_t i = 0; i < r.interface.size(); ++i)
    EXPECT_EQ(r.to_mesh[r.interface[i]], split.interface_vertices[i]);
}

// ---- refusals and warnings -----------------------------------------------------------

TetMesh two_bodies() {
  const TetMesh a = testing::box_mesh(0.1, 0.06, 0.05, 2, 2, 2);
  TetMesh m = a;
  const auto nv = a.vertices.rows();
  m.vertices.resize(2 * nv, 3);
  m.vertices << a.vertices, a.vertices.rowwise() + Eigen::RowVector3d(0.2, 0, 0);
  m.tetrahedra.resize(2 * a.tetrahedra.rows(), 4);
  m.tetrahedra << a.tetrahedra, a.tetrahedra.array() + static_cast<int>(nv);
  m.tet_group = Eigen::VectorXi::Zero(m.tetrahedra.rows());
  m.source_ids = Eigen::VectorXi::LinSpaced(2 * nv, 0, static_cast<int>(2 * nv) - 1);
  m.source = "two.msh";
  return m;
}

TEST(CutRegion, RefusesWithWhatWhereAndWhatIsAccepted) {
  TetMesh mesh = organ();
  mesh.source = "organ.msh";
  const std::vector<int> fixed = clamped_at_x0(mesh);
  using testing::expect_error;
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::box({0.2, 0, 0}, {0.3, 0.1, 0.1}), fixed);
      },
      {"organ.msh", "box (0.2, 0, 0) to (0.3, 0.1, 0.1) m", "holds no tetrahedron's centroid",
       "the mesh spans (0, 0, 0) to (0.1, 0.06, 0.05) m", "at least one tetrahedron"});
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::sphere({0, 0, 0}, 1), fixed);
      },
      {"organ.msh", "sphere at (0, 0, 0) m of radius 1 m", "holds every tetrahedron", "576",
       "must leave a precomputed rest"});
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::sphere({0, 0, 0}, -1), fixed);
      },
      {"radius -1 m", "a finite number > 0 m"});
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::box({0.1, 0, 0}, {0, 1, 1}), fixed);
      },
      {"box (0.1, 0, 0) to (0, 1, 1) m", "min ≤ max"});
  expect_error<InputError>(
      [&] { split_region(two_group_organ(), RegionSpec::physical_group("liver"), fixed); },
      {"'liver'", "not a 3-D physical group", "its 3-D groups: parenchyma, tumour"});
  // The region swallows the clamp: the rest floats.
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::box({-1, -1, -1}, {0.02, 1, 1}), fixed);
      },
      {"organ.msh", "holds every attachment vertex (25 of them)", "no longer attached", "singular",
       "leaves the attachment outside"});
  // A slab across the middle cuts the rest in two; the free end floats.
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::box({kLx / 3, -1, -1}, {2 * kLx / 3, 1, 1}), fixed);
      },
      {"organ.msh", "into 2 pieces", "piece 2", "holds no attachment vertex", "singular",
       "every piece of the rest attached"});

  // Held along two lines, x = 0 and x = L at y = z = 0: the region takes
  // the second, and the rest is held along one line, about which it turns.
  std::vector<int> lines;
  for (int k = 0; k <= kNz; ++k)
    for (int i : {0, kNx}) lines.push_back(testing::box_vertex(i, 0, k, kNx, kNy));
  std::sort(lines.begin(), lines.end());
  expect_error<InputError>(
      [&] {
        split_region(mesh, RegionSpec::box({0.085, -1, -1}, {1, 1, 1}), lines);
      },
      {"box (0.085, -1, -1) to (1, 1, 1) m", "leaves the rest held too weakly",
       "organ.msh (outside the cut region)", "all on one line",
       "at least 3 vertices not on one line"});

  // Two separate bodies, each clamped at its x = min face.
  const TetMesh two = two_bodies();
  std::vector<int> two_fixed;
  for (Eigen::Index v = 0; v < two.vertices.rows(); ++v)
    if (two.vertices(v, 0) == 0 || two.vertices(v, 0) == 0.2)
      two_fixed.push_back(static_cast<int>(v));
  // The whole second body, which holds its own clamp: it shares nothing.
  expect_error<InputError>(
      [&] {
        split_region(two, RegionSpec::box({0.15, -1, -1}, {1, 1, 1}), two_fixed);
      },
      {"two.msh", "box (0.15, -1, -1) to (1, 1, 1) m", "shares no vertex with the rest",
       "separate body"});
  // The free half of the first body and the free half of the second, whose
  // clamp is in the region: the second's piece is held by its clamp, so
  // this one is accepted; without the second's clamp it floats.
  std::vector<int> first_fixed;
  for (int v : two_fixed)
    if (two.vertices(v, 0) == 0) first_fixed.push_back(v);
  EXPECT_NO_THROW(split_region(two, RegionSpec::box({0.06, -1, -1}, {1, 1, 1}), two_fixed));
  expect_error<InputError>(
      [&] {
        split_region(two, RegionSpec::box({0.06, -1, -1}, {1, 1, 1}), first_fixed);
      },
      {"two.msh", "piece 2 of 2", "touches neither the rest of the organ nor the attachment"});
}

TEST(CutRegion, WarnsOfALargeRegion) {
  const TetMesh mesh = organ();
  const RegionSplit split =
      split_region(mesh, RegionSpec::box({kLx / 2, -1, -1}, {1, 1, 1}), clamped_at_x0(mesh));
  ASSERT_EQ(split.warnings.size(), 1u);
  EXPECT_NE(split.warnings[0].find("288 of the organ's 576 tetrahedra (50 %)"), std::string::npos)
      << split.warnings[0];
}

}  // namespace
}  // namespace palpate
