#include "palpate/offline/dense.hpp"

#include <cblas.h>
#include <fmt/format.h>
#include <lapacke.h>

#include "palpate/core/error.hpp"

namespace palpate {

void invert_from_cholesky(Eigen::Ref<Eigen::MatrixXd> a) {
  PALPATE_DEMAND(a.rows() == a.cols());
  const int n = static_cast<int>(a.rows());
  const int lda = static_cast<int>(a.outerStride());
  // The _work routine: LAPACK's dpotri itself, without LAPACKE's NaN scan.
  const lapack_int info = LAPACKE_dpotri_work(LAPACK_COL_MAJOR, 'L', n, a.data(), lda);
  if (info > 0)
    throw NumericalError(fmt::format("the Cholesky factor has a zero pivot at row {}", info - 1));
  PALPATE_DEMAND(info == 0);
  a.triangularView<Eigen::StrictlyUpper>() = a.transpose();
}

void blas_gemm(CRef<Eigen::MatrixXd> A, CRef<Eigen::MatrixXd> B, Eigen::Ref<Eigen::MatrixXd> C) {
  PALPATE_DEMAND(A.cols() == B.rows() && C.rows() == A.rows() && C.cols() == B.cols());
  const int m = static_cast<int>(A.rows()), n = static_cast<int>(B.cols()),
            k = static_cast<int>(A.cols());
  const int lda = static_cast<int>(A.outerStride()), ldb = static_cast<int>(B.outerStride()),
            ldc = static_cast<int>(C.outerStride());
  cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, m, n, k, 1.0, A.data(), lda, B.data(), ldb,
              0.0, C.data(), ldc);
}

}  // namespace palpate
