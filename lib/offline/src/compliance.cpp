#include "palpate/offline/compliance.hpp"

#include <dlfcn.h>
#include <sched.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <mutex>
#include <numeric>
#include <thread>

#include "palpate/core/detail/stopwatch.hpp"
#include "palpate/core/error.hpp"
#include "palpate/offline/dense.hpp"

namespace palpate {

namespace {

// Sets OpenBLAS's thread count for a scope (0: leave it), when OpenBLAS is
// the BLAS in use.
class BlasThreads {
 public:
  explicit BlasThreads(int count) {
    using Get = int (*)();
    auto get = reinterpret_cast<Get>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
    set_ = reinterpret_cast<Set>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
    if (count > 0 && get && set_) {
      previous_ = get();
      set_(count);
    }
  }
  ~BlasThreads() {
    if (previous_ > 0) set_(previous_);
  }
  BlasThreads(const BlasThreads&) = delete;
  BlasThreads& operator=(const BlasThreads&) = delete;

 private:
  using Set = void (*)(int);
  Set set_ = nullptr;
  int previous_ = 0;
};

using detail::seconds_since;

}  // namespace

std::vector<int> sample_columns(int m, int count) {
  std::vector<int> cols;
  if (m == 0 || count <= 0) return cols;
  count = std::min(count, m);
  for (int i = 0; i < count; ++i)
    cols.push_back(count == 1 ? 0 : static_cast<int>((static_cast<long>(m - 1) * i) / (count - 1)));
  cols.erase(std::unique(cols.begin(), cols.end()), cols.end());
  return cols;
}

namespace {

// Re-solves the sampled columns with `factor` and measures the residual of
// the full system and the agreement with the stored columns of G.
void check_columns(const SparseMatrixd& K_upper, SparseCholesky& factor, CRef<Eigen::MatrixXd> G,
                   int count, ComplianceStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  const int n = static_cast<int>(K_upper.rows());
  const int m = static_cast<int>(G.rows());
  const std::vector<int> cols = sample_columns(m, count);
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(n, static_cast<Eigen::Index>(cols.size()));
  for (size_t i = 0; i < cols.size(); ++i) E(cols[i], static_cast<Eigen::Index>(i)) = 1;
  Eigen::MatrixXd U(n, E.cols());
  factor.solve(E, U);
  const Eigen::MatrixXd R = K_upper.selfadjointView<Eigen::Upper>() * U - E;
  for (size_t i = 0; i < cols.size(); ++i) {
    const auto c = static_cast<Eigen::Index>(i);
    stats->max_residual = std::max(stats->max_residual, R.col(c).norm());  // ‖e_j‖ = 1
    const double g = G.col(cols[i]).norm();
    stats->max_column_mismatch =
        std::max(stats->max_column_mismatch, (U.col(c).head(m) - G.col(cols[i])).norm() / g);
  }
  stats->checked_columns = cols;
  stats->check_seconds = seconds_since(t0);
}

}  // namespace

int solve_threads() {
  // The cores this process may run on (taskset, a Slurm task's allocation),
  // not the machine's: shards side by side must not oversubscribe it.
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0 && CPU_COUNT(&set) > 0) return CPU_COUNT(&set);
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

namespace {

// The factor of the `solves` method, on single-threaded BLAS: OpenBLAS's
// threads change the factor's last bits, and G's columns must be the same
// bits on any machine of the same CPU kind whatever its core count (shards on
// a cluster, a single run on a workstation). The factor is a small part of
// the method's work (4 nnz(L) flops per column of G follow it).
SparseCholesky single_threaded_factor(const SparseMatrixd& K_upper) {
  BlasThreads single(1);
  return SparseCholesky(K_upper);
}

// Solves the given blocks of unit columns with @p factor, one thread per core
// taking every c-th block, each with its own workspace. BLAS is single-threaded
// throughout, whatever the number of blocks: CHOLMOD's supernodes are too
// small for OpenBLAS's own threads to pay off, and a block's bits must not
// depend on how many blocks a run has (shards, resumed runs).
void solve_blocks(const SparseMatrixd& K_upper, const SparseCholesky& factor, int m, int block,
                  const std::vector<int>& blocks, const std::vector<int>& check_columns,
                  const std::function<void(const SolvedBlock&)>& sink) {
  const int n = static_cast<int>(K_upper.rows());
  const int threads = std::min<int>(solve_threads(), static_cast<int>(blocks.size()));
  if (threads == 0) return;
  std::mutex serialize;  // one sink call at a time
  std::atomic<bool> failed{false};
  std::vector<std::exception_ptr> errors(static_cast<size_t>(threads));
  auto work = [&](int t) {
    try {
      auto ws = factor.make_workspace();
      Eigen::MatrixXd E = Eigen::MatrixXd::Zero(n, std::min(block, m));
      Eigen::MatrixXd U(n, E.cols());
      Eigen::VectorXd e(n), u(n);
      for (size_t i = static_cast<size_t>(t); i < blocks.size() && !failed;
           i += static_cast<size_t>(threads)) {
        const int b = blocks[i];
        const int c0 = b * block;
        const int width = std::min(block, m - c0);
        PALPATE_DEMAND(c0 >= 0 && width > 0);
        // Column (k, d) of the block is the unit force e_(k,d).
        E.setZero();
        for (int j = 0; j < width; ++j) E(c0 + j, j) = 1;
        factor.solve(E.leftCols(width), U.leftCols(width), *ws);
        std::vector<ColumnCheck> checks;
        for (const int c : check_columns) {
          if (c < c0 || c >= c0 + width) continue;
          // Alone, as a fresh solve: the residual of the full system and the
          // agreement with the blocked solve's column.
          e.setZero();
          e[c] = 1;
          factor.solve(e, u, *ws);
          const Eigen::VectorXd r = K_upper.selfadjointView<Eigen::Upper>() * u - e;
          const auto g = U.col(c - c0).head(m);
          checks.push_back({c, r.norm(), (u.head(m) - g).norm() / g.norm()});
        }
        std::lock_guard<std::mutex> lock(serialize);
        if (failed) break;
        sink(SolvedBlock{b, c0, U.topLeftCorner(m, width), std::move(checks)});
      }
    } catch (...) {
      failed = true;
      errors[static_cast<size_t>(t)] = std::current_exception();
    }
  };
  BlasThreads single(1);
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& th : pool) th.join();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace

void solve_compliance_blocks(const SparseMatrixd& K_upper, int m, int block_columns,
                             const std::vector<int>& blocks, const std::vector<int>& check_columns,
                             const std::function<void(const SolvedBlock&)>& sink,
                             ComplianceStats* stats,
                             const std::function<void(const FactorInfo&)>& on_factored) {
  PALPATE_DEMAND(m > 0 && m <= K_upper.rows() && block_columns > 0);
  ComplianceStats local;
  if (!stats) stats = &local;
  const SparseCholesky factor = single_threaded_factor(K_upper);
  stats->factor = factor.info();
  if (on_factored) on_factored(stats->factor);
  const auto t0 = std::chrono::steady_clock::now();
  long columns = 0;
  for (const int b : blocks) columns += std::min(block_columns, m - b * block_columns);
  solve_blocks(K_upper, factor, m, block_columns, blocks, check_columns, [&](const SolvedBlock& s) {
    for (const auto& c : s.checks) {
      stats->max_residual = std::max(stats->max_residual, c.residual);
      stats->max_column_mismatch = std::max(stats->max_column_mismatch, c.mismatch);
      stats->checked_columns.push_back(c.column);
    }
    sink(s);
  });
  stats->dense_seconds = seconds_since(t0);
  // Forward and backward substitution: 2 flops per nonzero of L each, per column.
  stats->dense_flops = 4.0 * stats->factor.nnz_L * static_cast<double>(columns);
}

Eigen::MatrixXd compliance_by_solves(const SparseMatrixd& K_upper, int m,
                                     const ComplianceOptions& options, ComplianceStats* stats) {
  Eigen::MatrixXd G(m, m);
  compliance_by_solves(K_upper, m, options, G, stats);
  return G;
}

void compliance_by_solves(const SparseMatrixd& K_upper, int m, const ComplianceOptions& options,
                          Eigen::Ref<Eigen::MatrixXd> G, ComplianceStats* stats) {
  PALPATE_DEMAND(m > 0 && m <= K_upper.rows() && options.block_columns > 0);
  PALPATE_DEMAND(G.rows() == m && G.cols() == m);
  ComplianceStats local;
  if (!stats) stats = &local;
  SparseCholesky factor = single_threaded_factor(K_upper);
  stats->factor = factor.info();

  const auto t0 = std::chrono::steady_clock::now();
  const int block = std::min(options.block_columns, m);
  std::vector<int> blocks((m + block - 1) / block);
  std::iota(blocks.begin(), blocks.end(), 0);
  long done = 0;
  solve_blocks(K_upper, factor, m, block, blocks, {}, [&](const SolvedBlock& s) {
    if (options.on_block) options.on_block(s.first, s.columns);
    G.middleCols(s.first, s.columns.cols()) = s.columns;
    done += s.columns.cols();
    if (options.progress) options.progress(done, m);
  });
  stats->dense_seconds = seconds_since(t0);
  // Forward and backward substitution: 2 flops per nonzero of L each, per column.
  stats->dense_flops = 4.0 * stats->factor.nnz_L * m;
  check_columns(K_upper, factor, G, options.check_columns, stats);
}

Eigen::MatrixXd compliance_by_condensation(const SparseMatrixd& K_upper, int m,
                                           const ComplianceOptions& options,
                                           ComplianceStats* stats) {
  PALPATE_DEMAND(m > 0 && m <= K_upper.rows());
  ComplianceStats local;
  if (!stats) stats = &local;
  SparseCholesky factor(K_upper, condensation_ordering(K_upper, m));
  stats->factor = factor.info();
  if (options.progress) options.progress(1, 3);

  const auto t0 = std::chrono::steady_clock::now();
  Eigen::MatrixXd G(m, m);
  factor.trailing_factor_block(G);  // L_S, S = L_S L_Sᵀ
  if (options.progress) options.progress(2, 3);
  invert_from_cholesky(G);  // G_SS = S⁻¹ = L_S⁻ᵀ L_S⁻¹
  stats->dense_seconds = seconds_since(t0);
  stats->dense_flops = 2.0 * m * static_cast<double>(m) * m / 3.0;
  if (options.progress) options.progress(3, 3);
  check_columns(K_upper, factor, G, options.check_columns, stats);
  return G;
}

std::vector<int> condensation_ordering(const SparseMatrixd& K_upper, int m) {
  const int n = static_cast<int>(K_upper.rows());
  // Interior first in CHOLMOD's fill-reducing order of K_II, surface last in
  // compliance order: then the trailing block of L factors S exactly.
  std::vector<int> perm;
  perm.reserve(n);
  if (n > m) {
    const SparseMatrixd K_II = K_upper.bottomRightCorner(n - m, n - m);
    for (int p : SparseCholesky::fill_reducing_ordering(K_II)) perm.push_back(m + p);
  }
  for (int i = 0; i < m; ++i) perm.push_back(i);
  return perm;
}

double max_relative_difference(CRef<Eigen::MatrixXd> a, CRef<Eigen::MatrixXd> b) {
  PALPATE_DEMAND(a.rows() == b.rows() && a.cols() == b.cols());
  const double scale = a.cwiseAbs().maxCoeff();
  return scale > 0 ? (a - b).cwiseAbs().maxCoeff() / scale : (a - b).cwiseAbs().maxCoeff();
}

double symmetry_error(CRef<Eigen::MatrixXd> G) {
  PALPATE_DEMAND(G.rows() == G.cols());
  const double scale = G.cwiseAbs().maxCoeff();
  double worst = 0;
  // Column blocks keep the transposed access cache-friendly on large G.
  const Eigen::Index n = G.rows(), b = 256;
  for (Eigen::Index j = 0; j < n; j += b)
    for (Eigen::Index i = 0; i <= j; i += b) {
      const Eigen::Index h = std::min(b, n - i), w = std::min(b, n - j);
      worst = std::max(
          worst, (G.block(i, j, h, w) - G.block(j, i, w, h).transpose()).cwiseAbs().maxCoeff());
    }
  return scale > 0 ? worst / scale : worst;
}

Eigen::Matrix3Xd diagonal_blocks(CRef<Eigen::MatrixXd> G) {
  PALPATE_DEMAND(G.rows() == G.cols() && G.rows() % 3 == 0);
  Eigen::Matrix3Xd blocks(3, G.cols());
  for (Eigen::Index k = 0; 3 * k < G.rows(); ++k)
    blocks.middleCols<3>(3 * k) = G.block<3, 3>(3 * k, 3 * k);
  return blocks;
}

DiagonalBlockSpectrum diagonal_block_spectrum(CRef<Eigen::Matrix3Xd> blocks) {
  PALPATE_DEMAND(blocks.cols() % 3 == 0);
  DiagonalBlockSpectrum spectrum;
  const Eigen::Index n = blocks.cols() / 3;
  spectrum.largest.resize(n);
  spectrum.smallest = INFINITY;
  for (Eigen::Index k = 0; k < n; ++k) {
    const Eigen::Matrix3d B = blocks.middleCols<3>(3 * k);
    const Eigen::Matrix3d S = 0.5 * (B + B.transpose());
    const Eigen::Vector3d e =
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(S, Eigen::EigenvaluesOnly).eigenvalues();
    spectrum.largest[k] = e[2];
    // A NaN eigenvalue stays the smallest, so that the block is refused.
    if (std::isnan(e[0]) || (!std::isnan(spectrum.smallest) && e[0] < spectrum.smallest)) {
      spectrum.smallest = e[0];
      spectrum.smallest_at = static_cast<int>(k);
    }
  }
  return spectrum;
}

double min_diagonal_block_eigenvalue(CRef<Eigen::MatrixXd> G, int* vertex) {
  const DiagonalBlockSpectrum spectrum = diagonal_block_spectrum(diagonal_blocks(G));
  if (vertex) *vertex = spectrum.smallest_at;
  return spectrum.smallest;
}

Eigen::VectorXd diagonal_block_largest_eigenvalues(CRef<Eigen::MatrixXd> G) {
  return diagonal_block_spectrum(diagonal_blocks(G)).largest;
}

}  // namespace palpate
