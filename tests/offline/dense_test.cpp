// The dense LAPACK/BLAS kernels palpate calls directly (offline/dense.hpp).
#include "palpate/offline/dense.hpp"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Dense>

#include "palpate/core/error.hpp"

namespace palpate {
namespace {

TEST(Dense, InverseFromCholeskyFactor) {
  Eigen::MatrixXd R = Eigen::MatrixXd::Random(40, 40);
  const Eigen::MatrixXd S = R * R.transpose() + 40 * Eigen::MatrixXd::Identity(40, 40);
  Eigen::MatrixXd a = Eigen::LLT<Eigen::MatrixXd>(S).matrixL();
  invert_from_cholesky(a);
  // ‖S S⁻¹ − I‖: S is well conditioned (eigenvalues in [40, ~200]), so
  // round-off of a few hundred ε.
  EXPECT_LT((S * a - Eigen::MatrixXd::Identity(40, 40)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ((a - a.transpose()).cwiseAbs().maxCoeff(), 0.0) << "both triangles, mirrored";
}

TEST(Dense, ZeroOnTheDiagonalOfTheFactorIsRefused) {
  Eigen::MatrixXd a = Eigen::MatrixXd::Identity(3, 3);
  a(1, 1) = 0;
  EXPECT_THROW(invert_from_cholesky(a), NumericalError);
}

TEST(Dense, GemmIsTheProduct) {
  const Eigen::MatrixXd A = Eigen::MatrixXd::Random(30, 20), B = Eigen::MatrixXd::Random(20, 10);
  Eigen::MatrixXd C(30, 10);
  blas_gemm(A, B, C);
  EXPECT_LT((C - A * B).cwiseAbs().maxCoeff(), 1e-13);
}

}  // namespace
}  // namespace palpate
