#include "palpate/runtime/solve/incremental_factor.hpp"

#include <cblas.h>
#include <lapacke.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"

namespace palpate::detail {

IncrementalFactor::IncrementalFactor(int max_unknowns) : ld_(max_unknowns) {
  PALPATE_DEMAND(max_unknowns > 0);
  const auto m = static_cast<std::size_t>(max_unknowns);
  W_.resize(m * m);
  L_.resize(m * m);
  work_.resize(3 * m);
  iwork_.resize(m);
}

// The LAPACKE routines are the _work ones, column-major: LAPACK itself, no
// NaN scan, no allocation.

/// Extends L over the unknowns first … m−1, whose columns of W are written.
int IncrementalFactor::extend(int first) {
  const int m = size_;
  const int k = m - first;
  const int ld = ld_;
  const Strided W(W_.data(), m, m, Eigen::OuterStride<>(ld));
  Strided L(L_.data(), m, m, Eigen::OuterStride<>(ld));
  if (first > 0) {
    // By BLAS in place: Eigen's L21 L21ᵀ is a temporary on the heap past
    // 20 unknowns (its coefficient-wise product's threshold).
    L.block(first, 0, k, first) = W.block(first, 0, k, first);
    cblas_dtrsm(CblasColMajor, CblasRight, CblasLower, CblasTrans, CblasNonUnit, k, first, 1.0,
                &L(0, 0), ld, &L(first, 0), ld);
    L.block(first, first, k, k).triangularView<Eigen::Lower>() = W.block(first, first, k, k);
    cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, k, first, -1.0, &L(first, 0), ld, 1.0,
                &L(first, first), ld);
  } else {
    L.topLeftCorner(m, m).triangularView<Eigen::Lower>() = W.topLeftCorner(m, m);
  }
  const lapack_int info = LAPACKE_dpotrf_work(LAPACK_COL_MAJOR, 'L', k, &L(first, first), ld);
  PALPATE_DEMAND(info >= 0);
  return info;
}

double IncrementalFactor::condition_estimate() {
  const int m = size_;
  PALPATE_DEMAND(m > 0);
  const int ld = ld_;
  const Strided W(W_.data(), m, m, Eigen::OuterStride<>(ld));
  const double norm1 = W.cwiseAbs().colwise().sum().maxCoeff();
  double rcond = 0;
  const lapack_int info = LAPACKE_dpocon_work(LAPACK_COL_MAJOR, 'L', m, L_.data(), ld, norm1,
                                              &rcond, work_.data(), iwork_.data());
  PALPATE_DEMAND(info == 0);  // dpocon fails only on its arguments
  return rcond > 0 ? 1.0 / rcond : std::numeric_limits<double>::infinity();
}

void IncrementalFactor::remove(int p) {
  const int m = size_;
  PALPATE_DEMAND(p >= 0 && p < m);
  const int ld = ld_;
  Strided W(W_.data(), m, m, Eigen::OuterStride<>(ld));
  Strided L(L_.data(), m, m, Eigen::OuterStride<>(ld));
  for (int j = p; j + 1 < m; ++j) W.col(j) = W.col(j + 1);
  for (int j = 0; j + 1 < m; ++j)
    for (int i = p; i + 1 < m; ++i) W(i, j) = W(i + 1, j);
  for (int j = 0; j < m; ++j)
    for (int i = std::max(p, j - 1); i + 1 < m; ++i) L(i, j) = L(i + 1, j);
  for (int i = p; i + 1 < m; ++i) {
    const double a = L(i, i), b = L(i, i + 1);
    const double r = std::hypot(a, b);
    if (r == 0) continue;
    const double c = a / r, s = b / r;
    for (int t = i; t + 1 < m; ++t) {
      const double x = L(t, i), y = L(t, i + 1);
      L(t, i) = c * x + s * y;
      L(t, i + 1) = c * y - s * x;
    }
  }
  --size_;
}

int IncrementalFactor::solve(double* b, int columns) const {
  const int m = size_;
  return LAPACKE_dpotrs_work(LAPACK_COL_MAJOR, 'L', m, columns, L_.data(), ld_, b, m);
}

}  // namespace palpate::detail
