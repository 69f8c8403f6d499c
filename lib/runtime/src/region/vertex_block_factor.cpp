#include "palpate/runtime/region/vertex_block_factor.hpp"

#include "palpate/core/error.hpp"

namespace palpate::detail {

using Eigen::Index;
using Eigen::Matrix3d;
using Eigen::Vector3d;

VertexBlockFactor::VertexBlockFactor(const Eigen::MatrixXd& lower) {
  PALPATE_DEMAND(lower.rows() == lower.cols() && lower.rows() % 3 == 0);
  const Index n = lower.rows() / 3;
  diagonal_.resize(static_cast<std::size_t>(n));
  column_start_.assign(static_cast<std::size_t>(n) + 1, 0);
  for (Index j = 0; j < n; ++j) {
    Matrix3d d = lower.block<3, 3>(3 * j, 3 * j);
    d.triangularView<Eigen::StrictlyUpper>().setZero();
    diagonal_[static_cast<std::size_t>(j)] = d;
    for (Index i = j + 1; i < n; ++i) {
      const auto block = lower.block<3, 3>(3 * i, 3 * j);
      if ((block.array() != 0).any()) {
        block_row_.push_back(static_cast<int>(i));
        blocks_.emplace_back(block);
      }
    }
    column_start_[static_cast<std::size_t>(j) + 1] = static_cast<int>(blocks_.size());
  }
}

namespace {
// y = D⁻¹ b and y = D⁻ᵀ b for a lower-triangular 3 × 3 D.
Vector3d lower_solve(const Matrix3d& d, const Vector3d& b) {
  Vector3d y;
  y[0] = b[0] / d(0, 0);
  y[1] = (b[1] - d(1, 0) * y[0]) / d(1, 1);
  y[2] = (b[2] - d(2, 0) * y[0] - d(2, 1) * y[1]) / d(2, 2);
  return y;
}
Vector3d lower_transpose_solve(const Matrix3d& d, const Vector3d& b) {
  Vector3d y;
  y[2] = b[2] / d(2, 2);
  y[1] = (b[1] - d(2, 1) * y[2]) / d(1, 1);
  y[0] = (b[0] - d(1, 0) * y[1] - d(2, 0) * y[2]) / d(0, 0);
  return y;
}
}  // namespace

void VertexBlockFactor::solve_in_place(Eigen::Ref<Eigen::VectorXd> x) const {
  PALPATE_DEMAND(x.size() == size());
  const auto n = static_cast<int>(diagonal_.size());
  // L y = b, column by column: y_j, then its part out of the rows below.
  for (int j = 0; j < n; ++j) {
    const Vector3d y = lower_solve(diagonal_[j], x.segment<3>(3 * j));
    x.segment<3>(3 * j) = y;
    for (int k = column_start_[j]; k < column_start_[j + 1]; ++k)
      x.segment<3>(3 * block_row_[k]).noalias() -= blocks_[k] * y;
  }
  // Lᵀ x = y, from the last vertex: the rows below are known.
  for (int j = n - 1; j >= 0; --j) {
    Vector3d t = x.segment<3>(3 * j);
    for (int k = column_start_[j]; k < column_start_[j + 1]; ++k)
      t.noalias() -= blocks_[k].transpose() * x.segment<3>(3 * block_row_[k]);
    x.segment<3>(3 * j) = lower_transpose_solve(diagonal_[j], t);
  }
}

}  // namespace palpate::detail
