// Issue 20's two halves together, on the sample organ: the cuttable region
// and the rest's compliance on its boundary (offline/cut_region) stepped by
// the tensor-mass model coupled through S = G_ΓΓ⁻¹ (runtime/tensor_mass),
// loaded and damped until it settles, against the pure precomputed answer:
// the whole organ's surface compliance G_SS (docs/model/hybrid-region.md, "The hybrid
// model"; docs/model/tensor-mass.md). The issue asks for 1 %; without a cut
// the two are the same linear problem, so the test holds them to the
// settling's tolerance.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "palpate/offline/compliance.hpp"
#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

/// The sample organ at 12 mm, held near one end, two materials (the
/// tumour four times stiffer), its whole surface compliance, and a ball
/// region cutting the surface at the far end, ready to step.
struct BallRegionOrgan {
  testing::TempDir dir;
  TetMesh mesh;
  std::vector<int> fixed;
  Eigen::VectorXi material_of_tet;
  std::vector<Lame> materials = {lame_parameters(85e3, 0.45), lame_parameters(340e3, 0.45)};
  DofMap dofs;
  MatrixXd G;  // the whole organ's G_SS
  RegionSplit split;
  RegionModel region;
  OutsideCompliance outside;

  BallRegionOrgan() {
    write_sample_organ(dir / "organ.msh", 0.012);
    mesh = read_mesh(dir / "organ.msh", {});
    validate_and_compact(mesh);
    for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
      if ((mesh.vertices.row(v) - Eigen::RowVector3d(-0.03, 0, 0.04)).norm() < 0.025)
        fixed.push_back(static_cast<int>(v));
    material_of_tet = (mesh.tet_group.array() == 2).cast<int>();
    dofs = make_dof_map(extract_boundary(mesh).on_surface, fixed);
    G = compliance_by_solves(
        assemble_stiffness(mesh.vertices, mesh.tetrahedra, material_of_tet, materials, dofs),
        dofs.surface_dofs(), {}, nullptr);
    split = split_region(mesh, RegionSpec::sphere({0.065, 0, 0.015}, 0.015), fixed);
    region = region_model(mesh, split, material_of_tet, materials);
    outside = outside_compliance(split, material_of_tet, materials, OutsideMethod::condensation);
  }

  /// The whole organ's surface displacement under f_n on surface vertex
  /// @p loaded, at mesh vertex @p v.
  Vector3d precomputed(int v, int loaded, const Vector3d& f_n) const {
    return G.block<3, 3>(dofs.first_dof[v], dofs.first_dof[loaded]) * f_n;
  }
};

/// ω_min of M⁻¹ (K + S) on the model's moving DOFs, from its own operators.
double slowest_frequency(TensorMassModel& model) {
  const int n = 3 * model.vertex_count();
  std::vector<int> moving;
  for (int v = 0; v < model.vertex_count(); ++v)
    if (!model.is_fixed(v)) moving.push_back(v);
  MatrixXd a(3 * moving.size(), 3 * moving.size());
  VectorXd e = VectorXd::Zero(n), ku(n), f(n);
  for (std::size_t c = 0; c < 3 * moving.size(); ++c) {
    const int dof = 3 * moving[c / 3] + static_cast<int>(c % 3);
    e[dof] = 1;
    model.apply_stiffness(e, ku);
    f.setZero();
    model.add_coupling_force(e, f);  // −S e on Γ
    for (std::size_t r = 0; r < 3 * moving.size(); ++r) {
      const int row = 3 * moving[r / 3] + static_cast<int>(r % 3);
      a(r, c) = (ku[row] - f[row]) /
                std::sqrt(model.mass_kg(moving[r / 3]) * model.mass_kg(moving[c / 3]));
    }
    e[dof] = 0;
  }
  return std::sqrt(
      Eigen::SelfAdjointEigenSolver<MatrixXd>(a, Eigen::EigenvaluesOnly).eigenvalues().minCoeff());
}

/// Steps the region, damped at γ = 2 ω_min, from rest until every mode has
/// decayed by e⁻³⁰, under a constant load on its own vertices and the
/// rest's loads entering as u_Γ⁰.
TensorMassModel settled(const BallRegionOrgan& o, const VectorXd& region_load_n,
                        const VectorXd& offset_m) {
  TensorMassModel probe(o.region.vertices_m, o.region.tetrahedra, o.region.element_stiffness,
                        {1060, 0}, o.region.fixed);
  probe.set_interface_coupling(o.region.interface, o.outside.coupling_stiffness);
  const double omega_min = slowest_frequency(probe);
  TensorMassModel model(o.region.vertices_m, o.region.tetrahedra, o.region.element_stiffness,
                        {1060, 2 * omega_min}, o.region.fixed);
  model.set_interface_coupling(o.region.interface, o.outside.coupling_stiffness);
  model.set_interface_offset(offset_m);
  const double dt = 0.9 * model.stable_time_step().critical_time_step_s;
  const int steps = static_cast<int>(std::ceil(30 / (omega_min * dt)));
  for (int n = 0; n < steps; ++n) model.step(dt, region_load_n);
  std::printf("settled in %d steps of %.3g µs (ω_min %.4g rad/s)\n", steps, dt * 1e6, omega_min);
  return model;
}

/// The hybrid's surface displacement at every organ-surface vertex it
/// computes: the region's own from the model, the rest's from
/// u_S = G_SΓ f_Γ + G_SS f_S with f_Γ = S (u_Γ − u_Γ⁰), the force the region
/// exerts on the rest. Returns the relative error against @p expected.
double relative_error_on_surface(const BallRegionOrgan& o, const TensorMassModel& model,
                                 const VectorXd& offset_m, const VectorXd& outside_load_n,
                                 int loaded, const Vector3d& f_n) {
  const auto& out = o.outside;
  VectorXd u_gamma(3 * o.region.interface.size());
  for (std::size_t k = 0; k < o.region.interface.size(); ++k)
    u_gamma.segment<3>(3 * k) = model.displacement_m().segment<3>(3 * o.region.interface[k]);
  const VectorXd f_gamma = out.coupling_stiffness * (u_gamma - offset_m);
  const VectorXd u_s = vertex_block(out.G, out.surface, out.interface) * f_gamma +
                       vertex_block(out.G, out.surface, out.surface) * outside_load_n;
  double error2 = 0, norm2 = 0;
  int compared = 0;
  auto compare = [&](int mesh_vertex, const Vector3d& u) {
    const Vector3d expected = o.precomputed(mesh_vertex, loaded, f_n);
    error2 += (u - expected).squaredNorm();
    norm2 += expected.squaredNorm();
    ++compared;
  };
  for (int r = 0; r < static_cast<int>(o.region.to_mesh.size()); ++r) {
    const int v = o.region.to_mesh[r];
    if (o.split.on_organ_surface[v] && !model.is_fixed(r))
      compare(v, model.displacement_m().segment<3>(3 * r));
  }
  for (std::size_t a = 0; a < out.surface.size(); ++a)
    compare(out.vertices[out.surface[a]], u_s.segment<3>(3 * static_cast<Eigen::Index>(a)));
  EXPECT_GT(compared, 100);
  return std::sqrt(error2 / norm2);
}

int nearest(const TetMesh& mesh, const std::vector<int>& among, const Eigen::RowVector3d& x) {
  return *std::min_element(among.begin(), among.end(), [&](int a, int b) {
    return (mesh.vertices.row(a) - x).norm() < (mesh.vertices.row(b) - x).norm();
  });
}

TEST(HybridRegion, SettlesOnTheWholeOrgansPrecomputedAnswer) {
  const BallRegionOrgan o;
  ASSERT_GT(o.region.interface.size(), 10u);
  const Vector3d f_n(0.1, 0.05, -0.4);  // N: a small load (displacements ≪ the mesh size)

  // A load on the region's part of the organ's surface.
  std::vector<int> region_surface;
  for (int r = 0; r < static_cast<int>(o.region.to_mesh.size()); ++r)
    if (o.split.on_organ_surface[o.region.to_mesh[r]]) region_surface.push_back(r);
  ASSERT_FALSE(region_surface.empty());
  std::vector<int> region_surface_mesh;
  for (int r : region_surface) region_surface_mesh.push_back(o.region.to_mesh[r]);
  const int loaded = nearest(o.mesh, region_surface_mesh, {0.08, 0, 0.01});
  const int loaded_r =
      static_cast<int>(std::find(o.region.to_mesh.begin(), o.region.to_mesh.end(), loaded) -
                       o.region.to_mesh.begin());
  VectorXd region_load = VectorXd::Zero(3 * o.region.vertices_m.rows());
  region_load.segment<3>(3 * loaded_r) = f_n;
  const VectorXd no_offset = VectorXd::Zero(3 * o.region.interface.size());
  const VectorXd no_outside_load = VectorXd::Zero(3 * o.outside.surface.size());
  const TensorMassModel on_region = settled(o, region_load, no_offset);
  const double e_region =
      relative_error_on_surface(o, on_region, no_offset, no_outside_load, loaded, f_n);
  std::printf("load in the region: relative error %.3g against G_SS\n", e_region);
  EXPECT_LE(e_region, 1e-6);

  // A load on the rest's surface: it reaches the region as u_Γ⁰ = G_ΓS f_S.
  std::vector<int> rest_surface;
  for (int a : o.outside.surface) rest_surface.push_back(o.outside.vertices[a]);
  const int loaded_s = nearest(o.mesh, rest_surface, {0.03, -0.005, 0.04});
  VectorXd outside_load = no_outside_load;
  const auto at = std::find(rest_surface.begin(), rest_surface.end(), loaded_s);
  outside_load.segment<3>(3 * (at - rest_surface.begin())) = f_n;
  const VectorXd offset =
      vertex_block(o.outside.G, o.outside.interface, o.outside.surface) * outside_load;
  const TensorMassModel on_rest =
      settled(o, VectorXd::Zero(3 * o.region.vertices_m.rows()), offset);
  const double e_rest = relative_error_on_surface(o, on_rest, offset, outside_load, loaded_s, f_n);
  std::printf("load on the rest: relative error %.3g against G_SS\n", e_rest);
  EXPECT_LE(e_rest, 1e-6);
}

}  // namespace
}  // namespace palpate
