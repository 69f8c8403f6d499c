// Shards into one compliance file (docs/precompute.md, "Batch
// precomputation"): `palpate-precompute merge`, and the last step of a
// streamed run, whose checkpoint is the one shard of its file.

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/core/version.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/xdmf.hpp"
#include "palpate/offline/partial_file.hpp"
#include "precompute_steps.hpp"

namespace palpate::precompute {

namespace {

// Rows of G per band when writing the final file from shards, within
// @p budget bytes: a band in double and float, plus the sampled rows.
long band_rows_within(double budget, int m) {
  const double per_row = 12.0 * m;
  return static_cast<long>(std::clamp(std::floor(budget / per_row), 1.0, 256.0));
}

// The OpenBLAS kernels in a blas_description() ("… core SkylakeX]"): what,
// besides the inputs, decides G's last bits (the thread count does not: the
// solves method runs on single-threaded BLAS).
std::string blas_core(const std::string& description) {
  const auto at = description.rfind("core ");
  return at == std::string::npos ? description : description.substr(at);
}

// Shards sorted by their first column; refused unless they come from one
// problem, with one storage and block size, and cover [0, m) once.
void check_shards_tile(std::vector<std::unique_ptr<PartialFile>>& shards,
                       const std::function<void(const std::string&)>& warn) {
  if (shards.empty()) throw InputError("merge: no shard given");
  std::sort(shards.begin(), shards.end(), [](const auto& a, const auto& b) {
    return a->identity().columns_begin < b->identity().columns_begin;
  });
  const auto& ref = *shards.front();
  const ShardIdentity& r = ref.identity();
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    const auto names = fmt::format("{} and {}", ref.path().string(), s->path().string());
    if (i.input_hash != r.input_hash || i.columns_total != r.columns_total)
      throw InputError(fmt::format(
          "merge: {} come from different inputs (input hash {}… and {}…): merge only the shards "
          "of one job (same mesh, materials and attachment)",
          names, r.input_hash.substr(0, 19), i.input_hash.substr(0, 19)));
    if (i.precision != r.precision)
      throw InputError(
          fmt::format("merge: {} store G in {} and {}: compute every shard with the "
                      "same --precision",
                      names, to_string(r.precision), to_string(i.precision)));
    if (i.block_columns != r.block_columns)
      throw InputError(
          fmt::format("merge: {} were solved in blocks of {} and {} columns: compute "
                      "every shard with the same --block-columns (the merged file "
                      "must equal one run)",
                      names, r.block_columns, i.block_columns));
    if (blas_core(s->blas()) != blas_core(ref.blas()))
      warn(
          fmt::format("merge: {} were computed with different BLAS kernels ({} and {}): G agrees "
                      "to round-off but its last bits may differ from a single run's (set "
                      "OPENBLAS_CORETYPE alike on every node)",
                      names, ref.blas(), s->blas()));
  }
  int expected = 0;
  const PartialFile* previous = nullptr;
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    if (i.columns_begin > expected)
      throw InputError(fmt::format(
          "merge: columns {}:{} of {} are in no shard (a gap {}): compute them with --columns "
          "{}:{}, or pass the shard that holds them",
          expected, i.columns_begin, r.columns_total,
          previous ? fmt::format("between {} and {}", previous->path().string(), s->path().string())
                   : fmt::format("before {}", s->path().string()),
          expected, i.columns_begin));
    if (i.columns_begin < expected)
      throw InputError(fmt::format(
          "merge: {} and {} both hold columns {}:{} (overlapping shards, e.g. from two different "
          "splits): pass each column once",
          previous->path().string(), s->path().string(), i.columns_begin,
          std::min(expected, i.columns_end)));
    expected = i.columns_end;
    previous = s.get();
  }
  if (expected < r.columns_total)
    throw InputError(fmt::format(
        "merge: columns {}:{} of {} are in no shard (a gap after {}): compute them with --columns "
        "{}:{}, or pass the shard that holds them",
        expected, r.columns_total, r.columns_total, previous->path().string(), expected,
        r.columns_total));
}

}  // namespace

void write_from_shards(std::vector<std::unique_ptr<PartialFile>>& shards,
                       const std::filesystem::path& output, bool write_xdmf, double budget_bytes,
                       PrecomputeReport& report, PhaseTimer& phases, const Say& say) {
  ComplianceModel model = shards.front()->model();
  const int m = shards.front()->identity().columns_total;

  // Diagonal blocks: the shards keep entries (3k + i, c) of the 3 columns c
  // of each vertex k, in float64.
  Eigen::Matrix3Xd blocks(3, m);
  double residual = 0, mismatch = 0;
  std::vector<int> checked;
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    blocks.middleCols(i.columns_begin, i.columns_end - i.columns_begin) =
        s->diagonal_entries().transpose();
    for (const auto& c : s->checks()) {
      residual = std::max(residual, c.residual);
      mismatch = std::max(mismatch, c.mismatch);
      checked.push_back(c.column);
    }
  }
  const DiagonalBlockSpectrum spectrum = diagonal_block_spectrum(blocks);
  refuse_unsound(residual, mismatch, spectrum, model);

  // Symmetry, sampled: for spread columns c, column c against row c, both
  // seen as the row bands go by (G itself is never whole in memory).
  const std::vector<int> sampled = sample_columns(m, 32);
  std::vector<Eigen::VectorXd> column(sampled.size(), Eigen::VectorXd(m)), row(sampled.size());
  double largest = 0;
  std::sort(checked.begin(), checked.end());
  ChecksReport& checks = report.checks.emplace();
  checks.max_residual = residual;
  checks.max_column_mismatch = mismatch;
  checks.min_diagonal_block_eigenvalue_m_per_n = spectrum.smallest;
  checks.min_diagonal_block_vertex =
      model.source_vertex_ids[model.compliance_vertices[spectrum.smallest_at]];
  checks.checked_columns = checked;
  // The symmetry error is only known once G is written: the stored report
  // says it was sampled, the returned one has the value.
  checks.symmetry_error_sampled_columns = static_cast<long>(sampled.size());
  report.method = "solves";
  model.method = "solves";
  model.created_utc = report.created_utc;
  model.producer = report.producer;

  const double fixed_bytes = 8.0 * m * static_cast<double>(sampled.size()) + 48.0 * m;
  const long band = band_rows_within(budget_bytes - fixed_bytes, m);
  if (!report.memory) report.memory.emplace();
  report.memory->merge_band_rows = band;

  write_compliance(
      output, write_xdmf, spectrum, model, report, phases, say,
      [&](const ComplianceModel& full, const ProgressFn& progress) {
        write_compliance_file(
            output, full,
            [&](long first, long count, double* rows) {
              for (const auto& s : shards) s->read_rows(first, count, rows);
              const Eigen::Map<
                  const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>
                  band_rows(rows, count, m);
              if (!band_rows.allFinite())
                throw InputError(
                    fmt::format("rows {}:{} of G in the shards hold a non-finite "
                                "value (a damaged shard?)",
                                first, first + count));
              largest = std::max(largest, band_rows.cwiseAbs().maxCoeff());
              for (size_t j = 0; j < sampled.size(); ++j) {
                column[j].segment(first, count) = band_rows.col(sampled[j]);
                if (sampled[j] >= first && sampled[j] < first + count)
                  row[j] = band_rows.row(sampled[j] - first).transpose();
              }
            },
            band, progress);
      });
  double asymmetry = 0;
  for (size_t j = 0; j < sampled.size(); ++j)
    asymmetry = std::max(asymmetry, (column[j] - row[j]).cwiseAbs().maxCoeff());
  report.checks->symmetry_error = largest > 0 ? asymmetry / largest : asymmetry;
}

}  // namespace palpate::precompute

namespace palpate {

PrecomputeReport merge_shards(const MergeJob& job, const PrecomputeHooks& hooks) {
  using namespace precompute;
  const Say say{hooks};
  if (job.output.empty()) throw InputError("merge: no output file given: use -o FILE.h5");
  if (job.shards.empty())
    throw InputError("merge: no shard given: list the shard files (e.g. liver.part-*.h5)");
  require_output_directory(job.output);
  if (job.write_xdmf) check_xdmf_sidecar_name(job.output);
  if (!(job.memory_limit_bytes >= 0))
    throw InputError("memory limit must be ≥ 0 (0: available memory)");

  std::vector<PhaseReport> merge_phases;
  PhaseTimer phases(&merge_phases);
  say.phase("check shards");
  phases.begin("check shards");
  std::vector<std::unique_ptr<PartialFile>> shards;
  for (const auto& path : job.shards) shards.push_back(PartialFile::open_complete(path));
  check_shards_tile(shards, [&](const std::string& s) { say.warn(s); });
  phases.end();

  // The first shard's report describes the problem (mesh, materials, factor).
  PrecomputeReport report = report_from_json(shards.front()->report_json());
  report.producer = "palpate-precompute " PALPATE_VERSION;
  report.created_utc = utc_timestamp();
  report.columns.reset();
  report.peak_rss_bytes.reset();
  auto& list = report.shards.emplace();
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    ShardReport entry;
    entry.file = s->path().string();
    entry.columns_begin = i.columns_begin;
    entry.columns_end = i.columns_end;
    entry.blas = s->blas();
    const PrecomputeReport r = report_from_json(s->report_json());
    if (r.columns) entry.columns_per_second = r.columns->columns_per_second;
    entry.peak_rss_bytes = r.peak_rss_bytes;
    list.push_back(entry);
  }
  report.phases = merge_phases;
  PhaseTimer more(&report.phases);
  const MemoryLimit limit = memory_limit(job.memory_limit_bytes);
  if (!report.memory) report.memory.emplace();
  report.memory->limit_bytes = limit.bytes;
  write_from_shards(shards, job.output, job.write_xdmf, limit.bytes, report, more, say);
  report.peak_rss_bytes = std::max(phases.peak(), more.peak());
  return report;
}

}  // namespace palpate
