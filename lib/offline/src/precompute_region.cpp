// A precompute job with a cuttable region (docs/precompute.md, "A cuttable
// region"): the problem becomes the rest of the organ, the outside, whose
// compliance on its boundary (Γ and its part of the organ's surface) the
// in-memory pipeline computes and cross-checks as it does a whole organ's;
// the region's own data go into the file's /cut_region.

#include <algorithm>

#include "palpate/core/error.hpp"
#include "palpate/offline/region_tensors.hpp"
#include "precompute_steps.hpp"

namespace palpate::precompute {

namespace {

Eigen::VectorXi to_vector(const std::vector<int>& v) {
  return Eigen::Map<const Eigen::VectorXi>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

void restrict_to_outside(const CutRegionJob& job, Problem& p, Boundary& boundary,
                         PrecomputeReport& report, const Say& say) {
  const TetMesh& mesh = p.mesh;
  RegionSplit split = split_region(mesh, job.spec, p.fixed);
  for (const auto& w : split.warnings) say.warn(w);
  const RegionModel region = region_model(mesh, split, p.tet_material, p.lame);

  CutRegionData& c = p.model.cut_region.emplace();
  c.vertices_m = region.vertices_m;
  c.tetrahedra = region.tetrahedra;
  const auto nr = static_cast<Eigen::Index>(region.to_mesh.size());
  const auto nt = static_cast<Eigen::Index>(region.mesh_tets.size());
  c.source_vertex_ids.resize(nr);
  for (Eigen::Index i = 0; i < nr; ++i)
    c.source_vertex_ids[i] = mesh.source_ids[region.to_mesh[static_cast<size_t>(i)]];
  c.tet_material.resize(nt);
  c.element_stiffness_n_per_m.resize(nt, kElementStiffnessValues);
  for (Eigen::Index t = 0; t < nt; ++t) {
    c.tet_material[t] = p.tet_material[region.mesh_tets[static_cast<size_t>(t)]];
    // Row-major, the file's layout: Ke's transpose in Eigen's column-major memory.
    const Matrix12d Kt = region.element_stiffness[static_cast<size_t>(t)].transpose();
    c.element_stiffness_n_per_m.row(t) =
        Eigen::Map<const Eigen::Matrix<double, 1, kElementStiffnessValues>>(Kt.data());
  }
  const TensorMassTensors tensors =
      tensor_mass_tensors(nr, region.tetrahedra, region.element_stiffness);
  c.vertex_stiffness_n_per_m = tensors.vertex_n_per_m;
  c.edges = tensors.edges;
  c.edge_stiffness_n_per_m = tensors.edge_n_per_m;
  c.boundary_triangles = region.boundary_triangles;
  c.interface_vertices = to_vector(region.interface);
  c.fixed_vertices = to_vector(region.fixed);
  c.density_kg_m3 = job.density_kg_m3;
  c.damping_per_s = job.damping_per_s;
  c.spec = job.spec.describe();

  // Free Γ in the outside's numbering (region.interface is in increasing
  // mesh index, and the outside numbers vertices in increasing mesh order).
  p.interface_outside.clear();
  for (int r : region.interface)
    p.interface_outside.push_back(split.mesh_to_outside[region.to_mesh[static_cast<size_t>(r)]]);

  CutRegionReport& r = report.cut_region.emplace();
  r.spec = c.spec;
  r.tetrahedra = static_cast<long>(nt);
  r.organ_tetrahedra = static_cast<long>(mesh.tetrahedra.rows());
  r.vertices = static_cast<long>(nr);
  r.interface_vertices = static_cast<long>(region.interface.size());
  r.fixed_vertices = static_cast<long>(region.fixed.size());
  r.density_kg_m3 = c.density_kg_m3;
  r.damping_per_s = c.damping_per_s;

  boundary = outside_boundary(split);
  Eigen::VectorXi material(split.outside.tetrahedra.rows());
  for (Eigen::Index i = 0; i < material.size(); ++i)
    material[i] = p.tet_material[split.outside_tets[static_cast<size_t>(i)]];
  std::vector<int> fixed;
  for (int v : split.fixed_outside) fixed.push_back(split.mesh_to_outside[v]);
  p.tet_material = material;
  p.fixed = fixed;
  p.mesh = std::move(split.outside);
}

void index_interface(Problem& p) {
  const auto& cv = p.dofs.compliance_vertices;
  CutRegionData& c = *p.model.cut_region;
  c.interface_compliance_index.resize(static_cast<Eigen::Index>(p.interface_outside.size()));
  for (size_t i = 0; i < p.interface_outside.size(); ++i) {
    const auto it = std::lower_bound(cv.begin(), cv.end(), p.interface_outside[i]);
    // Every free Γ vertex is on the outside's boundary (outside_boundary()).
    PALPATE_DEMAND(it != cv.end() && *it == p.interface_outside[i]);
    c.interface_compliance_index[static_cast<Eigen::Index>(i)] = static_cast<int>(it - cv.begin());
  }
}

}  // namespace palpate::precompute
