#pragma once
// Private to palpate_offline: the steps the precompute pipelines share
// (precompute.cpp runs them): the problem read from the job, timed phases,
// the memory estimates, the checks that refuse a compliance, and the ending
// that writes the file.

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh.hpp"
#include "palpate/offline/partial_file.hpp"
#include "palpate/offline/precompute.hpp"

namespace palpate::precompute {

/// The caller's hooks, each of which may be empty.
struct Say {
  const PrecomputeHooks& hooks;
  void warn(const std::string& s) const {
    if (hooks.warn) hooks.warn(s);
  }
  void phase(const std::string& s) const {
    if (hooks.phase) hooks.phase(s);
  }
  void info(const std::string& s) const {
    if (hooks.info) hooks.info(s);
  }
  ProgressFn progress(const std::string& label) const {
    return hooks.progress ? hooks.progress(label) : ProgressFn{};
  }
};

/// Times each phase and measures its peak resident memory, into
/// PrecomputeReport::phases.
class PhaseTimer {
 public:
  explicit PhaseTimer(std::vector<PhaseReport>* out) : out_(out) {}
  /// Starts phase @p name, after handing freed heap back to the system.
  void begin(const std::string& name);
  /// Ends the phase begun last; its entry, for the caller to add to.
  PhaseReport& end();
  /// The largest peak of the phases so far.
  double peak() const { return peak_; }

 private:
  std::vector<PhaseReport>* out_;
  std::string name_;
  double start_rss_ = 0;
  std::chrono::steady_clock::time_point t0_;
  double peak_ = 0;
};

/// What a method did, for the report.
MethodReport method_report(const ComplianceStats& stats);
/// The rate of a method's dense part (blocked solves, or the inversion of S), GFLOP/s.
double dense_gflop_per_s(const ComplianceStats& stats);

/// The problem every pipeline solves, read from the job.
struct Problem {
  TetMesh mesh;
  std::vector<Lame> lame;  ///< per material, as model.materials
  Eigen::VectorXi tet_material;
  std::vector<int> fixed;  ///< fixed vertices, sorted
  DofMap dofs;
  int m = 0;  ///< surface DOFs, 3n
  int n = 0;  ///< free DOFs
  /// The compliance file's content but G and the softness map: known before
  /// any solve, so that a streamed run's checkpoint holds it from the start.
  ComplianceModel model;
  SparseMatrixd K;  ///< upper triangle, surface first (empty until assemble_stiffness)
  /// With a cut region: mesh, tet_material, fixed and dofs above are the
  /// outside's (its own mesh, RegionSplit::outside), and this is the free Γ
  /// in the outside's numbering, in the order of model.cut_region's
  /// interface_vertices (precompute_region.cpp).
  std::vector<int> interface_outside;

  /// Runs @p method, turning a failed Cholesky into a message about the mesh.
  template <typename Method>
  void with_vertex_context(Method method) const;
  /// The source vertex index of compliance vertex @p k, for messages.
  int source_vertex(int k) const;
};

/// The NumericalError of a Cholesky that failed at DOF @p column of K.
[[noreturn]] void throw_not_positive_definite(const Problem& problem, int column);

/// Reads and checks the mesh, the materials, the attachment; numbers the
/// DOFs; fills report.mesh, dofs, materials, input_hash and the model but G.
/// Phase "read mesh". @throws InputError naming what is wrong.
Problem read_problem(const PrecomputeJob& job, PrecomputeReport& report, PhaseTimer& phases,
                     const Say& say);
/// With a cut region (precompute_region.cpp): splits the whole mesh
/// @p p.mesh by @p region (split_region(), its warnings said), puts the
/// region's data into p.model.cut_region (all but interface_compliance_index),
/// then makes the outside the problem: p.mesh, p.tet_material, p.fixed and
/// @p boundary become the outside's (outside_boundary()), so that G is its
/// compliance on its boundary, Γ included; fills report.cut_region.
/// @throws InputError from split_region().
void restrict_to_outside(const CutRegionJob& region, Problem& p, Boundary& boundary,
                         PrecomputeReport& report, const Say& say);
/// Then, once p.dofs numbers the outside's compliance vertices: where each
/// Γ vertex is among them (p.model.cut_region's interface_compliance_index).
void index_interface(Problem& p);

/// Assembles K (phase "assemble K").
void assemble_stiffness(Problem& problem, PhaseTimer& phases, const Say& say);

/// The memory a job may use.
struct MemoryLimit {
  double bytes = 0;
  std::string name;  ///< "is the memory limit set", "is available on this machine"
};
MemoryLimit memory_limit(double limit_bytes);
/// @throws ResourceError when @p need_bytes exceed @p limit, with the
/// numbers and @p detail (what the need is made of).
void refuse_if_too_big(double need_bytes, const std::string& detail, const MemoryLimit& limit);

/// Memory (bytes) one thread of the `solves` method holds for a block of
/// @p block columns: four n × B arrays of doubles (unit columns, solution,
/// CHOLMOD's X and Y) and the block of G it solved (m × B), twice when the
/// block is converted on its way to a file (@p converted).
double solve_thread_bytes(int n, int m, int block, bool converted);

/// Memory (bytes) of the streamed `solves` run (pipeline_streamed.cpp): K
/// and CHOLMOD's permuted copies of it while it factors (3 × @p k_bytes),
/// the factor, each thread's arrays and block on the way to the file, one
/// more block being converted, the checks. Against the solves phase's peak
/// resident memory less its start (docs/precompute.md): 280 MB for 310
/// estimated on one thread, 374 for 407 on two (110k-tet liver, B = 64);
/// 2.90 GB for 3.06 on two (505k tets).
double streamed_memory_bytes(int n, int m, int block, int threads, double k_bytes,
                             double factor_bytes);

/// Memory (bytes) of the in-memory run of @p method (pipeline_in_memory.cpp):
/// G, plus each method's factor and work arrays (they run one at a time),
/// plus K.
double in_memory_bytes(Method method, int n, int m, int block, double k_bytes,
                       double solves_factor_bytes, double condensation_factor_bytes);

/// Largest relative residual or column mismatch accepted (docs/model/compliance.md,
/// "Checks before a file is written").
inline constexpr double kMaxResidual = 1e-6;

/// @throws NumericalError unless the sampled residual and column mismatch are
/// within kMaxResidual: K is then singular to working precision (a part held
/// too loosely, a degenerate region) and G would be meaningless.
void refuse_bad_residual(double max_residual, double max_column_mismatch);

/// refuse_bad_residual(), then @throws NumericalError unless every diagonal
/// block is positive definite: no file is written.
void refuse_unsound(double max_residual, double max_column_mismatch,
                    const DiagonalBlockSpectrum& spectrum, const ComplianceModel& model);

/// Where the ending writes G from: the whole matrix, or a source of row bands.
using WriteG = std::function<void(const ComplianceModel& model, const ProgressFn& progress)>;

/// The ending every pipeline and merge share: the softness map into the
/// model, the report's output, the report into the file, the file written
/// atomically by @p write_G (phase "write file"), its XDMF sidecar, a
/// warning for a stale sidecar left by an earlier run; then output.bytes and
/// peak_rss_bytes. The caller checked G first (refuse_unsound).
void write_compliance(const std::filesystem::path& output, bool write_xdmf,
                      const DiagonalBlockSpectrum& spectrum, ComplianceModel& model,
                      PrecomputeReport& report, PhaseTimer& phases, const Say& say,
                      const WriteG& write_G);

// ---- the pipelines (their own files) -------------------------------------------

/// The columns of G a run computes: [begin, end).
struct ColumnRange {
  int begin = 0, end = 0;
};

/// `condensation` and `both`: G in memory, the methods cross-checked
/// (pipeline_in_memory.cpp).
void run_in_memory(const PrecomputeJob& job, Problem& problem, const MemoryLimit& limit,
                   PrecomputeReport& report, PhaseTimer& phases, const Say& say);

/// `solves` and shards: G streamed through a resumable checkpoint, never
/// whole in memory (pipeline_streamed.cpp).
void run_streamed(const PrecomputeJob& job, Problem& problem, ColumnRange columns,
                  const MemoryLimit& limit, PrecomputeReport& report, PhaseTimer& phases,
                  const Say& say);

/// The compliance file from complete shards that tile G (merge.cpp): the
/// diagonal blocks' spectrum from their float64 entries, the checks, then G
/// in row bands within @p budget_bytes, and the sidecar; fills the report's
/// checks, output and memory.merge_band_rows.
void write_from_shards(std::vector<std::unique_ptr<PartialFile>>& shards,
                       const std::filesystem::path& output, bool write_xdmf, double budget_bytes,
                       PrecomputeReport& report, PhaseTimer& phases, const Say& say);

template <typename Method>
void Problem::with_vertex_context(Method method) const {
  try {
    method();
  } catch (const NotPositiveDefinite& e) {
    throw_not_positive_definite(*this, e.column());
  }
}

}  // namespace palpate::precompute
