#include "palpate/offline/precompute_report.hpp"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "palpate/core/system_info.hpp"

namespace palpate {

using nlohmann::json;

const PhaseReport* PrecomputeReport::phase(std::string_view name) const {
  for (const auto& p : phases)
    if (p.name == name) return &p;
  return nullptr;
}

// ---- to JSON ----------------------------------------------------------------------

namespace {

template <typename T>
void put(json& j, const char* key, const std::optional<T>& value) {
  if (value) j[key] = *value;
}

json to_json_value(const PhaseReport& p) {
  json j = {{"name", p.name},
            {"seconds", p.seconds},
            {"start_rss_bytes", p.start_rss_bytes},
            {"peak_rss_bytes", p.peak_rss_bytes}};
  put(j, "nnz_upper", p.nnz_upper);
  put(j, "gflop_per_s", p.gflop_per_s);
  return j;
}

json to_json_value(const MeshReport& m) {
  return {{"file", m.file},
          {"unit", m.unit},
          {"vertices", m.vertices},
          {"tetrahedra", m.tetrahedra},
          {"dropped_vertices", m.dropped_vertices},
          {"surface_triangles", m.surface_triangles},
          {"surface_vertices", m.surface_vertices},
          {"fixed_vertices", m.fixed_vertices},
          {"compliance_vertices", m.compliance_vertices},
          {"bbox_min_m", m.bbox_min_m},
          {"bbox_max_m", m.bbox_max_m},
          {"min_tet_volume_m3", m.min_tet_volume_m3}};
}

json to_json_value(const MemoryReport& m) {
  json j = json::object();
  put(j, "G_bytes", m.G_bytes);
  put(j, "estimate_bytes", m.estimate_bytes);
  put(j, "limit_bytes", m.limit_bytes);
  put(j, "streamed", m.streamed);
  put(j, "G_file_bytes", m.G_file_bytes);
  put(j, "merge_band_rows", m.merge_band_rows);
  return j;
}

json to_json_value(const MethodReport& m) {
  return {{"ordering", m.ordering},
          {"nnz_L", m.nnz_L},
          {"supernodes", m.supernodes},
          {"bytes", m.bytes},
          {"analyze_seconds", m.analyze_seconds},
          {"factor_seconds", m.factor_seconds},
          {"factor_gflops", m.factor_gflops},
          {"factor_gflop_per_s", m.factor_gflop_per_s},
          {"dense_seconds", m.dense_seconds},
          {"dense_gflops", m.dense_gflops},
          {"dense_gflop_per_s", m.dense_gflop_per_s},
          {"max_residual", m.max_residual},
          {"max_column_mismatch", m.max_column_mismatch},
          {"checked_columns", m.checked_columns}};
}

json to_json_value(const ChecksReport& c) {
  json j = {{"max_residual", c.max_residual}, {"max_column_mismatch", c.max_column_mismatch}};
  put(j, "symmetry_error", c.symmetry_error);
  put(j, "symmetry_error_sampled_columns", c.symmetry_error_sampled_columns);
  put(j, "min_diagonal_block_eigenvalue_m_per_n", c.min_diagonal_block_eigenvalue_m_per_n);
  put(j, "min_diagonal_block_vertex", c.min_diagonal_block_vertex);
  put(j, "checked_columns", c.checked_columns);
  put(j, "max_relative_difference", c.max_relative_difference);
  put(j, "tolerance", c.tolerance);
  return j;
}

json to_json_value(const PrecomputeReport& r) {
  json j = {{"producer", r.producer},
            {"created_utc", r.created_utc},
            {"blas", r.blas},
            {"method", r.method},
            {"phases", json::array()}};
  for (const auto& p : r.phases) j["phases"].push_back(to_json_value(p));
  if (r.mesh) j["mesh"] = to_json_value(*r.mesh);
  if (r.cut_region) {
    const CutRegionReport& c = *r.cut_region;
    j["cut_region"] = {{"spec", c.spec},
                       {"tetrahedra", c.tetrahedra},
                       {"organ_tetrahedra", c.organ_tetrahedra},
                       {"vertices", c.vertices},
                       {"interface_vertices", c.interface_vertices},
                       {"fixed_vertices", c.fixed_vertices},
                       {"density_kg_m3", c.density_kg_m3},
                       {"damping_per_s", c.damping_per_s}};
  }
  if (r.dofs) j["dofs"] = {{"total", r.dofs->total}, {"surface", r.dofs->surface}};
  if (r.materials) {
    j["materials"] = json::array();
    for (const auto& m : *r.materials)
      j["materials"].push_back({{"name", m.name},
                                {"young_modulus_pa", m.young_modulus_pa},
                                {"poisson_ratio", m.poisson_ratio}});
  }
  put(j, "input_hash", r.input_hash);
  if (r.memory) j["memory"] = to_json_value(*r.memory);
  if (!r.methods.empty()) {
    j["methods"] = json::object();
    for (const auto& [name, m] : r.methods) j["methods"][name] = to_json_value(m);
  }
  if (r.columns) {
    const auto& c = *r.columns;
    j["columns"] = {{"begin", c.begin},   {"end", c.end},
                    {"total", c.total},   {"block_columns", c.block_columns},
                    {"blocks", c.blocks}, {"resumed_blocks", c.resumed_blocks}};
    put(j["columns"], "columns_per_second", c.columns_per_second);
  }
  if (r.checks) j["checks"] = to_json_value(*r.checks);
  if (r.output) {
    const auto& o = *r.output;
    j["output"] = {{"file", o.file},
                   {"precision", o.precision},
                   {"xdmf", o.xdmf ? json(*o.xdmf) : json(nullptr)}};
    put(j["output"], "bytes", o.bytes);
    j["output"]["reused"] = o.reused;
  }
  put(j, "peak_rss_bytes", r.peak_rss_bytes);
  if (r.shards) {
    j["shards"] = json::array();
    for (const auto& s : *r.shards) {
      json e = {{"file", s.file}, {"columns", {s.columns_begin, s.columns_end}}, {"blas", s.blas}};
      put(e, "columns_per_second", s.columns_per_second);
      put(e, "peak_rss_bytes", s.peak_rss_bytes);
      j["shards"].push_back(e);
    }
  }
  return j;
}

// ---- from JSON --------------------------------------------------------------------

/// The value of @p key in @p j when it is there with a type T converts from.
template <typename T>
std::optional<T> get(const json& j, const char* key) {
  if (!j.is_object() || !j.contains(key)) return std::nullopt;
  const json& v = j[key];
  if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) return std::nullopt;
  } else if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) return std::nullopt;
  } else if constexpr (std::is_arithmetic_v<T>) {
    if (!v.is_number()) return std::nullopt;
  } else {
    if (!v.is_array()) return std::nullopt;
  }
  try {
    return v.get<T>();
  } catch (const json::exception&) {
    return std::nullopt;
  }
}

template <typename T>
void take(const json& j, const char* key, T& out) {
  if (auto v = get<T>(j, key)) out = std::move(*v);
}

PrecomputeReport from_json_value(const json& j) {
  PrecomputeReport r;
  take(j, "producer", r.producer);
  take(j, "created_utc", r.created_utc);
  take(j, "blas", r.blas);
  take(j, "method", r.method);
  if (j.contains("phases") && j["phases"].is_array())
    for (const json& p : j["phases"]) {
      PhaseReport phase;
      take(p, "name", phase.name);
      take(p, "seconds", phase.seconds);
      take(p, "start_rss_bytes", phase.start_rss_bytes);
      take(p, "peak_rss_bytes", phase.peak_rss_bytes);
      phase.nnz_upper = get<long>(p, "nnz_upper");
      phase.gflop_per_s = get<double>(p, "gflop_per_s");
      r.phases.push_back(phase);
    }
  if (j.contains("mesh") && j["mesh"].is_object()) {
    const json& m = j["mesh"];
    MeshReport& mesh = r.mesh.emplace();
    take(m, "file", mesh.file);
    take(m, "unit", mesh.unit);
    take(m, "vertices", mesh.vertices);
    take(m, "tetrahedra", mesh.tetrahedra);
    take(m, "dropped_vertices", mesh.dropped_vertices);
    take(m, "surface_triangles", mesh.surface_triangles);
    take(m, "surface_vertices", mesh.surface_vertices);
    take(m, "fixed_vertices", mesh.fixed_vertices);
    take(m, "compliance_vertices", mesh.compliance_vertices);
    take(m, "bbox_min_m", mesh.bbox_min_m);
    take(m, "bbox_max_m", mesh.bbox_max_m);
    take(m, "min_tet_volume_m3", mesh.min_tet_volume_m3);
  }
  if (j.contains("dofs") && j["dofs"].is_object()) {
    DofReport& d = r.dofs.emplace();
    take(j["dofs"], "total", d.total);
    take(j["dofs"], "surface", d.surface);
  }
  if (j.contains("materials") && j["materials"].is_array()) {
    auto& list = r.materials.emplace();
    for (const json& m : j["materials"]) {
      MaterialRecord record;
      take(m, "name", record.name);
      take(m, "young_modulus_pa", record.young_modulus_pa);
      take(m, "poisson_ratio", record.poisson_ratio);
      list.push_back(record);
    }
  }
  r.input_hash = get<std::string>(j, "input_hash");
  if (j.contains("memory") && j["memory"].is_object()) {
    const json& m = j["memory"];
    MemoryReport& memory = r.memory.emplace();
    memory.G_bytes = get<double>(m, "G_bytes");
    memory.estimate_bytes = get<double>(m, "estimate_bytes");
    memory.limit_bytes = get<double>(m, "limit_bytes");
    memory.streamed = get<bool>(m, "streamed");
    memory.G_file_bytes = get<double>(m, "G_file_bytes");
    memory.merge_band_rows = get<long>(m, "merge_band_rows");
  }
  if (j.contains("methods") && j["methods"].is_object())
    for (const auto& [name, m] : j["methods"].items()) {
      MethodReport& method = r.methods[name];
      take(m, "ordering", method.ordering);
      take(m, "nnz_L", method.nnz_L);
      take(m, "supernodes", method.supernodes);
      take(m, "bytes", method.bytes);
      take(m, "analyze_seconds", method.analyze_seconds);
      take(m, "factor_seconds", method.factor_seconds);
      take(m, "factor_gflops", method.factor_gflops);
      take(m, "factor_gflop_per_s", method.factor_gflop_per_s);
      take(m, "dense_seconds", method.dense_seconds);
      take(m, "dense_gflops", method.dense_gflops);
      take(m, "dense_gflop_per_s", method.dense_gflop_per_s);
      take(m, "max_residual", method.max_residual);
      take(m, "max_column_mismatch", method.max_column_mismatch);
      take(m, "checked_columns", method.checked_columns);
    }
  if (j.contains("columns") && j["columns"].is_object()) {
    const json& c = j["columns"];
    ColumnsReport& columns = r.columns.emplace();
    take(c, "begin", columns.begin);
    take(c, "end", columns.end);
    take(c, "total", columns.total);
    take(c, "block_columns", columns.block_columns);
    take(c, "blocks", columns.blocks);
    take(c, "resumed_blocks", columns.resumed_blocks);
    columns.columns_per_second = get<double>(c, "columns_per_second");
  }
  if (j.contains("checks") && j["checks"].is_object()) {
    const json& c = j["checks"];
    ChecksReport& checks = r.checks.emplace();
    take(c, "max_residual", checks.max_residual);
    take(c, "max_column_mismatch", checks.max_column_mismatch);
    checks.symmetry_error = get<double>(c, "symmetry_error");
    checks.symmetry_error_sampled_columns = get<long>(c, "symmetry_error_sampled_columns");
    checks.min_diagonal_block_eigenvalue_m_per_n =
        get<double>(c, "min_diagonal_block_eigenvalue_m_per_n");
    checks.min_diagonal_block_vertex = get<long>(c, "min_diagonal_block_vertex");
    checks.checked_columns = get<std::vector<int>>(c, "checked_columns");
    checks.max_relative_difference = get<double>(c, "max_relative_difference");
    checks.tolerance = get<double>(c, "tolerance");
  }
  if (j.contains("output") && j["output"].is_object()) {
    const json& o = j["output"];
    OutputReport& output = r.output.emplace();
    take(o, "file", output.file);
    take(o, "precision", output.precision);
    output.xdmf = get<std::string>(o, "xdmf");
    output.bytes = get<std::uint64_t>(o, "bytes");
    output.reused = get<bool>(o, "reused").value_or(false);
  }
  r.peak_rss_bytes = get<double>(j, "peak_rss_bytes");
  if (j.contains("shards") && j["shards"].is_array()) {
    auto& list = r.shards.emplace();
    for (const json& s : j["shards"]) {
      ShardReport shard;
      take(s, "file", shard.file);
      if (const auto columns = get<std::vector<long>>(s, "columns");
          columns && columns->size() == 2) {
        shard.columns_begin = (*columns)[0];
        shard.columns_end = (*columns)[1];
      }
      take(s, "blas", shard.blas);
      shard.columns_per_second = get<double>(s, "columns_per_second");
      shard.peak_rss_bytes = get<double>(s, "peak_rss_bytes");
      list.push_back(shard);
    }
  }
  return r;
}

}  // namespace

std::string to_json(const PrecomputeReport& report, int indent) {
  return to_json_value(report).dump(indent);
}

PrecomputeReport report_from_json(std::string_view text) {
  try {
    return from_json_value(json::parse(text));
  } catch (const json::exception&) {
    return {};
  }
}

// ---- for a terminal ---------------------------------------------------------------

std::string format_report(const PrecomputeReport& r) {
  std::string s = fmt::format("palpate-precompute report ({})\n", r.producer);
  const bool reused = r.output && r.output->reused;
  if (!r.mesh || !r.dofs || (!r.checks && !reused)) return s;
  const MeshReport& mesh = *r.mesh;
  s += fmt::format("  mesh       {}: {} vertices, {} tetrahedra, {} surface triangles\n", mesh.file,
                   mesh.vertices, mesh.tetrahedra, mesh.surface_triangles);
  s += fmt::format("             {} surface vertices, {} fixed, {} in the compliance; {} DOFs\n",
                   mesh.surface_vertices, mesh.fixed_vertices, mesh.compliance_vertices,
                   r.dofs->total);
  if (r.cut_region) {
    const CutRegionReport& c = *r.cut_region;
    s += fmt::format(
        "  cut region {}: {} of the organ's {} tetrahedra, {} vertices, {} free on Γ, {} fixed; "
        "{:.4g} kg/m³, γ = {:.4g} /s (the mesh above is the rest of the organ)\n",
        c.spec, c.tetrahedra, c.organ_tetrahedra, c.vertices, c.interface_vertices,
        c.fixed_vertices, c.density_kg_m3, c.damping_per_s);
  }
  if (r.materials)
    for (const auto& m : *r.materials)
      s += fmt::format("  material   {}: E = {:.4g} Pa, nu = {}\n", m.name, m.young_modulus_pa,
                       m.poisson_ratio);
  if (reused)  // nothing computed: the problem read, and the file kept
    return s + fmt::format(
                   "  output     {} ({}, {}), input hash {}; kept (--reuse): it already "
                   "holds this problem\n",
                   r.output->file, r.output->precision,
                   format_bytes(static_cast<double>(r.output->bytes.value_or(0))),
                   r.input_hash.value_or("").substr(0, 23));
  s += fmt::format("  BLAS       {}\n", r.blas);
  s += "  phases     time        peak RSS    rate\n";
  for (const auto& p : r.phases) {
    s += fmt::format("    {:<14} {:>8.3f} s  {:>10}", p.name, p.seconds,
                     format_bytes(p.peak_rss_bytes));
    if (p.gflop_per_s) s += fmt::format("  {:.1f} GFLOP/s (dense part)", *p.gflop_per_s);
    s += "\n";
  }
  for (const auto& [name, m] : r.methods)
    s += fmt::format(
        "  {:<12} factor: {} ordering, nnz(L) = {:.3g}, {:.2f} s ({:.1f} GFLOP/s); dense: {:.2f} "
        "s ({:.1f} GFLOP/s)\n",
        name, m.ordering, m.nnz_L, m.factor_seconds, m.factor_gflop_per_s, m.dense_seconds,
        m.dense_gflop_per_s);
  const ChecksReport& c = *r.checks;
  s += fmt::format(
      "  checks     residual ‖Ku−e‖/‖e‖ ≤ {:.2e} on sampled columns; column mismatch ≤ {:.2e}\n",
      c.max_residual, c.max_column_mismatch);
  // A shard has no whole diagonal block, nor G to compare with its transpose.
  if (c.symmetry_error)
    s += fmt::format(
        "             symmetry error {:.2e}{}; smallest eigenvalue of a diagonal block {:.4g} "
        "m/N\n",
        *c.symmetry_error,
        c.symmetry_error_sampled_columns
            ? fmt::format(" ({} sampled columns)", *c.symmetry_error_sampled_columns)
            : std::string(),
        c.min_diagonal_block_eigenvalue_m_per_n.value_or(0.0));
  if (r.columns) {
    const auto& k = *r.columns;
    s += fmt::format(
        "  columns    {}:{} of {}, {} blocks of {} ({} resumed from the checkpoint){}\n", k.begin,
        k.end, k.total, k.blocks, k.block_columns, k.resumed_blocks,
        k.columns_per_second ? fmt::format(", {:.0f} columns/s", *k.columns_per_second)
                             : std::string());
  }
  if (r.shards)
    for (const auto& sh : *r.shards)
      s += fmt::format("  shard      {}: columns {}:{}\n", sh.file, sh.columns_begin,
                       sh.columns_end);
  if (c.max_relative_difference)
    s += fmt::format(
        "             solves vs condensation: largest relative difference {:.2e} (tolerance "
        "{:.0e})\n",
        *c.max_relative_difference, c.tolerance.value_or(0.0));
  if (r.output)
    s += fmt::format("  output     {} ({}, {}), input hash {}\n", r.output->file,
                     r.output->precision,
                     format_bytes(static_cast<double>(r.output->bytes.value_or(0))),
                     r.input_hash.value_or("").substr(0, 23));
  if (r.peak_rss_bytes)
    s += fmt::format("  peak RSS   {} (G is {})\n", format_bytes(*r.peak_rss_bytes),
                     format_bytes(r.memory ? r.memory->G_bytes.value_or(0.0) : 0.0));
  return s;
}

}  // namespace palpate
