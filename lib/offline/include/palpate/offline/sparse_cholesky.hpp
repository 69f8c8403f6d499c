#pragma once
/// @file
/// Sparse Cholesky factorization of a symmetric positive definite matrix with
/// CHOLMOD (supernodal, on the BLAS): factor once, solve many. This header
/// does not include cholmod.h.

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/core/error.hpp"

namespace palpate {

/// The matrix is not positive definite: Cholesky failed at @c column (in the
/// numbering of the input matrix, not the factor's ordering).
class NotPositiveDefinite : public NumericalError {
 public:
  NotPositiveDefinite(int column, const std::string& message)
      : NumericalError(message), column_(column) {}
  int column() const { return column_; }

 private:
  int column_;
};

/// Facts about a factorization, for reports and benchmarks.
struct FactorInfo {
  std::string ordering;  ///< fill-reducing ordering CHOLMOD used ("amd", "metis", "given"...)
  double nnz_L = 0;      ///< nonzeros in L
  double flops = 0;      ///< floating-point operations of the numeric factorization
  double bytes = 0;      ///< memory held by the factor
  int supernodes = 0;
  double analyze_seconds = 0;
  double factor_seconds = 0;
};

/// A = L Lᵀ for a sparse SPD matrix A, held by CHOLMOD.
class SparseCholesky {
 public:
  /// Analyses and factors A, given by its upper triangle (CHOLMOD's symmetric
  /// storage), n × n.
  /// @param permutation empty: CHOLMOD chooses a fill-reducing ordering (AMD
  ///   or METIS, postordered). Otherwise the exact elimination order to keep
  ///   (no postordering), e.g. to eliminate some unknowns last.
  /// @throws NotPositiveDefinite with the column at which it failed.
  /// @throws ResourceError if CHOLMOD runs out of memory.
  explicit SparseCholesky(const SparseMatrixd& upper, std::span<const int> permutation = {});
  ~SparseCholesky();
  SparseCholesky(const SparseCholesky&) = delete;
  SparseCholesky& operator=(const SparseCholesky&) = delete;

  int rows() const;
  const FactorInfo& info() const;

  /// Scratch memory for solves; one per thread solving concurrently.
  class Workspace;
  struct WorkspaceDeleter {
    void operator()(Workspace* w) const;
  };
  using WorkspacePtr = std::unique_ptr<Workspace, WorkspaceDeleter>;
  WorkspacePtr make_workspace() const;

  /// X = A⁻¹ B for a dense block of right-hand sides (n × k): one blocked
  /// supernodal solve (BLAS-3), not k vector solves.
  void solve(CRef<Eigen::MatrixXd> B, Eigen::Ref<Eigen::MatrixXd> X);
  /// The same with the caller's workspace: threads may solve concurrently,
  /// each with its own workspace (the factor is only read).
  void solve(CRef<Eigen::MatrixXd> B, Eigen::Ref<Eigen::MatrixXd> X, Workspace& workspace) const;

  /// The elimination order: position p of the factor eliminates unknown perm[p].
  std::vector<int> permutation() const;

  /// Copies the trailing m × m block of L (the last m eliminated unknowns)
  /// into the lower triangle of @p out (m × m; the strict upper triangle is
  /// zeroed). When those are eliminated last, it is the Cholesky factor of
  /// the Schur complement on them.
  void trailing_factor_block(Eigen::Ref<Eigen::MatrixXd> out) const;

  /// CHOLMOD's fill-reducing ordering of a symmetric matrix (upper triangle)
  /// without factoring it.
  static std::vector<int> fill_reducing_ordering(const SparseMatrixd& upper);

  /// What factoring A would take, from a symbolic analysis only.
  struct Estimate {
    double bytes = 0;  ///< memory of the supernodal factor
    double nnz_L = 0;  ///< nonzeros of L
    double flops = 0;  ///< floating-point operations of the numeric factorization
  };
  /// Same @p permutation rules as the constructor.
  static Estimate estimate(const SparseMatrixd& upper, std::span<const int> permutation = {});
  /// estimate().bytes.
  static double estimate_factor_bytes(const SparseMatrixd& upper,
                                      std::span<const int> permutation = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  WorkspacePtr default_workspace_;
};

}  // namespace palpate
