#pragma once
/// @file
/// Short aliases for the Eigen types palpate passes around.

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace palpate {

/// Read-only view of any Eigen expression with storage (blocks included).
template <typename T>
using CRef = const Eigen::Ref<const T>&;

using Matrix12d = Eigen::Matrix<double, 12, 12>;
using Matrix43d = Eigen::Matrix<double, 4, 3>;
using SparseMatrixd = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

}  // namespace palpate
