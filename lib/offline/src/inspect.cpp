#include "palpate/offline/inspect.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/offline/dense.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh.hpp"
#include "palpate/offline/sparse_cholesky.hpp"
#include "precompute_steps.hpp"

namespace palpate {

namespace {

/// The six dihedral angles of a tetrahedron (rad), from its face normals:
/// the angle along the edge shared by faces a and b is π minus the angle
/// between their outward normals.
std::array<double, 6> dihedral_angles(const Matrix43d& p) {
  // Outward normal of the face opposite vertex i, for V > 0.
  std::array<Eigen::Vector3d, 4> n;
  const int faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d a = p.row(faces[i][0]), b = p.row(faces[i][1]), c = p.row(faces[i][2]);
    n[static_cast<std::size_t>(i)] = (b - a).cross(c - a).normalized();
  }
  std::array<double, 6> angles{};
  int k = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j)
      angles[static_cast<std::size_t>(k++)] =
          M_PI -
          std::acos(std::clamp(n[static_cast<std::size_t>(i)].dot(n[static_cast<std::size_t>(j)]),
                               -1.0, 1.0));
  return angles;
}

/// This machine's dgemm rate, GFLOP/s: the scale of the time estimates.
double measure_dgemm() {
  const int n = 512;
  const Eigen::MatrixXd A = Eigen::MatrixXd::Random(n, n), B = Eigen::MatrixXd::Random(n, n);
  Eigen::MatrixXd C(n, n);
  blas_gemm(A, B, C);  // warm-up
  double best = INFINITY;
  for (int r = 0; r < 3; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    blas_gemm(A, B, C);
    best = std::min(best,
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return 2.0 * n * n * n / best / 1e9;
}

// Shares of dgemm's rate the phases reach (docs/benchmarks-history.md, "palpate-precompute":
// the factor about 30 %, the blocked solves 12 to 45 %, dpotri 60 to 110 %),
// and a write rate: enough for an estimate to the factor of two.
constexpr double kFactorShare = 0.3, kSolvesShare = 0.15, kInverseShare = 0.6;
constexpr double kWriteBytesPerSecond = 500e6;

void estimate_costs(MeshInspection& r, TetMesh& mesh, const Boundary& boundary) {
  const DofMap dofs = make_dof_map(boundary.on_surface, {});
  const int m = dofs.surface_dofs(), n = dofs.dofs();
  // K's sparsity, which is all the estimates need, does not depend on the material.
  const SparseMatrixd K = assemble_stiffness(mesh.vertices, mesh.tetrahedra,
                                             Eigen::VectorXi::Zero(mesh.tetrahedra.rows()),
                                             {lame_parameters(1e4, 0.3)}, dofs);
  const auto solves = SparseCholesky::estimate(K);
  const auto condensation = SparseCholesky::estimate(K, condensation_ordering(K, m));
  const double k_bytes = 12.0 * static_cast<double>(K.nonZeros());
  const double rate = r.dgemm_gflop_per_s = measure_dgemm();
  const double flops_per_s = rate * 1e9;
  const double g = r.G_bytes;
  const int block = std::min(64, m);
  const double write_s = g / kWriteBytesPerSecond;
  const double solves_s = solves.flops / (kFactorShare * flops_per_s) +
                          4.0 * solves.nnz_L * m / (kSolvesShare * flops_per_s);
  const double condensation_s =
      condensation.flops / (kFactorShare * flops_per_s) +
      2.0 / 3.0 * m * static_cast<double>(m) * m / (kInverseShare * flops_per_s);
  r.methods.push_back({"condensation",
                       precompute::in_memory_bytes(Method::kCondensation, n, m, block, k_bytes, 0,
                                                   condensation.bytes),
                       g, condensation_s + write_s});
  r.methods.push_back(
      {"solves (streamed)",
       precompute::streamed_memory_bytes(n, m, block, solve_threads(), k_bytes, solves.bytes), g,
       solves_s + 2 * write_s});
  r.methods.push_back({"both",
                       precompute::in_memory_bytes(Method::kBoth, n, m, block, k_bytes,
                                                   solves.bytes, condensation.bytes),
                       g, condensation_s + solves_s + write_s});
}

}  // namespace

MeshInspection inspect_mesh(const std::filesystem::path& file, const MeshReadOptions& options) {
  MeshInspection r;
  r.file = file.string();
  r.unit = options.unit.name;
  TetMesh mesh = read_mesh_isolated(file, options);
  // Gmsh numbers every node of the file; a reader that does not say counts the vertices.
  r.file_nodes = static_cast<long>(std::max(mesh.source_vertex_count, mesh.vertices.rows()));
  r.tetrahedra = mesh.tetrahedra.rows();
  if (mesh.vertices.rows() > 0) {
    const Eigen::MatrixX3d in_file = mesh.vertices / options.unit.to_metres;
    for (int d = 0; d < 3; ++d) {
      r.bbox_min[static_cast<std::size_t>(d)] = in_file.col(d).minCoeff();
      r.bbox_max[static_cast<std::size_t>(d)] = in_file.col(d).maxCoeff();
    }
    r.diagonal = (in_file.colwise().maxCoeff() - in_file.colwise().minCoeff()).norm();
  }
  r.readings = unit_readings(r.diagonal);
  r.likely_unit = likely_unit(r.diagonal);

  for (const auto& [tag, name] : mesh.group_names) {
    MeshInspection::Group g{tag, name, 0, 0};
    if (auto it = mesh.group_vertices.find(name); it != mesh.group_vertices.end())
      g.vertices = static_cast<long>(it->second.size());
    g.tetrahedra = (mesh.tet_group.array() == tag).count();
    r.groups.push_back(g);
  }

  // Quality, before any check refuses the mesh.
  r.min_volume_m3 = INFINITY;
  r.max_volume_m3 = -INFINITY;
  r.min_dihedral_deg = 180;
  const double radians_to_degrees = 180 / M_PI;
  const Eigen::Index vertex_count = mesh.vertices.rows();
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    Matrix43d p;
    bool in_range = true;
    for (int i = 0; i < 4; ++i) {
      const int v = mesh.tetrahedra(t, i);
      if (v < 0 || v >= vertex_count)
        in_range = false;
      else
        p.row(i) = mesh.vertices.row(v);
    }
    if (!in_range) continue;  // validate_and_compact names it below
    const double volume = signed_volume(p);
    r.min_volume_m3 = std::min(r.min_volume_m3, volume);
    r.max_volume_m3 = std::max(r.max_volume_m3, volume);
    if (!(volume > 0)) {
      ++(volume < 0 ? r.inverted : r.degenerate);
      if (r.first_bad < 0) r.first_bad = t;
      continue;
    }
    const auto angles = dihedral_angles(p);
    const double smallest = *std::min_element(angles.begin(), angles.end()) * radians_to_degrees;
    const double largest = *std::max_element(angles.begin(), angles.end()) * radians_to_degrees;
    if (smallest < r.min_dihedral_deg) {
      r.min_dihedral_deg = smallest;
      r.min_dihedral_tetrahedron = t;
    }
    r.max_dihedral_deg = std::max(r.max_dihedral_deg, largest);
    if (smallest < 5) ++r.sliver_count;
  }

  try {
    const MeshCheck check = validate_and_compact(mesh);
    r.unreferenced_vertices = static_cast<long>(check.dropped_vertices.size());
    r.vertices = mesh.vertices.rows();
    const Boundary boundary = extract_boundary(mesh);
    r.surface_triangles = boundary.triangles.rows();
    r.surface_vertices = std::count(boundary.on_surface.begin(), boundary.on_surface.end(), true);
    const double m = 3.0 * static_cast<double>(r.surface_vertices);
    r.G_bytes = 8 * m * m;
    estimate_costs(r, mesh, boundary);
    r.valid = true;
  } catch (const InputError& e) {
    r.vertices = mesh.vertices.rows();
    r.invalid_reason = e.what();
  }
  return r;
}

std::string format_inspection(const MeshInspection& r) {
  std::string s = fmt::format("palpate-precompute inspect: {}\n", r.file);
  s += fmt::format("  counts      {} nodes in the file, {} tetrahedra", r.file_nodes, r.tetrahedra);
  if (r.valid)
    s += fmt::format(
        "; {} vertices used ({} unreferenced), {} surface triangles, {} surface "
        "vertices",
        r.vertices, r.unreferenced_vertices, r.surface_triangles, r.surface_vertices);
  s += "\n";
  s += fmt::format(
      "  box         in the file's numbers: x {:.4g} to {:.4g}, y {:.4g} to {:.4g}, "
      "z {:.4g} to {:.4g}; diagonal {:.4g}\n",
      r.bbox_min[0], r.bbox_max[0], r.bbox_min[1], r.bbox_max[1], r.bbox_min[2], r.bbox_max[2],
      r.diagonal);
  s += "  unit        ";
  for (const auto& u : r.readings)
    s += fmt::format("{}as {}: {:.3g} m across{}{}", &u == &r.readings.front() ? "" : "; ", u.unit,
                     u.diagonal_m, u.plausible ? "" : " (not an organ's size)",
                     u.unit == r.likely_unit ? " ← likely" : "");
  s += fmt::format("\n              (an organ is {:g} to {:g} m across: use --mesh-unit {})\n",
                   kPlausibleOrganMinM, kPlausibleOrganMaxM, r.likely_unit);
  if (r.groups.empty()) {
    s += "  groups      none: attach with boxes, spheres, half-spaces or an id file\n";
  } else {
    for (const auto& g : r.groups)
      s += fmt::format(
          "  group       {} \"{}\": {} vertices{}\n", g.tag, g.name, g.vertices,
          g.tetrahedra > 0 ? fmt::format(", {} tetrahedra (a material region)", g.tetrahedra) : "");
  }
  if (r.inverted + r.degenerate > 0)
    s += fmt::format(
        "  quality     {} inverted and {} degenerate tetrahedra (the first: {}): the "
        "mesh must be repaired or exported again with positive orientation\n",
        r.inverted, r.degenerate, r.first_bad);
  else if (r.min_dihedral_tetrahedron >= 0)
    s += fmt::format(
        "  quality     tetrahedron volumes {:.3g} to {:.3g} m³ as read with --mesh-unit {}; "
        "dihedral "
        "angles {:.1f}° to {:.1f}° (smallest in tetrahedron {}); {} tetrahedra with "
        "an angle under 5°\n",
        r.min_volume_m3, r.max_volume_m3, r.unit, r.min_dihedral_deg, r.max_dihedral_deg,
        r.min_dihedral_tetrahedron, r.sliver_count);
  if (!r.valid) {
    s += fmt::format("  refused     {}\n", r.invalid_reason);
    return s;
  }
  s += fmt::format(
      "  G           {0} × {0}: {1} in float64 ({2} in float32), if no surface vertex is fixed\n",
      3 * r.surface_vertices, format_bytes(r.G_bytes), format_bytes(r.G_bytes / 2));
  for (const auto& m : r.methods)
    s += fmt::format("  method      {:<18} about {} of memory, {} file, {:.0f} s on this machine\n",
                     m.method, format_bytes(m.memory_bytes), format_bytes(m.disk_bytes),
                     std::max(1.0, std::round(m.seconds)));
  s += fmt::format(
      "              (times scaled from this machine's dgemm, {:.0f} GFLOP/s; memory "
      "available now {})\n",
      r.dgemm_gflop_per_s, format_bytes(available_memory_bytes()));
  return s;
}

std::string inspection_json(const MeshInspection& r) {
  using nlohmann::json;
  json j = {{"file", r.file},
            {"unit", r.unit},
            {"file_nodes", r.file_nodes},
            {"tetrahedra", r.tetrahedra},
            {"bbox_min", r.bbox_min},
            {"bbox_max", r.bbox_max},
            {"diagonal", r.diagonal},
            {"likely_unit", r.likely_unit},
            {"units", json::array()},
            {"groups", json::array()},
            {"quality",
             {{"inverted", r.inverted},
              {"degenerate", r.degenerate},
              {"min_volume_m3", r.min_volume_m3},
              {"max_volume_m3", r.max_volume_m3},
              {"min_dihedral_deg", r.min_dihedral_deg},
              {"max_dihedral_deg", r.max_dihedral_deg},
              {"tetrahedra_under_5_deg", r.sliver_count}}},
            {"valid", r.valid}};
  for (const auto& u : r.readings)
    j["units"].push_back(
        {{"unit", u.unit}, {"diagonal_m", u.diagonal_m}, {"plausible", u.plausible}});
  for (const auto& g : r.groups)
    j["groups"].push_back(
        {{"tag", g.tag}, {"name", g.name}, {"vertices", g.vertices}, {"tetrahedra", g.tetrahedra}});
  if (!r.valid) {
    j["invalid_reason"] = r.invalid_reason;
  } else {
    j["vertices"] = r.vertices;
    j["unreferenced_vertices"] = r.unreferenced_vertices;
    j["surface_triangles"] = r.surface_triangles;
    j["surface_vertices"] = r.surface_vertices;
    j["G_bytes"] = r.G_bytes;
    j["dgemm_gflop_per_s"] = r.dgemm_gflop_per_s;
    j["methods"] = json::array();
    for (const auto& m : r.methods)
      j["methods"].push_back({{"method", m.method},
                              {"memory_bytes", m.memory_bytes},
                              {"disk_bytes", m.disk_bytes},
                              {"seconds", m.seconds}});
  }
  return j.dump(2);
}

}  // namespace palpate
