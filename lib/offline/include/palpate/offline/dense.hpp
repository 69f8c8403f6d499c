#pragma once
/// @file
/// The few dense LAPACK/BLAS kernels palpate calls directly (on the optimized
/// BLAS the system provides, OpenBLAS on Debian).

#include "palpate/core/eigen.hpp"

namespace palpate {

/// Given the lower Cholesky factor L of an SPD matrix S = L Lᵀ in the lower
/// triangle of @p a (n × n, column-major), overwrites @p a with S⁻¹, both
/// triangles (LAPACK dpotri, then a mirror). About 2n³/3 flops.
/// @throws NumericalError if L has a zero on its diagonal.
void invert_from_cholesky(Eigen::Ref<Eigen::MatrixXd> a);

/// C = A B with the BLAS dgemm (for measuring the machine's dense rate).
void blas_gemm(CRef<Eigen::MatrixXd> A, CRef<Eigen::MatrixXd> B, Eigen::Ref<Eigen::MatrixXd> C);

}  // namespace palpate
