// The in-memory pipeline: `condensation` and `both` (docs/precompute.md).
// G is computed whole in memory; with `both`, by condensation first, then
// the solves compare each block of columns with it before overwriting it.

#include <fmt/format.h>

#include <algorithm>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/offline/sparse_cholesky.hpp"
#include "precompute_steps.hpp"

namespace palpate::precompute {

void run_in_memory(const PrecomputeJob& job, Problem& p, const MemoryLimit& limit,
                   PrecomputeReport& report, PhaseTimer& phases, const Say& say) {
  const SparseMatrixd& K = p.K;
  const int m = p.m;
  const bool do_solves = job.method != Method::kCondensation;
  const bool do_condensation = job.method != Method::kSolves;
  const double g_bytes = 8.0 * m * static_cast<double>(m);
  {
    const double need = in_memory_bytes(
        job.method, p.n, m, std::min(job.block_columns, m),
        12.0 * static_cast<double>(K.nonZeros()),
        do_solves ? SparseCholesky::estimate_factor_bytes(K) : 0.0,
        do_condensation ? SparseCholesky::estimate_factor_bytes(K, condensation_ordering(K, m))
                        : 0.0);
    MemoryReport& memory = report.memory.emplace();
    memory.G_bytes = g_bytes;
    memory.estimate_bytes = need;
    memory.limit_bytes = limit.bytes;
    refuse_if_too_big(need,
                      fmt::format("G is {}; the rest is the sparse factor; --method solves "
                                  "computes G out of core, within the limit",
                                  format_bytes(g_bytes)),
                      limit);
  }

  ComplianceOptions options;
  options.block_columns = job.block_columns;
  Eigen::MatrixXd G;
  if (do_condensation) {
    say.phase("condensation");
    phases.begin("condensation");
    options.progress = say.progress("condensation");
    ComplianceStats stats;
    p.with_vertex_context([&] { G = compliance_by_condensation(K, m, options, &stats); });
    phases.end().gflop_per_s = dense_gflop_per_s(stats);
    report.methods["condensation"] = method_report(stats);
  }
  double max_difference = -1;
  if (do_solves) {
    say.phase("solves");
    phases.begin("solves");
    options.progress = say.progress(fmt::format("{} solves", m));
    ComplianceStats stats;
    if (do_condensation) {
      // Compare block by block with the condensation result, then overwrite it.
      const double scale = G.cwiseAbs().maxCoeff();
      double worst = 0;
      options.on_block = [&](int first, CRef<Eigen::MatrixXd> block) {
        worst = std::max(worst, (block - G.middleCols(first, block.cols())).cwiseAbs().maxCoeff());
      };
      p.with_vertex_context([&] { compliance_by_solves(K, m, options, G, &stats); });
      max_difference = worst / scale;
    } else {
      p.with_vertex_context([&] { G = compliance_by_solves(K, m, options, &stats); });
    }
    phases.end().gflop_per_s = dense_gflop_per_s(stats);
    report.methods["solves"] = method_report(stats);
  }

  say.phase("checks");
  phases.begin("checks");
  double residual = 0, mismatch = 0;
  for (const auto& [name, method] : report.methods) {
    residual = std::max(residual, method.max_residual);
    mismatch = std::max(mismatch, method.max_column_mismatch);
  }
  const DiagonalBlockSpectrum spectrum = diagonal_block_spectrum(diagonal_blocks(G));
  ChecksReport& checks = report.checks.emplace();
  checks.max_residual = residual;
  checks.max_column_mismatch = mismatch;
  checks.symmetry_error = symmetry_error(G);
  checks.min_diagonal_block_eigenvalue_m_per_n = spectrum.smallest;
  checks.min_diagonal_block_vertex = p.source_vertex(spectrum.smallest_at);
  if (max_difference >= 0) {
    checks.max_relative_difference = max_difference;
    checks.tolerance = job.tolerance;
  }
  phases.end();
  if (max_difference > job.tolerance || !(max_difference == max_difference))
    throw NumericalError(fmt::format(
        "the two methods disagree: largest relative difference {:.3g} > tolerance {:.3g}; no file "
        "written (the stiffness may be too ill-conditioned: check ν < 0.5 and the mesh quality)",
        max_difference, job.tolerance));
  refuse_unsound(residual, mismatch, spectrum, p.model);

  write_compliance(job.output, job.write_xdmf, spectrum, p.model, report, phases, say,
                   [&](const ComplianceModel& model, const ProgressFn& progress) {
                     write_compliance_file(job.output, model, G, progress);
                   });
}

}  // namespace palpate::precompute
