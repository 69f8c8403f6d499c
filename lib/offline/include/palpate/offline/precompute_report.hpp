#pragma once
/// @file
/// What a precompute run reports: the inputs it read, what each phase took,
/// what each method did, the checks, the file written
/// (docs/compliance-file.md, "The report"). A typed value inside the
/// program; JSON only where it is printed (`--json`) or stored in the file
/// (`report_json`).

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "palpate/file/compliance_file.hpp"

namespace palpate {

/// One phase: "read mesh", "assemble K", "condensation", "solves", "checks",
/// "check shards", "write file".
struct PhaseReport {
  std::string name;
  double seconds = 0;
  double start_rss_bytes = 0;     ///< resident memory as the phase starts (freed heap handed back)
  double peak_rss_bytes = 0;      ///< peak resident memory during the phase
  std::optional<long> nnz_upper;  ///< "assemble K": stored nonzeros of K's upper triangle
  std::optional<double> gflop_per_s;  ///< method phases: rate of their dense part
};

struct MeshReport {
  std::string file, unit;
  long vertices = 0;  ///< after dropping unreferenced ones
  long tetrahedra = 0;
  long dropped_vertices = 0;
  long surface_triangles = 0;
  long surface_vertices = 0;     ///< fixed ones included
  long fixed_vertices = 0;       ///< surface and interior
  long compliance_vertices = 0;  ///< n
  std::array<double, 3> bbox_min_m{}, bbox_max_m{};
  double min_tet_volume_m3 = 0;
};

/// A job's cut region (docs/precompute.md, "A cuttable region"): the mesh
/// report is then the outside's.
struct CutRegionReport {
  std::string spec;  ///< RegionSpec::describe()
  long tetrahedra = 0;
  long organ_tetrahedra = 0;    ///< the whole organ's
  long vertices = 0;            ///< the region's
  long interface_vertices = 0;  ///< free vertices of Γ
  long fixed_vertices = 0;      ///< region vertices the attachment holds
  double density_kg_m3 = 0;
  double damping_per_s = 0;
};

struct DofReport {
  long total = 0;    ///< free DOFs
  long surface = 0;  ///< m = 3n
};

/// The memory estimate the run was checked against, and what it used.
struct MemoryReport {
  std::optional<double> G_bytes;         ///< 8 m² (float64 G)
  std::optional<double> estimate_bytes;  ///< the whole job's estimate
  std::optional<double> limit_bytes;     ///< the limit it was checked against
  std::optional<bool> streamed;          ///< G streamed to disk (solves, shards)
  std::optional<double> G_file_bytes;    ///< streamed: G's bytes in the file
  std::optional<long> merge_band_rows;   ///< rows of G per band when writing from shards
};

/// One method's factorization, dense work and sampled checks.
struct MethodReport {
  std::string ordering;  ///< CHOLMOD's: amd, metis, … (solves); given (condensation)
  double nnz_L = 0;
  long supernodes = 0;
  double bytes = 0;  ///< memory of the factor
  double analyze_seconds = 0, factor_seconds = 0, factor_gflops = 0, factor_gflop_per_s = 0;
  double dense_seconds = 0, dense_gflops = 0, dense_gflop_per_s = 0;
  double max_residual = 0, max_column_mismatch = 0;
  std::vector<int> checked_columns;
};

/// The columns of G a streamed run or a shard computed.
struct ColumnsReport {
  long begin = 0, end = 0, total = 0, block_columns = 0, blocks = 0, resumed_blocks = 0;
  std::optional<double> columns_per_second;
};

/// The checks that decide whether a file is written (docs/model/compliance.md,
/// "Checks before a file is written").
struct ChecksReport {
  double max_residual = 0;         ///< max ‖K u − e_j‖ over sampled columns, ‖e_j‖ = 1
  double max_column_mismatch = 0;  ///< max ‖u_S − G(:, j)‖ / ‖G(:, j)‖
  std::optional<double> symmetry_error;                ///< max|G − Gᵀ| / max|G|
  std::optional<long> symmetry_error_sampled_columns;  ///< when sampled (streamed)
  std::optional<double> min_diagonal_block_eigenvalue_m_per_n;
  std::optional<long> min_diagonal_block_vertex;    ///< source vertex index
  std::optional<std::vector<int>> checked_columns;  ///< streamed: the sampled columns
  std::optional<double> max_relative_difference;    ///< `both`: solves vs condensation
  std::optional<double> tolerance;                  ///< `both`: the accepted difference
};

struct OutputReport {
  std::string file;
  std::string precision;               ///< "float64", "float32"
  std::optional<std::string> xdmf;     ///< the sidecar's path; none with --no-xdmf (null in JSON)
  std::optional<std::uint64_t> bytes;  ///< file size, once written
  bool reused = false;                 ///< --reuse kept the file there, which holds this problem
};

/// A shard merged into the file.
struct ShardReport {
  std::string file;
  long columns_begin = 0, columns_end = 0;
  std::string blas;
  std::optional<double> columns_per_second;
  std::optional<double> peak_rss_bytes;
};

struct PrecomputeReport {
  std::string producer;     ///< "palpate-precompute 0.1.0"
  std::string created_utc;  ///< ISO 8601
  std::string blas;         ///< the BLAS loaded, its configuration and kernels
  std::string method;       ///< "solves", "condensation", "both"
  std::vector<PhaseReport> phases;
  std::optional<MeshReport> mesh;
  std::optional<CutRegionReport> cut_region;
  std::optional<DofReport> dofs;
  std::optional<std::vector<MaterialRecord>> materials;
  std::optional<std::string> input_hash;
  std::optional<MemoryReport> memory;
  std::map<std::string, MethodReport> methods;  ///< by method name; absent in JSON when empty
  std::optional<ColumnsReport> columns;
  std::optional<ChecksReport> checks;
  std::optional<OutputReport> output;
  std::optional<double> peak_rss_bytes;  ///< the largest phase peak (printed report only)
  std::optional<std::vector<ShardReport>> shards;

  /// The phase named @p name, or null.
  const PhaseReport* phase(std::string_view name) const;
};

/// The report as JSON text (docs/compliance-file.md, "The report"); @p indent
/// as nlohmann::json::dump (−1: compact, one line).
std::string to_json(const PrecomputeReport& report, int indent = -1);

/// A report read back from its JSON (a shard's, for merge). Fields missing
/// or of another type are left empty; text that is not JSON gives an empty
/// report.
PrecomputeReport report_from_json(std::string_view text);

/// The report as text for a terminal.
std::string format_report(const PrecomputeReport& report);

}  // namespace palpate
