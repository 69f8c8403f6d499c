// The streamed pipeline: `solves` and shards (docs/precompute.md, "Batch
// precomputation"). G is never whole in memory: its columns are solved in
// blocks into a checkpoint beside the output (partial_file.hpp), flagged
// complete block by block, so that a killed run resumes from its last
// complete block; the checkpoint then becomes the shard file, or the
// compliance file through the same writer as a merge.

#include <fmt/format.h>

#include <algorithm>
#include <set>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/offline/partial_file.hpp"
#include "palpate/offline/sparse_cholesky.hpp"
#include "precompute_steps.hpp"

namespace palpate::precompute {

namespace {

// Prints one line at the first block (the estimate), then at every tenth of
// the columns: done / total, columns per second, time left.
class SolveProgress {
 public:
  SolveProgress(std::function<void(const std::string&)> info, long done, long total, int threads)
      : info_(std::move(info)),
        resumed_(done),
        done_(done),
        total_(total),
        threads_(threads),
        t0_(std::chrono::steady_clock::now()) {}
  /// The clock starts when the factor is ready: the first block's time (and
  /// so the estimate, and the rate) is then the solves' alone.
  void start() { t0_ = std::chrono::steady_clock::now(); }
  void add(long columns, int block_columns, long pending_blocks) {
    done_ += columns;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    if (!info_) return;
    if (!first_reported_) {
      first_reported_ = true;
      // The threads solve their first blocks side by side.
      const double estimate = s * static_cast<double>(pending_blocks) / threads_;
      info_(fmt::format(
          "first block of {} columns solved in {:.2f} s: about {:.0f} s for the {} "
          "blocks left ({} thread{})",
          block_columns, s, estimate, pending_blocks, threads_, threads_ > 1 ? "s" : ""));
    }
    const long tenth = 10 * done_ / std::max(1L, total_);
    if (tenth <= last_tenth_) return;
    last_tenth_ = tenth;
    const double rate = s > 0 ? static_cast<double>(done_ - resumed_) / s : 0;
    info_(fmt::format("solves: {}/{} columns ({:.0f} %), {:.0f} columns/s, about {:.0f} s left",
                      done_, total_,
                      100.0 * static_cast<double>(done_) / static_cast<double>(total_), rate,
                      rate > 0 ? static_cast<double>(total_ - done_) / rate : 0.0));
  }
  double rate() const {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    return s > 0 ? static_cast<double>(done_ - resumed_) / s : 0;
  }

 private:
  std::function<void(const std::string&)> info_;
  long resumed_, done_, total_;
  int threads_;
  std::chrono::steady_clock::time_point t0_;
  bool first_reported_ = false;
  long last_tenth_ = 0;
};

}  // namespace

void run_streamed(const PrecomputeJob& job, Problem& p, ColumnRange columns,
                  const MemoryLimit& limit, PrecomputeReport& report, PhaseTimer& phases,
                  const Say& say) {
  const SparseMatrixd& K = p.K;
  const int m = p.m, n = p.n;
  const int block_columns = job.block_columns;
  const ShardIdentity id{p.model.input_hash, columns.begin, columns.end, m,
                         block_columns,      job.precision};
  const bool sharded = columns.begin != 0 || columns.end != m || job.shard.any();
  const auto target =
      sharded ? shard_output_path(job.output, columns.begin, columns.end) : job.output;
  const auto checkpoint = checkpoint_path(target);
  const int width = columns.end - columns.begin;

  // G is never in memory (streamed_memory_bytes() says what is).
  const double k_bytes = 12.0 * static_cast<double>(K.nonZeros());
  const int threads = std::min(solve_threads(), id.blocks());
  const int block = std::min(block_columns, m);
  const double factor_bytes = SparseCholesky::estimate_factor_bytes(K);
  const double need = streamed_memory_bytes(n, m, block, threads, k_bytes, factor_bytes);
  const int element_bytes = job.precision == Precision::kFloat32 ? 4 : 8;
  const double file_bytes = static_cast<double>(element_bytes) * m * width;
  MemoryReport& memory = report.memory.emplace();
  memory.G_bytes = 8.0 * m * static_cast<double>(m);
  memory.estimate_bytes = need;
  memory.limit_bytes = limit.bytes;
  memory.streamed = true;
  memory.G_file_bytes = file_bytes;
  if (need > limit.bytes)
    throw ResourceError(fmt::format(
        "even one block of {} columns per thread ({} threads) and the sparse factor ({}) need "
        "about {} but {} {}: use a smaller --block-columns, or a machine with more memory",
        block, threads, format_bytes(factor_bytes), format_bytes(need), format_bytes(limit.bytes),
        limit.name));
  say.info(fmt::format(
      "{}: columns {}:{} of {} in {} blocks of {}; G {} on disk ({}), at most about {} in memory "
      "(limit {})",
      sharded ? "shard" : "solves", columns.begin, columns.end, m, id.blocks(), block_columns,
      format_bytes(file_bytes), to_string(job.precision), format_bytes(need),
      format_bytes(limit.bytes)));

  // Resume the checkpoint of an earlier run of the same columns, if any.
  std::unique_ptr<PartialFile> partial;
  std::error_code ec;
  if (std::filesystem::exists(checkpoint, ec)) {
    std::string why;
    partial = PartialFile::open_to_resume(checkpoint, id, &why);
    if (partial) {
      say.info(fmt::format("resuming {}: {} of {} blocks already complete", checkpoint.string(),
                           id.blocks() - static_cast<int>(partial->pending_blocks().size()),
                           id.blocks()));
    } else {
      say.warn(
          fmt::format("discarded {}, left by an earlier run: {}; starting from the first block",
                      checkpoint.string(), why));
      std::filesystem::remove(checkpoint, ec);
    }
  }
  const auto checks_wanted = [&] {
    // The checks a single run makes that fall here, plus this range's ends.
    std::set<int> c{columns.begin, columns.end - 1};
    for (const int j : sample_columns(m, ComplianceOptions{}.check_columns))
      if (j >= columns.begin && j < columns.end) c.insert(j);
    return std::vector<int>(c.begin(), c.end());
  }();
  if (!partial) partial = PartialFile::create(checkpoint, p.model, id, checks_wanted, report.blas);
  const std::vector<int> pending = partial->pending_blocks();
  ColumnsReport& columns_report = report.columns.emplace();
  columns_report.begin = columns.begin;
  columns_report.end = columns.end;
  columns_report.total = m;
  columns_report.block_columns = block_columns;
  columns_report.blocks = id.blocks();
  columns_report.resumed_blocks = id.blocks() - static_cast<int>(pending.size());

  say.phase("solves");
  phases.begin("solves");
  ComplianceStats stats;
  if (!pending.empty()) {
    long done = 0;
    for (int b = id.first_block(); b < id.first_block() + id.blocks(); ++b)
      if (!std::binary_search(pending.begin(), pending.end(), b))
        done += std::min(block_columns, m - b * block_columns);
    SolveProgress lines(say.hooks.info, done, width,
                        std::min<int>(threads, static_cast<int>(pending.size())));
    auto bar = say.progress(fmt::format("{} solves", width));
    long left = static_cast<long>(pending.size());
    p.with_vertex_context([&] {
      solve_compliance_blocks(
          K, m, block_columns, pending, checks_wanted,
          [&](const SolvedBlock& b) {
            partial->write_block(b);
            done += b.columns.cols();
            lines.add(b.columns.cols(), block_columns, --left);
            if (bar) bar(done, width);
          },
          &stats,
          [&](const FactorInfo& f) {
            lines.start();
            say.info(
                fmt::format("factor: {} ordering, nnz(L) = {:.3g}, {:.2f} s; {} columns left "
                            "to solve, {:.3g} GFLOP",
                            f.ordering, f.nnz_L, f.factor_seconds, width - done,
                            4.0 * f.nnz_L * static_cast<double>(width - done) / 1e9));
          });
    });
    report.columns->columns_per_second = lines.rate();
  }
  phases.end().gflop_per_s = dense_gflop_per_s(stats);
  // The checks of every block, this run's and the resumed ones.
  double residual = 0, mismatch = 0;
  std::vector<int> checked;
  for (const auto& c : partial->checks()) {
    residual = std::max(residual, c.residual);
    mismatch = std::max(mismatch, c.mismatch);
    checked.push_back(c.column);
  }
  stats.max_residual = residual;
  stats.max_column_mismatch = mismatch;
  stats.checked_columns = checked;
  report.methods = {{"solves", method_report(stats)}};
  ChecksReport& checks = report.checks.emplace();
  checks.max_residual = residual;
  checks.max_column_mismatch = mismatch;
  try {
    refuse_bad_residual(residual, mismatch);
  } catch (const NumericalError&) {
    partial.reset();
    std::filesystem::remove(checkpoint, ec);  // the same inputs would give the same
    throw;
  }

  if (sharded) {
    OutputReport& output = report.output.emplace();
    output.file = target.string();
    output.precision = to_string(job.precision);
    partial->finish(to_json(report));
    partial->close();
    durable_rename(checkpoint, target);
    report.output->bytes = std::filesystem::file_size(target);
    report.peak_rss_bytes = phases.peak();
    return;
  }
  partial->finish(to_json(report));
  partial->close();
  partial.reset();
  std::vector<std::unique_ptr<PartialFile>> whole;
  whole.push_back(PartialFile::open_complete(checkpoint));
  write_from_shards(whole, job.output, job.write_xdmf, limit.bytes - k_bytes, report, phases, say);
  whole.clear();
  std::filesystem::remove(checkpoint, ec);
  report.peak_rss_bytes = phases.peak();
}

}  // namespace palpate::precompute
