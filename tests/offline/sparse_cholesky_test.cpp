// SparseCholesky (CHOLMOD) against dense references: solves against Eigen's
// dense LLT, blocked right-hand sides against column-by-column solves, a
// given elimination order kept, the trailing block of L against the
// Cholesky factor of the dense Schur complement, the failing column of an
// indefinite matrix against the pivots computed by hand, concurrent solves
// with their own workspaces, and the symbolic memory estimate.

#include "palpate/offline/sparse_cholesky.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace palpate {
namespace {

// The test matrices are strictly diagonally dominant with a margin of 1 on
// the diagonal: by Gershgorin their eigenvalues lie in [1, 2·r + 1], r the
// largest off-diagonal row sum (≤ ~2·per_row ≤ 12 here), so κ ≤ ~25 and a
// backward-stable solve is accurate to a few n·ε·κ ≈ 1e-12 relative at
// worst. 1e-11 leaves margin and still catches any wrong entry, ordering or
// transposition (errors of order 1).
constexpr double kSolveTolerance = 1e-11;

/// A random symmetric, strictly diagonally dominant (hence SPD) sparse
/// matrix: ~@p per_row off-diagonal entries per row in [-1, 1], the diagonal
/// the row's absolute sum plus 1. Dense, full symmetric.
Eigen::MatrixXd random_spd(int n, int per_row, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> column(0, n - 1);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < per_row; ++k) {
      const int j = column(rng);
      if (j == i) continue;
      A(i, j) = A(j, i) = value(rng);
    }
  for (int i = 0; i < n; ++i) A(i, i) = A.row(i).cwiseAbs().sum() + 1.0;
  return A;
}

/// The upper triangle of a dense symmetric matrix, compressed (CHOLMOD's input).
SparseMatrixd upper(const Eigen::MatrixXd& A) {
  SparseMatrixd S = A.triangularView<Eigen::Upper>().toDenseMatrix().sparseView();
  S.makeCompressed();
  return S;
}

/// The whole symmetric matrix, compressed (both triangles stored).
SparseMatrixd full(const Eigen::MatrixXd& A) {
  SparseMatrixd S = A.sparseView();
  S.makeCompressed();
  return S;
}

double relative(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / b.norm();
}

Eigen::MatrixXd random_matrix(int rows, int cols, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  Eigen::MatrixXd M(rows, cols);
  for (Eigen::Index j = 0; j < M.cols(); ++j)
    for (Eigen::Index i = 0; i < M.rows(); ++i) M(i, j) = value(rng);
  return M;
}

std::vector<int> shuffled(int n, std::uint32_t seed) {
  std::vector<int> p(static_cast<std::size_t>(n));
  std::iota(p.begin(), p.end(), 0);
  std::mt19937 rng(seed);
  std::shuffle(p.begin(), p.end(), rng);
  return p;
}

bool is_permutation_of_range(std::vector<int> p, int n) {
  if (static_cast<int>(p.size()) != n) return false;
  std::sort(p.begin(), p.end());
  for (int i = 0; i < n; ++i)
    if (p[static_cast<std::size_t>(i)] != i) return false;
  return true;
}

TEST(SparseCholesky, SolvesLikeADenseCholesky) {
  const int n = 60;
  const Eigen::MatrixXd A = random_spd(n, 4, 1);
  const Eigen::MatrixXd B = random_matrix(n, 3, 2);
  const Eigen::MatrixXd reference = Eigen::LLT<Eigen::MatrixXd>(A).solve(B);

  SparseCholesky chol(upper(A));
  EXPECT_EQ(chol.rows(), n);
  EXPECT_TRUE(is_permutation_of_range(chol.permutation(), n));
  EXPECT_GT(chol.info().nnz_L, n - 1);  // at least the diagonal
  Eigen::MatrixXd X(n, 3);
  chol.solve(B, X);
  EXPECT_LT(relative(X, reference), kSolveTolerance);
  // The residual itself, independently of the reference.
  EXPECT_LT(relative(A * X, B), kSolveTolerance);
}

TEST(SparseCholesky, ReadsOnlyTheUpperTriangle) {
  // CHOLMOD's symmetric storage: the strict lower triangle, if present, is
  // ignored. Garbage there changes nothing.
  const int n = 30;
  const Eigen::MatrixXd A = random_spd(n, 3, 3);
  Eigen::MatrixXd garbage = A;
  garbage.triangularView<Eigen::StrictlyLower>().setConstant(1e3);
  const Eigen::MatrixXd B = random_matrix(n, 2, 4);
  SparseCholesky from_upper(upper(A));
  SparseCholesky from_full(full(garbage));
  Eigen::MatrixXd X1(n, 2), X2(n, 2);
  from_upper.solve(B, X1);
  from_full.solve(B, X2);
  EXPECT_LT(relative(X2, X1), kSolveTolerance);
  EXPECT_LT(relative(A * X2, B), kSolveTolerance);
}

TEST(SparseCholesky, ABlockOfRightHandSidesEqualsColumnByColumnSolves) {
  const int n = 80, k = 7;
  const Eigen::MatrixXd A = random_spd(n, 5, 5);
  const Eigen::MatrixXd B = random_matrix(n, k, 6);
  SparseCholesky chol(upper(A));
  Eigen::MatrixXd X(n, k);
  chol.solve(B, X);
  for (int j = 0; j < k; ++j) {
    Eigen::MatrixXd x(n, 1);
    chol.solve(B.col(j), x);
    // The blocked (BLAS-3) and the vector solve use the same factor; they
    // may sum in another order, so they agree to round-off, not bits.
    EXPECT_LT(relative(X.col(j), x), kSolveTolerance) << "column " << j;
  }
  // Strided views: B a block of a taller matrix (outer stride ≠ n, copied
  // by the solver) and X a block of a wider one.
  Eigen::MatrixXd tall = Eigen::MatrixXd::Constant(n + 5, k, std::nan(""));
  tall.topRows(n) = B;
  Eigen::MatrixXd wide = Eigen::MatrixXd::Constant(n + 3, k + 2, -7.0);
  chol.solve(tall.topRows(n), wide.block(1, 1, n, k));
  EXPECT_EQ(wide.block(1, 1, n, k), X) << "the same solve, the same bits";
  EXPECT_TRUE((wide.row(0).array() == -7.0).all()) << "nothing written outside X";
  EXPECT_TRUE((wide.col(0).array() == -7.0).all());
  EXPECT_TRUE((wide.bottomRows(2).array() == -7.0).all());
}

TEST(SparseCholesky, KeepsAGivenEliminationOrder) {
  const int n = 50;
  const Eigen::MatrixXd A = random_spd(n, 4, 7);
  const std::vector<int> order = shuffled(n, 8);
  SparseCholesky chol(upper(A), order);
  EXPECT_EQ(chol.permutation(), order);
  EXPECT_EQ(chol.info().ordering, "given");
  const Eigen::MatrixXd B = random_matrix(n, 2, 9);
  Eigen::MatrixXd X(n, 2);
  chol.solve(B, X);
  EXPECT_LT(relative(X, Eigen::LLT<Eigen::MatrixXd>(A).solve(B)), kSolveTolerance);
}

TEST(SparseCholesky, FillReducingOrderingIsAPermutation) {
  const int n = 40;
  const Eigen::MatrixXd A = random_spd(n, 3, 10);
  EXPECT_TRUE(is_permutation_of_range(SparseCholesky::fill_reducing_ordering(upper(A)), n));
}

TEST(SparseCholesky, TrailingBlockIsTheCholeskyFactorOfTheSchurComplement) {
  // Eliminate the unknowns T last, in the order listed: the trailing m × m
  // block of L is chol(S), S = A_TT − A_TO A_OO⁻¹ A_OT, rows and columns in
  // T's order (computed densely here, the textbook way).
  const int n = 45;
  const Eigen::MatrixXd A = random_spd(n, 5, 11);
  const std::vector<int> last = {3, 17, 5, 29, 11, 0, 44};
  const int m = static_cast<int>(last.size());
  std::vector<int> order;
  for (int i = 0; i < n; ++i)
    if (std::find(last.begin(), last.end(), i) == last.end()) order.push_back(i);
  const std::vector<int> others = order;
  order.insert(order.end(), last.begin(), last.end());

  auto pick = [&](const std::vector<int>& rows, const std::vector<int>& cols) {
    Eigen::MatrixXd M(rows.size(), cols.size());
    for (std::size_t i = 0; i < rows.size(); ++i)
      for (std::size_t j = 0; j < cols.size(); ++j)
        M(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = A(rows[i], cols[j]);
    return M;
  };
  const Eigen::MatrixXd S =
      pick(last, last) -
      pick(last, others) *
          Eigen::LLT<Eigen::MatrixXd>(pick(others, others)).solve(pick(others, last));
  const Eigen::MatrixXd reference = Eigen::LLT<Eigen::MatrixXd>(S).matrixL();

  SparseCholesky chol(upper(A), order);
  ASSERT_EQ(chol.permutation(), order);
  Eigen::MatrixXd trailing = Eigen::MatrixXd::Constant(m, m, std::nan(""));
  chol.trailing_factor_block(trailing);
  EXPECT_LT(relative(trailing, reference), kSolveTolerance) << trailing << "\n\n" << reference;
  EXPECT_TRUE(trailing.triangularView<Eigen::StrictlyUpper>().toDenseMatrix().isZero(0))
      << "the strict upper triangle is zeroed";
  // L Lᵀ of the block gives back S.
  EXPECT_LT(relative(trailing * trailing.transpose(), S), kSolveTolerance);
}

TEST(SparseCholesky, ANegativePivotIsReportedAtItsColumnWhateverTheOrdering) {
  // A diagonally dominant SPD matrix whose unknown c has a negative diagonal:
  // every pivot before c is that of an SPD principal submatrix (positive),
  // and c's pivot is A_cc minus a non-negative quantity (negative). So the
  // factorization fails at c, in any elimination order.
  const int n = 40, c = 23;
  Eigen::MatrixXd A = random_spd(n, 4, 12);
  A(c, c) = -1.0;
  for (const bool given : {false, true}) {
    const std::vector<int> order = given ? shuffled(n, 13) : std::vector<int>{};
    try {
      SparseCholesky chol(upper(A), order);
      ADD_FAILURE() << "no NotPositiveDefinite, given order " << given;
    } catch (const NotPositiveDefinite& e) {
      EXPECT_EQ(e.column(), c) << "given order " << given;
      EXPECT_NE(std::string(e.what()).find("column " + std::to_string(c)), std::string::npos)
          << e.what();
    }
  }
}

TEST(SparseCholesky, AnIndefiniteMatrixFailsWhereItsLeadingPivotTurnsNonPositive) {
  // T = tridiag(−1, d, −1) with d = 2 − σ has pivots p₁ = d, p_k = d − 1/p_{k−1}:
  // the first k with p_k ≤ 0 is where Cholesky in T's order fails. The
  // unknowns are renumbered by a random permutation q (unknown q[k] is T's
  // k-th) and eliminated in that order, so the failure is at column q[k].
  const int n = 30;
  const double d = 2.0 - 0.05;  // σ above T's smallest eigenvalue 2 − 2cos(π/31) ≈ 0.0103
  std::vector<double> pivot(static_cast<std::size_t>(n));
  int failing = -1;
  for (int k = 0; k < n; ++k) {
    pivot[static_cast<std::size_t>(k)] =
        k == 0 ? d : d - 1.0 / pivot[static_cast<std::size_t>(k - 1)];
    if (pivot[static_cast<std::size_t>(k)] <= 0) {
      failing = k;
      break;
    }
  }
  ASSERT_GT(failing, 2) << "the failure is not at the start";
  ASSERT_LT(failing, n - 1) << "nor at the end";

  const std::vector<int> q = shuffled(n, 14);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
  for (int k = 0; k < n; ++k) {
    A(q[k], q[k]) = d;
    if (k + 1 < n) A(q[k], q[k + 1]) = A(q[k + 1], q[k]) = -1.0;
  }
  try {
    SparseCholesky chol(upper(A), q);
    ADD_FAILURE() << "no NotPositiveDefinite";
  } catch (const NotPositiveDefinite& e) {
    EXPECT_EQ(e.column(), q[static_cast<std::size_t>(failing)])
        << "T's pivot " << failing << " fails; CHOLMOD says column " << e.column();
  }
}

TEST(SparseCholesky, ThreadsWithTheirOwnWorkspacesSolveConcurrentlyAsOneDoes) {
  const int n = 120, k = 5;
  const Eigen::MatrixXd A = random_spd(n, 6, 15);
  SparseCholesky chol(upper(A));
  const Eigen::MatrixXd B1 = random_matrix(n, k, 16), B2 = random_matrix(n, k, 17);
  // One thread, in turn.
  Eigen::MatrixXd X1(n, k), X2(n, k);
  chol.solve(B1, X1);
  chol.solve(B2, X2);
  // Two threads at once, each with its workspace, many times (the factor is
  // only read): the same code on the same data gives the same bits.
  constexpr int kRounds = 200;
  auto run = [&](const Eigen::MatrixXd& B, const Eigen::MatrixXd& expected, int* mismatches) {
    auto workspace = chol.make_workspace();
    Eigen::MatrixXd X(n, k);
    for (int r = 0; r < kRounds; ++r) {
      X.setConstant(std::nan(""));
      std::as_const(chol).solve(B, X, *workspace);
      if (X != expected) ++*mismatches;
    }
  };
  int mismatches1 = 0, mismatches2 = 0;
  std::thread t1(run, std::cref(B1), std::cref(X1), &mismatches1);
  std::thread t2(run, std::cref(B2), std::cref(X2), &mismatches2);
  t1.join();
  t2.join();
  EXPECT_EQ(mismatches1, 0);
  EXPECT_EQ(mismatches2, 0);
  EXPECT_LT(relative(A * X1, B1), kSolveTolerance);
}

TEST(SparseCholesky, EstimatesTheFactorsMemoryFromTheSymbolicAnalysis) {
  const int n = 200;
  const Eigen::MatrixXd A = random_spd(n, 5, 18);
  const SparseMatrixd U = upper(A);
  for (const bool given : {false, true}) {
    const std::vector<int> order = given ? shuffled(n, 19) : std::vector<int>{};
    const double estimate = SparseCholesky::estimate_factor_bytes(U, order);
    SparseCholesky chol(U, order);
    const double held = chol.info().bytes;
    EXPECT_GT(estimate, 0) << "given order " << given;
    EXPECT_GT(held, 0);
    // At least the values of L: nnz(L) doubles.
    EXPECT_GE(held, 8.0 * chol.info().nnz_L);
    // "Of the order of": the same symbolic analysis, so within a factor of 2.
    EXPECT_GE(estimate, 0.5 * held) << "given order " << given;
    EXPECT_LE(estimate, 2.0 * held) << "given order " << given;
  }
}

}  // namespace
}  // namespace palpate
