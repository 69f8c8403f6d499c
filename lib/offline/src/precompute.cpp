#include "palpate/offline/precompute.hpp"

#include <fmt/format.h>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/core/version.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/file/xdmf.hpp"
#include "precompute_steps.hpp"

namespace palpate {

std::filesystem::path shard_output_path(const std::filesystem::path& output, int begin, int end) {
  auto name = fmt::format("{}.part-{}-{}{}", output.stem().string(), begin, end,
                          output.extension().string());
  return output.has_parent_path() ? output.parent_path() / name : std::filesystem::path(name);
}

namespace {

/// The columns of G a run computes: all of them, or its shard's whole
/// blocks, or the explicit range (checked against G's size here, once m is
/// known).
precompute::ColumnRange columns_of(const PrecomputeJob& job, int m) {
  const int block_columns = job.block_columns;
  if (job.shard.count > 0) {
    const int blocks = (m + block_columns - 1) / block_columns;
    if (job.shard.count > blocks)
      throw InputError(
          fmt::format("shard {}/{}: G has {} columns, {} blocks of {}: at most {} "
                      "shards; use fewer shards or a smaller --block-columns",
                      job.shard.index, job.shard.count, m, blocks, block_columns, blocks));
    // As even as whole blocks go: shard k gets blocks [k·B/N, (k+1)·B/N).
    const auto first_block = static_cast<long>(job.shard.index) * blocks / job.shard.count;
    const auto end_block = static_cast<long>(job.shard.index + 1) * blocks / job.shard.count;
    return {static_cast<int>(first_block) * block_columns,
            std::min(m, static_cast<int>(end_block) * block_columns)};
  }
  if (job.shard.begin >= 0) {
    const int begin = job.shard.begin, end = job.shard.end;
    if (end > m || begin % block_columns != 0 || (end % block_columns != 0 && end != m))
      throw InputError(fmt::format(
          "columns {}:{}: G has {} columns (0:{}) solved in blocks of {}: a shard starts at a "
          "multiple of {} and ends at one or at {}, so that every column is solved as in a "
          "single run",
          begin, end, m, m, block_columns, block_columns, m));
    return {begin, end};
  }
  return {0, m};
}

/// --reuse: keeps the output when it holds this problem, whole (its digest
/// checked as it is read), at the job's precision; writes missing sidecars.
/// @returns true when kept; false (with the reason said) when it must be computed.
bool reuse_output(const PrecomputeJob& job, const precompute::Problem& problem,
                  PrecomputeReport& report, const precompute::Say& say) {
  std::error_code ec;
  if (!std::filesystem::exists(job.output, ec)) return false;
  ComplianceModel kept;
  try {
    Eigen::MatrixXd G;
    Eigen::MatrixXf G32;
    kept = read_compliance_file(job.output, &G, &G32);
  } catch (const InputError& e) {
    say.warn(fmt::format("--reuse: computing again: {}", e.what()));
    return false;
  }
  const char* differs = kept.input_hash != problem.model.input_hash ? "another problem"
                        : kept.precision != job.precision           ? "another precision"
                                                                    : nullptr;
  if (differs != nullptr) {
    say.info(fmt::format("--reuse: {} holds {}: computing it again", job.output.string(), differs));
    return false;
  }
  OutputReport& out = report.output.emplace();
  out.file = job.output.string();
  out.precision = to_string(kept.precision);
  out.bytes = std::filesystem::file_size(job.output);
  out.reused = true;
  if (job.write_xdmf) {
    out.xdmf = xdmf_sidecar_path(job.output).string();
    if (!std::filesystem::exists(xdmf_sidecar_path(job.output), ec) ||
        !std::filesystem::exists(xdmf_surface_sidecar_path(job.output), ec))
      write_xdmf_sidecar(job.output, kept);
  }
  return true;
}

}  // namespace

PrecomputeReport run_precompute(const PrecomputeJob& job, const PrecomputeHooks& hooks) {
  using namespace precompute;
  const Say say{hooks};
  validate_job(job);
  PrecomputeReport report;
  report.producer = "palpate-precompute " PALPATE_VERSION;
  report.created_utc = utc_timestamp();
  report.blas = blas_description();
  report.method = to_string(job.method);
  PhaseTimer phases(&report.phases);

  Problem problem = read_problem(job, report, phases, say);
  const int m = problem.m;

  // The `solves` method streams G through a checkpoint: out of core and
  // resumable. Its columns: all, or the shard's whole blocks. Shards are
  // computed by solves (condensation needs the whole G).
  if (job.shard.any() && job.method == Method::kCondensation)
    throw InputError(
        "--shard and --columns compute columns of G by solves: use --method solves "
        "(condensation computes the whole G at once)");
  const bool streaming = job.method == Method::kSolves || job.shard.any();
  {
    // The job the file stores: enough to run it again (no shard: the file
    // is the whole G, however it was computed).
    PrecomputeJob stored = job;
    stored.shard = {};
    if (streaming) stored.method = Method::kSolves;
    problem.model.method = to_string(stored.method);
    report.method = problem.model.method;
    problem.model.job_toml = to_toml(stored);
  }
  const ColumnRange columns = columns_of(job, m);

  // Memory: refuse before the long work, with the numbers.
  const MemoryLimit limit = memory_limit(job.memory_limit_bytes);
  if (!streaming)
    refuse_if_too_big(8.0 * m * static_cast<double>(m),
                      fmt::format("G alone is {} × {} doubles; --method solves computes it out of "
                                  "core, within the limit",
                                  m, m),
                      limit);

  if (job.reuse && !job.shard.any() && reuse_output(job, problem, report, say)) return report;

  assemble_stiffness(problem, phases, say);
  if (streaming)
    run_streamed(job, problem, columns, limit, report, phases, say);
  else
    run_in_memory(job, problem, limit, report, phases, say);
  return report;
}

}  // namespace palpate
