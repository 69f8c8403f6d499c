#include "palpate/offline/cut_region.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <map>
#include <set>

#include "palpate/core/error.hpp"
#include "palpate/offline/attachment.hpp"

namespace palpate {

namespace {

std::string point(const Eigen::Vector3d& x) {
  return fmt::format("({:.6g}, {:.6g}, {:.6g})", x.x(), x.y(), x.z());
}

std::string extent(const TetMesh& mesh) {
  const Eigen::Vector3d lo = mesh.vertices.colwise().minCoeff().transpose();
  const Eigen::Vector3d hi = mesh.vertices.colwise().maxCoeff().transpose();
  return fmt::format("the mesh spans {} to {} m", point(lo), point(hi));
}

// The name a 3-D group goes by in messages and in RegionSpec::group.
std::string group_name(const TetMesh& mesh, int tag) {
  auto it = mesh.group_names.find(tag);
  return it != mesh.group_names.end() ? it->second : fmt::format("#{}", tag);
}

// Faces of exactly one of @p tets, oriented outward (normal = (b−a)×(c−a)),
// sorted. Unlike extract_boundary() it does not require a 2-manifold: a
// region or an outside chosen by centroids can touch itself along an edge,
// which matters neither to a compliance nor to a tensor-mass model.
std::vector<std::array<int, 3>> faces_of_one(const Eigen::MatrixX4i& tetrahedra,
                                             const std::vector<int>& tets) {
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  std::map<std::array<int, 3>, std::pair<std::array<int, 3>, int>> faces;
  for (int t : tets)
    for (const auto& f : kFace) {
      const std::array<int, 3> o = {tetrahedra(t, f[0]), tetrahedra(t, f[1]), tetrahedra(t, f[2])};
      std::array<int, 3> key = o;
      std::sort(key.begin(), key.end());
      auto [it, inserted] = faces.try_emplace(key, o, 0);
      ++it->second.second;
    }
  std::vector<std::array<int, 3>> out;
  for (const auto& [key, seen] : faces)
    if (seen.second == 1) out.push_back(seen.first);
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<int> all_tets(Eigen::Index count) {
  std::vector<int> t(static_cast<size_t>(count));
  for (size_t i = 0; i < t.size(); ++i) t[i] = static_cast<int>(i);
  return t;
}

void check_spec(const RegionSpec& spec) {
  switch (spec.kind) {
    case RegionSpec::Kind::box:
      if (!spec.min_m.allFinite() || !spec.max_m.allFinite() ||
          !(spec.min_m.array() <= spec.max_m.array()).all())
        throw InputError(
            fmt::format("the cut region's {} is not a box: its corners must be "
                        "finite, with min ≤ max on every axis",
                        spec.describe()));
      break;
    case RegionSpec::Kind::sphere:
      if (!spec.center_m.allFinite() || !(spec.radius_m > 0) || !std::isfinite(spec.radius_m))
        throw InputError(
            fmt::format("the cut region's {} is not a ball: its centre must be "
                        "finite and its radius a finite number > 0 m",
                        spec.describe()));
      break;
    case RegionSpec::Kind::group:
      break;
  }
}

}  // namespace

RegionSpec RegionSpec::box(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m) {
  RegionSpec s;
  s.kind = Kind::box;
  s.min_m = min_m;
  s.max_m = max_m;
  return s;
}

RegionSpec RegionSpec::sphere(const Eigen::Vector3d& center_m, double radius_m) {
  RegionSpec s;
  s.kind = Kind::sphere;
  s.center_m = center_m;
  s.radius_m = radius_m;
  return s;
}

RegionSpec RegionSpec::physical_group(const std::string& name) {
  RegionSpec s;
  s.kind = Kind::group;
  s.group = name;
  return s;
}

std::string RegionSpec::describe() const {
  switch (kind) {
    case Kind::box:
      return fmt::format("box {} to {} m", point(min_m), point(max_m));
    case Kind::sphere:
      return fmt::format("sphere at {} m of radius {:.6g} m", point(center_m), radius_m);
    case Kind::group:
      return fmt::format("physical group '{}'", group);
  }
  return "region";
}

RegionSplit split_region(const TetMesh& mesh, const RegionSpec& spec,
                         const std::vector<int>& fixed_vertices) {
  check_spec(spec);
  const auto nv = static_cast<size_t>(mesh.vertices.rows());
  const auto nt = static_cast<int>(mesh.tetrahedra.rows());
  const std::string where = mesh.source.empty() ? "the mesh" : mesh.source;

  // Which tetrahedra: the centroid rule (cut_region.hpp says why), or the group.
  std::vector<bool> in_region(static_cast<size_t>(nt), false);
  if (spec.kind == RegionSpec::Kind::group) {
    std::set<int> tags(mesh.tet_group.begin(), mesh.tet_group.end());
    int wanted = 0;
    bool found = false;
    std::string known;
    for (int tag : tags) {
      const std::string name = group_name(mesh, tag);
      known += (known.empty() ? "" : ", ") + name;
      if (name == spec.group || fmt::format("#{}", tag) == spec.group) {
        wanted = tag;
        found = true;
      }
    }
    if (!found)
      throw InputError(fmt::format(
          "{}: the cut region's physical group '{}' is not a 3-D physical group of the mesh; "
          "its 3-D groups: {}",
          where, spec.group, known));
    for (int t = 0; t < nt; ++t) in_region[t] = mesh.tet_group[t] == wanted;
  } else {
    for (int t = 0; t < nt; ++t) {
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (int i = 0; i < 4; ++i) c += mesh.vertices.row(mesh.tetrahedra(t, i)).transpose();
      c /= 4;
      in_region[t] =
          spec.kind == RegionSpec::Kind::box
              ? (c.array() >= spec.min_m.array()).all() && (c.array() <= spec.max_m.array()).all()
              : (c - spec.center_m).norm() <= spec.radius_m;
    }
  }

  RegionSplit split;
  for (int t = 0; t < nt; ++t) (in_region[t] ? split.region_tets : split.outside_tets).push_back(t);
  if (split.region_tets.empty())
    throw InputError(fmt::format(
        "{}: the cut region's {} holds no tetrahedron's centroid; {}; a region must hold the "
        "centroid of at least one tetrahedron",
        where, spec.describe(), extent(mesh)));
  if (split.outside_tets.empty())
    throw InputError(
        fmt::format("{}: the cut region's {} holds every tetrahedron of the mesh ({}); the "
                    "region must leave a precomputed rest, attached, around it",
                    where, spec.describe(), nt));

  std::vector<bool> used_region(nv, false), used_outside(nv, false), fixed(nv, false);
  for (int t : split.region_tets)
    for (int i = 0; i < 4; ++i) used_region[mesh.tetrahedra(t, i)] = true;
  for (int t : split.outside_tets)
    for (int i = 0; i < 4; ++i) used_outside[mesh.tetrahedra(t, i)] = true;
  for (int v : fixed_vertices) fixed.at(static_cast<size_t>(v)) = true;
  split.mesh_to_outside.assign(nv, -1);
  for (size_t v = 0; v < nv; ++v) {
    const int iv = static_cast<int>(v);
    if (used_region[v]) split.region_vertices.push_back(iv);
    if (used_region[v] && used_outside[v]) split.interface_vertices.push_back(iv);
    if (used_outside[v]) {
      split.mesh_to_outside[v] = static_cast<int>(split.outside_to_mesh.size());
      split.outside_to_mesh.push_back(iv);
      if (fixed[v]) split.fixed_outside.push_back(iv);
    }
    if (used_region[v] && fixed[v]) split.fixed_region.push_back(iv);
  }

  split.on_organ_surface.assign(nv, false);
  for (const auto& f : faces_of_one(mesh.tetrahedra, all_tets(nt)))
    for (int v : f) split.on_organ_surface[v] = true;

  // The outside as a mesh of its own, vertices in increasing mesh order.
  TetMesh& out = split.outside;
  const auto no = static_cast<Eigen::Index>(split.outside_to_mesh.size());
  out.source = fmt::format("{} (outside the cut region)", where);
  out.vertices.resize(no, 3);
  out.source_ids.resize(no);
  for (Eigen::Index o = 0; o < no; ++o) {
    const int v = split.outside_to_mesh[o];
    out.vertices.row(o) = mesh.vertices.row(v);
    out.source_ids[o] = mesh.source_ids.size() ? mesh.source_ids[v] : v;
  }
  out.source_vertex_count = mesh.source_vertex_count;
  out.tetrahedra.resize(static_cast<Eigen::Index>(split.outside_tets.size()), 4);
  out.tet_group.resize(out.tetrahedra.rows());
  for (Eigen::Index i = 0; i < out.tetrahedra.rows(); ++i) {
    const int t = split.outside_tets[i];
    for (int k = 0; k < 4; ++k) out.tetrahedra(i, k) = split.mesh_to_outside[mesh.tetrahedra(t, k)];
    out.tet_group[i] = mesh.tet_group.size() ? mesh.tet_group[t] : 0;
  }
  out.group_names = mesh.group_names;
  for (const auto& [name, ids] : mesh.group_vertices) {
    std::vector<int> kept;
    for (int v : ids)
      if (split.mesh_to_outside[v] >= 0) kept.push_back(split.mesh_to_outside[v]);
    out.group_vertices[name] = std::move(kept);
  }

  // Γ is where the region hands its force to the rest: without it the
  // region is a separate body the rest's compliance knows nothing of.
  if (split.interface_vertices.empty())
    throw InputError(fmt::format(
        "{}: the cut region's {} shares no vertex with the rest of the organ (it is a separate "
        "body); the region must be part of the organ the rest is attached to",
        where, spec.describe()));

  // The outside's K must be positive definite: every part of it held.
  if (split.fixed_outside.empty())
    throw InputError(fmt::format(
        "{}: the cut region's {} holds every attachment vertex ({} of them), so the rest of the "
        "organ is no longer attached: its stiffness would be singular; choose a region that "
        "leaves the attachment outside it",
        where, spec.describe(), fixed_vertices.size()));
  int parts = 0;
  const std::vector<int> part_of = solid_parts(out, &parts);
  std::vector<int> fixed_in_part(static_cast<size_t>(parts), 0), first_tet(parts, -1);
  for (Eigen::Index i = 0; i < out.tetrahedra.rows(); ++i) {
    const int p = part_of[i];
    if (first_tet[p] < 0) first_tet[p] = split.outside_tets[i];
    for (int k = 0; k < 4; ++k)
      if (fixed[split.outside_to_mesh[out.tetrahedra(i, k)]]) ++fixed_in_part[p];
  }
  for (int p = 0; p < parts; ++p)
    if (fixed_in_part[p] == 0)
      throw InputError(fmt::format(
          "{}: the cut region's {} cuts the rest of the organ into {} pieces, and piece {} (the "
          "one holding tetrahedron {}) holds no attachment vertex: its stiffness would be "
          "singular; choose a region that leaves every piece of the rest attached, or one piece",
          where, spec.describe(), parts, p + 1, first_tet[p]));
  std::vector<int> fixed_out_local;
  for (int v : split.fixed_outside) fixed_out_local.push_back(split.mesh_to_outside[v]);
  try {
    check_attachment_stops_rigid_motion(out, fixed_out_local);
  } catch (const InputError& e) {
    throw InputError(fmt::format("the cut region's {} leaves the rest held too weakly: {}",
                                 spec.describe(), e.what()));
  }

  // Each piece of the region must be held: by the rest through Γ or by the
  // attachment. A piece touching neither would float.
  {
    TetMesh region;
    region.vertices = mesh.vertices;
    region.tetrahedra.resize(static_cast<Eigen::Index>(split.region_tets.size()), 4);
    for (size_t i = 0; i < split.region_tets.size(); ++i)
      region.tetrahedra.row(static_cast<Eigen::Index>(i)) =
          mesh.tetrahedra.row(split.region_tets[i]);
    int rparts = 0;
    const std::vector<int> rpart = solid_parts(region, &rparts);
    std::vector<bool> held(static_cast<size_t>(rparts), false);
    for (size_t i = 0; i < split.region_tets.size(); ++i)
      for (int k = 0; k < 4; ++k) {
        const int v = region.tetrahedra(static_cast<Eigen::Index>(i), k);
        if (used_outside[v] || fixed[v]) held[rpart[i]] = true;
      }
    for (size_t i = 0; i < split.region_tets.size(); ++i)
      if (!held[rpart[i]])
        throw InputError(fmt::format(
            "{}: piece {} of {} of the cut region's {} (the one holding tetrahedron {}) touches "
            "neither the rest of the organ nor the attachment; every piece of the region must "
            "share vertices with the rest",
            where, rpart[i] + 1, rparts, spec.describe(), split.region_tets[i]));
  }

  const auto n_region = static_cast<int>(split.region_tets.size());
  if (n_region > kRegionFractionWarning * nt)
    split.warnings.push_back(fmt::format(
        "the cut region's {} holds {} of the organ's {} tetrahedra ({:.0f} %): the precomputed "
        "part is the smaller one; a cuttable region is meant to be where the surgery happens",
        spec.describe(), n_region, nt, 100.0 * n_region / nt));
  if (n_region > kRegionTetrahedraAt1kHz)
    split.warnings.push_back(fmt::format(
        "the cut region's {} holds {} tetrahedra, more than the {} a tensor-mass model steps "
        "within half a 1 ms tick on one core (at 4 mm elements)",
        spec.describe(), n_region, kRegionTetrahedraAt1kHz));
  int free_interface = 0;
  for (int v : split.interface_vertices) free_interface += fixed[v] ? 0 : 1;
  if (free_interface > kInterfaceVerticesAt1kHz)
    split.warnings.push_back(fmt::format(
        "the cut region's {} has {} free interface vertices, more than {}: the coupling force, "
        "a dense {}×{} product, takes a large part of a 1 kHz step",
        spec.describe(), free_interface, kInterfaceVerticesAt1kHz, 3 * free_interface,
        3 * free_interface));
  return split;
}

Eigen::MatrixXd vertex_block(CRef<Eigen::MatrixXd> G, const std::vector<int>& rows,
                             const std::vector<int>& cols) {
  Eigen::MatrixXd B(3 * rows.size(), 3 * cols.size());
  for (size_t a = 0; a < rows.size(); ++a)
    for (size_t b = 0; b < cols.size(); ++b)
      B.block<3, 3>(3 * a, 3 * b) = G.block<3, 3>(3 * rows[a], 3 * cols[b]);
  return B;
}

Boundary outside_boundary(const RegionSplit& split) {
  const TetMesh& out = split.outside;
  Boundary b;
  b.on_surface.assign(static_cast<size_t>(out.vertices.rows()), false);
  const auto faces = faces_of_one(out.tetrahedra, all_tets(out.tetrahedra.rows()));
  b.triangles.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      b.triangles(static_cast<Eigen::Index>(f), k) = faces[f][k];
      b.on_surface[faces[f][k]] = true;
    }
  for (int v : split.interface_vertices) b.on_surface[split.mesh_to_outside[v]] = true;
  return b;
}

OutsideCompliance outside_compliance(const RegionSplit& split,
                                     CRef<Eigen::VectorXi> material_of_tet,
                                     const std::vector<Lame>& materials, OutsideMethod method,
                                     const ComplianceOptions& options) {
  const TetMesh& out = split.outside;
  const auto no = static_cast<size_t>(out.vertices.rows());
  // The outside's boundary is Γ and its part of the organ's surface: every
  // face of one outside tetrahedron is either a face of the organ or one it
  // shares with a region tetrahedron (outside_boundary()).
  const std::vector<bool> on_boundary = outside_boundary(split).on_surface;
  PALPATE_DEMAND(on_boundary.size() == no);
  std::vector<bool> is_interface(split.mesh_to_outside.size(), false);
  for (int v : split.interface_vertices) is_interface[v] = true;
  std::vector<int> fixed_local;
  for (int v : split.fixed_outside) fixed_local.push_back(split.mesh_to_outside[v]);
  const DofMap dofs = make_dof_map(on_boundary, fixed_local);
  Eigen::VectorXi material(out.tetrahedra.rows());
  for (Eigen::Index i = 0; i < material.size(); ++i)
    material[i] = material_of_tet[split.outside_tets[i]];
  const SparseMatrixd K =
      assemble_stiffness(out.vertices, out.tetrahedra, material, materials, dofs);

  OutsideCompliance result;
  const int m = dofs.surface_dofs();
  result.G = method == OutsideMethod::solves
                 ? compliance_by_solves(K, m, options, &result.stats)
                 : compliance_by_condensation(K, m, options, &result.stats);
  for (size_t a = 0; a < dofs.compliance_vertices.size(); ++a) {
    const int v = split.outside_to_mesh[dofs.compliance_vertices[a]];
    result.vertices.push_back(v);
    if (is_interface[v])
      result.interface.push_back(static_cast<int>(a));
    else if (split.on_organ_surface[v])
      result.surface.push_back(static_cast<int>(a));
    else
      PALPATE_DEMAND(false);  // a boundary vertex of the outside is on Γ or the organ's surface
  }

  // S = G_ΓΓ⁻¹ (docs/model/hybrid-region.md, "The hybrid model"): the outside's Schur
  // complement onto Γ, the stiffness the region feels at its interface.
  const Eigen::MatrixXd Ggg = vertex_block(result.G, result.interface, result.interface);
  result.interface_compliance = 0.5 * (Ggg + Ggg.transpose());
  const Eigen::LLT<Eigen::MatrixXd> llt(result.interface_compliance);
  if (llt.info() != Eigen::Success) {
    int worst = 0;
    const double smallest = min_diagonal_block_eigenvalue(result.interface_compliance, &worst);
    throw NumericalError(fmt::format(
        "{}: the outside's compliance on the interface G_ΓΓ ({}×{}) is not positive definite "
        "(smallest diagonal-block eigenvalue {:.3g} m/N, at interface vertex {}); the coupling "
        "stiffness S = G_ΓΓ⁻¹ needs it symmetric positive definite",
        out.source, Ggg.rows(), Ggg.cols(), smallest,
        result.vertices[result.interface[static_cast<size_t>(worst)]]));
  }
  const Eigen::MatrixXd S = llt.solve(Eigen::MatrixXd::Identity(Ggg.rows(), Ggg.cols()));
  result.coupling_stiffness = 0.5 * (S + S.transpose());
  return result;
}

RegionModel region_model(const TetMesh& mesh, const RegionSplit& split,
                         CRef<Eigen::VectorXi> material_of_tet,
                         const std::vector<Lame>& materials) {
  RegionModel r;
  r.to_mesh = split.region_vertices;
  std::vector<int> local(static_cast<size_t>(mesh.vertices.rows()), -1);
  r.vertices_m.resize(static_cast<Eigen::Index>(r.to_mesh.size()), 3);
  for (size_t i = 0; i < r.to_mesh.size(); ++i) {
    local[r.to_mesh[i]] = static_cast<int>(i);
    r.vertices_m.row(static_cast<Eigen::Index>(i)) = mesh.vertices.row(r.to_mesh[i]);
  }
  r.mesh_tets = split.region_tets;
  r.tetrahedra.resize(static_cast<Eigen::Index>(r.mesh_tets.size()), 4);
  r.element_stiffness.reserve(r.mesh_tets.size());
  for (size_t i = 0; i < r.mesh_tets.size(); ++i) {
    const int t = r.mesh_tets[i];
    Matrix43d P;
    for (int k = 0; k < 4; ++k) {
      r.tetrahedra(static_cast<Eigen::Index>(i), k) = local[mesh.tetrahedra(t, k)];
      P.row(k) = mesh.vertices.row(mesh.tetrahedra(t, k));
    }
    r.element_stiffness.push_back(element_stiffness(P, materials.at(material_of_tet[t])));
  }
  const auto faces = faces_of_one(r.tetrahedra, all_tets(r.tetrahedra.rows()));
  r.boundary_triangles.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) r.boundary_triangles(static_cast<Eigen::Index>(f), k) = faces[f][k];
  // Free Γ in increasing mesh index: the order of OutsideCompliance::interface.
  std::vector<int> free_interface;
  std::set_difference(split.interface_vertices.begin(), split.interface_vertices.end(),
                      split.fixed_region.begin(), split.fixed_region.end(),
                      std::back_inserter(free_interface));
  for (int v : free_interface) r.interface.push_back(local[v]);
  for (int v : split.fixed_region) r.fixed.push_back(local[v]);
  return r;
}

}  // namespace palpate
