#pragma once
// Private to palpate_runtime: a sparse Cholesky factor L of a matrix whose
// DOFs come three to a vertex, stored by 3 × 3 blocks, and its solve
// L Lᵀ x = b. Eigen's scalar sparse triangular solves spend about 1 ns per
// entry of the factor on index work and dependent loads; by blocks, the
// index is read once per nine entries and each block is a fixed-size
// product (docs/model/hybrid-serving.md, "The implicit step": the interior's solves).

#include <Eigen/Core>
#include <vector>

namespace palpate::detail {

class VertexBlockFactor {
 public:
  VertexBlockFactor() = default;
  /// Keeps the 3 × 3 blocks of @p lower (a dense lower Cholesky factor,
  /// 3n × 3n, the strict upper triangle ignored) that hold a non-zero entry.
  /// A factor computed densely in a fill-reducing order has exact zeros
  /// outside its fill, so those are all the blocks a sparse one would have.
  explicit VertexBlockFactor(const Eigen::MatrixXd& lower);

  Eigen::Index size() const { return 3 * static_cast<Eigen::Index>(diagonal_.size()); }
  /// Off-diagonal blocks kept (the sparse factor's size, in blocks).
  std::size_t block_count() const { return blocks_.size(); }

  /// x ← (L Lᵀ)⁻¹ x, by block forward and backward substitution.
  /// Allocates nothing.
  void solve_in_place(Eigen::Ref<Eigen::VectorXd> x) const;

 private:
  std::vector<Eigen::Matrix3d> diagonal_;  // per vertex: L's lower-triangular diagonal block
  std::vector<int> column_start_;          // per vertex + 1: its first block below the diagonal
  std::vector<int> block_row_;             // per block: the vertex of its rows
  std::vector<Eigen::Matrix3d> blocks_;    // per block: L's block (rows block_row_, column vertex)
};

}  // namespace palpate::detail
