#pragma once
// Private to palpate_runtime: the Fortran BLAS and LAPACK routines the
// run-time code calls (OpenBLAS or the reference, linked as BLAS::BLAS and
// LAPACK::LAPACK), declared once.

extern "C" {
// LAPACK: Cholesky factor, solve, condition estimate, inverse.
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dpotrs_(const char* uplo, const int* n, const int* nrhs, const double* a, const int* lda,
             double* b, const int* ldb, int* info);
void dpocon_(const char* uplo, const int* n, const double* a, const int* lda, const double* anorm,
             double* rcond, double* work, int* iwork, int* info);
void dpotri_(const char* uplo, const int* n, double* a, const int* lda, int* info);
// LAPACK: a general system by LU with partial pivoting.
void dgesv_(const int* n, const int* nrhs, double* a, const int* lda, int* ipiv, double* b,
            const int* ldb, int* info);
// BLAS: triangular solve with many right-hand sides, symmetric rank-k
// update, general and symmetric matrix-vector products.
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const double* alpha, const double* a, const int* lda, double* b,
            const int* ldb);
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* beta, double* c, const int* ldc);
void dgemv_(const char* trans, const int* m, const int* n, const double* alpha, const double* a,
            const int* lda, const double* x, const int* incx, const double* beta, double* y,
            const int* incy);
void dsymv_(const char* uplo, const int* n, const double* alpha, const double* a, const int* lda,
            const double* x, const int* incx, const double* beta, double* y, const int* incy);
}
