#include "precompute_steps.hpp"

#include <fmt/format.h>
#include <malloc.h>

#include <algorithm>
#include <optional>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/file/hash.hpp"
#include "palpate/file/xdmf.hpp"
#include "palpate/offline/attachment.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "palpate/offline/plausibility.hpp"

namespace palpate::precompute {

// ---- phases and method reports ------------------------------------------------------

void PhaseTimer::begin(const std::string& name) {
  name_ = name;
  // glibc keeps freed heap pages (Gmsh's model, assembly triplets) resident;
  // handing them back makes the process's memory what the phase holds, which
  // is what a batch scheduler's memory limit counts.
  malloc_trim(0);
  reset_peak_rss();
  start_rss_ = current_rss_bytes();
  t0_ = std::chrono::steady_clock::now();
}

PhaseReport& PhaseTimer::end() {
  PhaseReport p;
  p.name = name_;
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  p.start_rss_bytes = start_rss_;
  p.peak_rss_bytes = peak_rss_bytes();
  peak_ = std::max(peak_, p.peak_rss_bytes);
  out_->push_back(p);
  return out_->back();
}

double dense_gflop_per_s(const ComplianceStats& s) {
  return s.dense_seconds > 0 ? s.dense_flops / s.dense_seconds / 1e9 : 0.0;
}

MethodReport method_report(const ComplianceStats& s) {
  const FactorInfo& f = s.factor;
  MethodReport r;
  r.ordering = f.ordering;
  r.nnz_L = f.nnz_L;
  r.supernodes = f.supernodes;
  r.bytes = f.bytes;
  r.analyze_seconds = f.analyze_seconds;
  r.factor_seconds = f.factor_seconds;
  r.factor_gflops = f.flops / 1e9;
  r.factor_gflop_per_s = f.factor_seconds > 0 ? f.flops / f.factor_seconds / 1e9 : 0.0;
  r.dense_seconds = s.dense_seconds;
  r.dense_gflops = s.dense_flops / 1e9;
  r.dense_gflop_per_s = dense_gflop_per_s(s);
  r.max_residual = s.max_residual;
  r.max_column_mismatch = s.max_column_mismatch;
  r.checked_columns = s.checked_columns;
  return r;
}

// ---- the problem ---------------------------------------------------------------------

namespace {

/// SHA-256 of what determines G: vertices, tetrahedra, materials, fixed
/// vertices (docs/compliance-file.md, "input_hash").
std::string input_hash(const TetMesh& mesh, const std::vector<MaterialRecord>& materials,
                       const Eigen::VectorXi& tet_material, const std::vector<int>& fixed,
                       const std::optional<CutRegionData>& region) {
  Sha256 h;
  // The version in which this definition of the hash was fixed, not the
  // file's: minor versions add datasets but hash the same problem the same
  // way, so a 1.1 file and a 1.0 file of one problem share their hash.
  h.update(fmt::format("{} {}.0\n", kComplianceFormatName, kComplianceFormatMajor));
  const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> X = mesh.vertices;
  const Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor> T = mesh.tetrahedra;
  h.update(fmt::format("vertices {}\n", X.rows()));
  h.update(X.data(), sizeof(double) * static_cast<size_t>(X.size()));
  h.update(fmt::format("tetrahedra {}\n", T.rows()));
  h.update(T.data(), sizeof(int) * static_cast<size_t>(T.size()));
  h.update(tet_material.data(), sizeof(int) * static_cast<size_t>(tet_material.size()));
  for (const auto& m : materials)
    h.update(fmt::format("material {:.17g} {:.17g}\n", m.young_modulus_pa, m.poisson_ratio));
  h.update(fmt::format("fixed {}\n", fixed.size()));
  h.update(fixed.data(), sizeof(int) * fixed.size());
  // With a region the mesh above is the outside; the region's own data (its
  // elements, density, damping) determine the file too. Without one, the
  // hash is what it was before regions existed.
  if (region) {
    h.update(fmt::format("cut_region {} density {:.17g} damping {:.17g}\n", region->spec,
                         region->density_kg_m3, region->damping_per_s));
    const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> RX = region->vertices_m;
    const Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor> RT = region->tetrahedra;
    h.update(RX.data(), sizeof(double) * static_cast<size_t>(RX.size()));
    h.update(RT.data(), sizeof(int) * static_cast<size_t>(RT.size()));
    h.update(region->element_stiffness_n_per_m.data(),
             sizeof(double) * static_cast<size_t>(region->element_stiffness_n_per_m.size()));
  }
  return h.hex_digest();
}

/// Per-tetrahedron material: the organ's (0), or its physical group's.
Eigen::VectorXi tetrahedron_materials(const TetMesh& mesh,
                                      const std::vector<GroupMaterial>& groups) {
  Eigen::VectorXi tet_material = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());
  for (size_t g = 0; g < groups.size(); ++g) {
    const auto& name = groups[g].group;
    int tag = 0;
    for (const auto& [t, n] : mesh.group_names)
      if (n == name || fmt::format("#{}", t) == name) tag = t;
    if (tag == 0) {
      std::string known;
      for (const auto& [t, n] : mesh.group_names) known += (known.empty() ? "" : ", ") + n;
      throw InputError(fmt::format(
          "{}: material group '{}' is not a physical volume of the mesh (its physical volumes: {})",
          mesh.source, name, known.empty() ? "none" : known));
    }
    for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
      if (mesh.tet_group[t] == tag) tet_material[t] = static_cast<int>(g + 1);
  }
  return tet_material;
}

}  // namespace

Problem read_problem(const PrecomputeJob& job, PrecomputeReport& report, PhaseTimer& phases,
                     const Say& say) {
  Problem p;
  // Materials first: a bad modulus is reported before any long work.
  std::vector<MaterialRecord> materials{{"organ", *job.young_modulus_pa, *job.poisson_ratio}};
  p.lame.push_back(lame_parameters(*job.young_modulus_pa, *job.poisson_ratio));
  for (const auto& g : job.group_materials) {
    try {
      p.lame.push_back(lame_parameters(g.young_modulus_pa, g.poisson_ratio));
    } catch (const InputError& e) {
      throw InputError(fmt::format("material of group '{}': {}", g.group, e.what()));
    }
    materials.push_back({g.group, g.young_modulus_pa, g.poisson_ratio});
  }
  for (const auto& m : materials) {
    const std::string what = m.name == "organ" ? "organ" : "material of group '" + m.name + "'";
    if (auto w = young_modulus_warning(m.young_modulus_pa, what)) say.warn(*w);
    if (auto w = poisson_ratio_warning(m.poisson_ratio, what)) say.warn(*w);
  }
  if (job.cut_region)
    if (auto w = density_warning(job.cut_region->density_kg_m3)) say.warn(*w);

  say.phase("read mesh");
  phases.begin("read mesh");
  const MeshReadOptions read_options{parse_length_unit(job.mesh_unit), job.fill_size};
  p.mesh = read_mesh_isolated(job.mesh_file, read_options);
  TetMesh& mesh = p.mesh;
  const MeshCheck check = validate_and_compact(mesh);
  if (!check.dropped_vertices.empty()) {
    std::string first;
    for (size_t i = 0; i < std::min<size_t>(5, check.dropped_vertices.size()); ++i)
      first += fmt::format("{}{}", i ? " " : "", check.dropped_vertices[i]);
    say.warn(fmt::format("{}: {} vertices belong to no tetrahedron and were dropped (first: {})",
                         mesh.source, check.dropped_vertices.size(), first));
  }
  const double diagonal = (check.bbox_max - check.bbox_min).norm();
  if (auto w = organ_size_warning(diagonal, job.mesh_unit, mesh.source)) say.warn(*w);
  Boundary boundary = extract_boundary(mesh);
  phases.end();

  p.tet_material = tetrahedron_materials(mesh, job.group_materials);
  p.fixed = select_fixed_vertices(mesh, job.attachment);
  check_attachment_stops_rigid_motion(mesh, p.fixed);
  if (job.cut_region) restrict_to_outside(*job.cut_region, p, boundary, report, say);
  p.dofs = make_dof_map(boundary.on_surface, p.fixed);
  if (job.cut_region) index_interface(p);
  p.m = p.dofs.surface_dofs();
  p.n = p.dofs.dofs();
  if (p.m == 0)
    throw InputError(
        fmt::format("{}: every surface vertex is fixed: nothing left to touch", mesh.source));

  MeshReport& r = report.mesh.emplace();
  r.file = job.mesh_file.string();
  r.unit = job.mesh_unit;
  r.vertices = mesh.vertices.rows();
  r.tetrahedra = mesh.tetrahedra.rows();
  r.dropped_vertices = static_cast<long>(check.dropped_vertices.size());
  r.surface_triangles = boundary.triangles.rows();
  r.surface_vertices = std::count(boundary.on_surface.begin(), boundary.on_surface.end(), true);
  r.fixed_vertices = static_cast<long>(p.fixed.size());
  r.compliance_vertices = static_cast<long>(p.dofs.compliance_vertices.size());
  r.bbox_min_m = {check.bbox_min.x(), check.bbox_min.y(), check.bbox_min.z()};
  r.bbox_max_m = {check.bbox_max.x(), check.bbox_max.y(), check.bbox_max.z()};
  r.min_tet_volume_m3 = check.min_volume_m3;
  report.dofs = DofReport{p.n, p.m};
  report.materials = materials;

  ComplianceModel& model = p.model;
  model.vertices_m = mesh.vertices;
  model.tetrahedra = mesh.tetrahedra;
  model.tet_material = p.tet_material;
  model.materials = materials;
  model.surface_triangles = boundary.triangles;
  model.fixed_vertices =
      Eigen::Map<const Eigen::VectorXi>(p.fixed.data(), static_cast<Eigen::Index>(p.fixed.size()));
  model.source_vertex_ids = mesh.source_ids;
  model.compliance_vertices = Eigen::Map<const Eigen::VectorXi>(
      p.dofs.compliance_vertices.data(),
      static_cast<Eigen::Index>(p.dofs.compliance_vertices.size()));
  model.precision = job.precision;
  model.producer = report.producer;
  model.created_utc = report.created_utc;
  model.input_hash = input_hash(mesh, materials, p.tet_material, p.fixed, model.cut_region);
  report.input_hash = model.input_hash;
  for (const auto& mat : materials)
    model.material_summary +=
        fmt::format("{}{}: E = {:.6g} Pa, nu = {:.6g}", model.material_summary.empty() ? "" : "; ",
                    mat.name, mat.young_modulus_pa, mat.poisson_ratio);
  return p;
}

void assemble_stiffness(Problem& p, PhaseTimer& phases, const Say& say) {
  say.phase("assemble K");
  phases.begin("assemble K");
  p.K = assemble_stiffness(p.mesh.vertices, p.mesh.tetrahedra, p.tet_material, p.lame, p.dofs);
  phases.end().nnz_upper = static_cast<long>(p.K.nonZeros());
}

int Problem::source_vertex(int k) const {
  return mesh.source_ids[dofs.compliance_vertices[static_cast<std::size_t>(k)]];
}

void throw_not_positive_definite(const Problem& p, int column) {
  const int v = p.dofs.vertex_of_dof(column);
  throw NumericalError(fmt::format(
      "{}: the stiffness matrix is not positive definite (Cholesky failed at vertex {}, axis {}): "
      "check that the attachment holds every part of the organ and that no element is degenerate",
      p.mesh.source, p.mesh.source_ids[v], "xyz"[column % 3]));
}

// ---- memory --------------------------------------------------------------------------

MemoryLimit memory_limit(double limit_bytes) {
  if (limit_bytes > 0) return {limit_bytes, "is the memory limit set"};
  return {available_memory_bytes(), "is available on this machine"};
}

void refuse_if_too_big(double need, const std::string& detail, const MemoryLimit& limit) {
  if (need > limit.bytes)
    throw ResourceError(fmt::format(
        "the job needs about {} ({}) but {} {}: use a coarser mesh (fewer surface vertices), or a "
        "machine with more memory",
        format_bytes(need), detail, format_bytes(limit.bytes), limit.name));
}

double solve_thread_bytes(int n, int m, int block, bool converted) {
  return (32.0 * n + (converted ? 16.0 : 8.0) * m) * block;
}

double streamed_memory_bytes(int n, int m, int block, int threads, double k_bytes,
                             double factor_bytes) {
  return 3 * k_bytes + factor_bytes +
         threads * solve_thread_bytes(n, m, block, /*converted=*/true) + 16.0 * m * block +
         8.0 * m * 40 + 48.0 * m;
}

double in_memory_bytes(Method method, int n, int m, int block, double k_bytes,
                       double solves_factor_bytes, double condensation_factor_bytes) {
  const double g_bytes = 8.0 * m * static_cast<double>(m);
  double need = 0;
  if (method != Method::kCondensation)
    need =
        std::max(need, g_bytes + solves_factor_bytes +
                           solve_thread_bytes(n, m, block, /*converted=*/false) * solve_threads());
  if (method != Method::kSolves) need = std::max(need, g_bytes + condensation_factor_bytes);
  return need + k_bytes;
}

// ---- the checks and the ending -------------------------------------------------------

void refuse_bad_residual(double residual, double mismatch) {
  if (!(residual <= kMaxResidual) || !(mismatch <= kMaxResidual))
    throw NumericalError(fmt::format(
        "the solution does not satisfy K u = e: residual {:.3g}, column mismatch {:.3g} (accepted: "
        "≤ {:.0e}); K is numerically singular: check that the attachment holds every part of the "
        "organ and that no region is degenerate; no file written",
        residual, mismatch, kMaxResidual));
}

void refuse_unsound(double residual, double mismatch, const DiagonalBlockSpectrum& spectrum,
                    const ComplianceModel& model) {
  refuse_bad_residual(residual, mismatch);
  if (!(spectrum.smallest > 0))
    throw NumericalError(fmt::format(
        "G has a diagonal block that is not positive definite (vertex {}, eigenvalue {:.3g} m/N); "
        "no file written",
        model.source_vertex_ids[model.compliance_vertices[spectrum.smallest_at]],
        spectrum.smallest));
}

void write_compliance(const std::filesystem::path& output, bool write_xdmf,
                      const DiagonalBlockSpectrum& spectrum, ComplianceModel& model,
                      PrecomputeReport& report, PhaseTimer& phases, const Say& say,
                      const WriteG& write_G) {
  // The softness map, from the float64 G (before any float32 storage rounding).
  model.softness_m_per_n = Eigen::VectorXd::Zero(model.vertices_m.rows());
  for (Eigen::Index a = 0; a < model.compliance_vertices.size(); ++a)
    model.softness_m_per_n[model.compliance_vertices[a]] = spectrum.largest[a];
  const auto sidecar = xdmf_sidecar_path(output);
  OutputReport& out = report.output.emplace();
  out.file = output.string();
  out.precision = to_string(model.precision);
  if (write_xdmf) out.xdmf = sidecar.string();
  model.report_json = to_json(report);

  say.phase("write file");
  phases.begin("write file");
  write_G(model, say.progress("write file"));
  // The sidecar refers to the file's datasets: only once the file is in place.
  if (write_xdmf) write_xdmf_sidecar(output, model);
  phases.end();
  std::error_code ec;
  if (!write_xdmf)
    for (const auto& old : {sidecar, xdmf_surface_sidecar_path(output)})
      if (std::filesystem::exists(old, ec))
        say.warn(
            fmt::format("{} is left from an earlier run and may not match the new {}: delete it, "
                        "or run without --no-xdmf to rewrite it",
                        old.string(), output.string()));
  report.output->bytes = std::filesystem::file_size(output);
  report.peak_rss_bytes = phases.peak();
}

}  // namespace palpate::precompute
