#pragma once
/// @file
/// The surface compliance G_SS = (K⁻¹)_SS by the two methods of docs/model/compliance.md
/// ("Surface compliance"): 3N_S solves, and condensation (Schur complement).
///
/// The stiffness is numbered surface-first (fem.hpp, DofMap): DOFs [0, m) are
/// the m = 3N_S surface DOFs, [m, n) the interior ones. G_SS is m × m in that
/// order: G(3a+i, 3b+j) is the displacement (m) of compliance vertex a along
/// axis i per newton on vertex b along axis j.

#include <functional>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/offline/sparse_cholesky.hpp"

namespace palpate {

/// Progress of a long phase: done out of total units.
using ProgressFn = std::function<void(long done, long total)>;

/// Threads the `solves` method runs its column blocks on: one per core this
/// process may run on (its CPU affinity, e.g. a Slurm task's cores).
int solve_threads();

struct ComplianceOptions {
  /// Right-hand sides per blocked solve in the `solves` method (BLAS-3 work).
  int block_columns = 64;
  /// Columns of G re-solved and checked against K u = e (spread over the surface).
  int check_columns = 6;
  ProgressFn progress;  ///< optional
  /// `solves` only, optional: sees each block of columns [first, first + k)
  /// of G before it is stored (to compare it with another method's G in the
  /// same memory).
  std::function<void(int first, CRef<Eigen::MatrixXd> block)> on_block;
};

/// What a method did and how well: times, work, and the sampled checks.
struct ComplianceStats {
  FactorInfo factor;
  double dense_seconds = 0;  ///< blocked solves, or the dense inversion of S
  double dense_flops = 0;    ///< floating-point operations of that phase
  double check_seconds = 0;
  /// max over sampled columns j of ‖K u − e_j‖ / ‖e_j‖, u the full solution.
  double max_residual = 0;
  /// max over sampled j of ‖u_S − G(:, j)‖ / ‖G(:, j)‖: the stored column
  /// against a fresh solve with the same factor.
  double max_column_mismatch = 0;
  std::vector<int> checked_columns;
};

/// G_SS by 3N_S solves: factor K once (fill-reducing ordering), solve K U = E
/// for blocks of unit right-hand sides e_(k,d), keep the surface rows.
/// @param K_upper n × n stiffness, upper triangle, surface-first numbering
/// @param surface_dofs m = 3N_S
/// @param G m × m output; may hold another method's G, which on_block sees
///   block by block before it is overwritten.
/// @throws NotPositiveDefinite (column in K's numbering)
void compliance_by_solves(const SparseMatrixd& K_upper, int surface_dofs,
                          const ComplianceOptions& options, Eigen::Ref<Eigen::MatrixXd> G,
                          ComplianceStats* stats);
/// Same, into a new matrix.
Eigen::MatrixXd compliance_by_solves(const SparseMatrixd& K_upper, int surface_dofs,
                                     const ComplianceOptions& options, ComplianceStats* stats);

/// One sampled column re-solved alone: ‖K u − e_j‖ and ‖u_S − G(:, j)‖ / ‖G(:, j)‖.
struct ColumnCheck {
  int column = 0;
  double residual = 0;
  double mismatch = 0;
};

/// A block of solved columns of G: G(:, first + i) = columns.col(i).
struct SolvedBlock {
  int index = 0;                    ///< block number: columns [index · block_columns, ...)
  int first = 0;                    ///< first column of G
  CRef<Eigen::MatrixXd> columns;    ///< m × width, m/N
  std::vector<ColumnCheck> checks;  ///< the sampled columns that fall in this block
};

/// The columns of G in blocks aligned to absolute column indices: block b is
/// columns [b·B, min((b+1)·B, m)), B = @p block_columns, solved as one
/// blocked supernodal solve on single-threaded BLAS. So column j of G is
/// the same bits whichever blocks a run solves (a shard, a resumed run, the
/// whole matrix): it depends only on K and B.
/// @param blocks the block numbers to solve (any subset, any order)
/// @param check_columns columns to re-solve alone and check when their block is solved
/// @param sink receives each solved block, one call at a time (serialized), from
///   the solving threads; it may throw (the solve stops and rethrows)
/// @param on_factored optional: called once the factor is ready, with its facts
/// @throws NotPositiveDefinite (column in K's numbering)
void solve_compliance_blocks(const SparseMatrixd& K_upper, int surface_dofs, int block_columns,
                             const std::vector<int>& blocks, const std::vector<int>& check_columns,
                             const std::function<void(const SolvedBlock&)>& sink,
                             ComplianceStats* stats,
                             const std::function<void(const FactorInfo&)>& on_factored = {});

/// Columns to check, spread evenly over [0, m), always including both ends.
std::vector<int> sample_columns(int m, int count);

/// G_SS by condensation: G_SS = (K_SS − K_SI K_II⁻¹ K_IS)⁻¹. K is factored
/// with the interior eliminated first (CHOLMOD's ordering of K_II) and the
/// surface last, so the trailing m × m block of L is the Cholesky factor of
/// the Schur complement S; then G_SS = S⁻¹ from that factor (LAPACK dpotri).
/// @throws NotPositiveDefinite (column in K's numbering)
Eigen::MatrixXd compliance_by_condensation(const SparseMatrixd& K_upper, int surface_dofs,
                                           const ComplianceOptions& options,
                                           ComplianceStats* stats);

/// The elimination order condensation uses: the interior DOFs [m, n) in
/// CHOLMOD's fill-reducing order of K_II, then the surface DOFs 0..m−1.
std::vector<int> condensation_ordering(const SparseMatrixd& K_upper, int surface_dofs);

/// max|A − B| / max|A|: the relative difference of two compliances.
double max_relative_difference(CRef<Eigen::MatrixXd> a, CRef<Eigen::MatrixXd> b);

/// max|G − Gᵀ| / max|G|.
double symmetry_error(CRef<Eigen::MatrixXd> G);

/// The eigenvalues of the 3 × 3 diagonal blocks G^kk that decide whether a
/// compliance is sound and how soft each vertex is. The blocks are
/// symmetrized first: the eigenvalues of the symmetric part decide
/// definiteness, and G from `solves` is symmetric only to round-off.
struct DiagonalBlockSpectrum {
  /// Softness of each compliance vertex: the largest eigenvalue λ_max (m/N)
  /// of its block. For a force f on vertex k alone, the vertex moves by
  /// u_k = G^kk f, and
  ///
  ///     max over ‖f‖ = 1 N of ‖u_k‖ = λ_max(G^kk)      (G^kk symmetric positive definite)
  ///
  /// so it is the largest displacement (m) one newton at that vertex can
  /// produce there. n values, compliance order.
  Eigen::VectorXd largest;
  double smallest = 0;  ///< smallest eigenvalue over every block, m/N (> 0 for a sound G)
  int smallest_at = 0;  ///< the compliance index where it occurs
};

/// The diagonal blocks of a 3n × 3n compliance side by side, 3 × 3n:
/// columns 3k..3k+2 hold G^kk.
Eigen::Matrix3Xd diagonal_blocks(CRef<Eigen::MatrixXd> G);

/// The spectrum of the diagonal blocks @p blocks (3 × 3n, as
/// diagonal_blocks() lays them; float64, before any storage rounding).
/// n 3 × 3 symmetric eigenproblems: cheap next to G.
DiagonalBlockSpectrum diagonal_block_spectrum(CRef<Eigen::Matrix3Xd> blocks);

/// Smallest eigenvalue (m/N) of the 3 × 3 diagonal blocks G^kk, over all k;
/// *vertex receives the compliance index where it occurs
/// (diagonal_block_spectrum()).
double min_diagonal_block_eigenvalue(CRef<Eigen::MatrixXd> G, int* vertex = nullptr);

/// The softness of each compliance vertex (DiagonalBlockSpectrum::largest),
/// m/N, compliance order.
Eigen::VectorXd diagonal_block_largest_eigenvalues(CRef<Eigen::MatrixXd> G);

}  // namespace palpate
