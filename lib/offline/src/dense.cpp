#include "palpate/offline/dense.hpp"

#include <fmt/format.h>

#include "palpate/core/error.hpp"

extern "C" {
void dpotri_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
            const double* beta, double* c, const int* ldc);
}

namespace palpate {

void invert_from_cholesky(Eigen::Ref<Eigen::MatrixXd> a) {
  PALPATE_DEMAND(a.rows() == a.cols());
  const int n = static_cast<int>(a.rows());
  const int lda = static_cast<int>(a.outerStride());
  int info = 0;
  dpotri_("L", &n, a.data(), &lda, &info);
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
  const double one = 1, zero = 0;
  dgemm_("N", "N", &m, &n, &k, &one, A.data(), &lda, B.data(), &ldb, &zero, C.data(), &ldc);
}

}  // namespace palpate
