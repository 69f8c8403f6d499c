// The interior's Cholesky factor by 3 × 3 vertex blocks
// (lib/runtime/src/vertex_block_factor): its solve against a dense one on
// a block-sparse SPD matrix of a grid's vertices, the blocks it keeps
// (exactly the fill of the order), and no allocation per solve.

#include "palpate/runtime/region/vertex_block_factor.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "support/allocation_counter.hpp"

namespace palpate::detail {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// A stiffness-like SPD matrix of an nx × ny grid of vertices, 3 DOFs each:
// a random symmetric 3 × 3 block per edge of the grid (4-neighbours), and
// diagonal blocks that dominate them. Its order is the grid's, row by row.
MatrixXd grid_matrix(int nx, int ny, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  const int n = nx * ny;
  MatrixXd a = MatrixXd::Zero(3 * n, 3 * n);
  const auto link = [&](int p, int q) {
    Eigen::Matrix3d k;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) k(i, j) = 1e3 * value(rng);
    a.block<3, 3>(3 * p, 3 * q) = k;
    a.block<3, 3>(3 * q, 3 * p) = k.transpose();
  };
  for (int y = 0; y < ny; ++y)
    for (int x = 0; x < nx; ++x) {
      if (x + 1 < nx) link(y * nx + x, y * nx + x + 1);
      if (y + 1 < ny) link(y * nx + x, (y + 1) * nx + x);
    }
  // Diagonally dominant by rows: SPD.
  for (int v = 0; v < n; ++v) {
    const double off = a.middleRows(3 * v, 3).cwiseAbs().sum();
    a.block<3, 3>(3 * v, 3 * v) = (off + 1e3) * Eigen::Matrix3d::Identity();
  }
  return a;
}

MatrixXd dense_factor(const MatrixXd& a) {
  Eigen::LLT<MatrixXd> llt(a);
  EXPECT_EQ(llt.info(), Eigen::Success);
  return llt.matrixL();
}

TEST(VertexBlockFactor, SolvesAsTheDenseFactorDoes) {
  const MatrixXd a = grid_matrix(7, 5, 1);
  const VertexBlockFactor factor(dense_factor(a));
  ASSERT_EQ(factor.size(), a.rows());
  std::mt19937 rng(2);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 5; ++trial) {
    VectorXd b(a.rows());
    for (auto& e : b) e = normal(rng);
    VectorXd x = b;
    factor.solve_in_place(x);
    const VectorXd reference = a.ldlt().solve(b);
    // Both backward stable; a's condition is below 1e2 (dominant diagonal).
    EXPECT_LE((x - reference).norm(), 1e-13 * reference.norm());
    EXPECT_LE((a * x - b).norm(), 1e-12 * b.norm());
  }
}

TEST(VertexBlockFactor, KeepsTheBlocksOfTheFillOnly) {
  // A chain of vertices (ny = 1) eliminated in order has no fill: its factor
  // has one block under each diagonal one but the last.
  const VertexBlockFactor chain(dense_factor(grid_matrix(12, 1, 3)));
  EXPECT_EQ(chain.block_count(), 11u);
  // A grid row by row fills the band: each vertex's column holds the nx
  // vertices after it (fewer at the end), far fewer than the dense lower half.
  const int nx = 6, ny = 6, n = nx * ny;
  const VertexBlockFactor grid(dense_factor(grid_matrix(nx, ny, 4)));
  std::size_t band = 0;
  for (int v = 0; v < n; ++v) band += static_cast<std::size_t>(std::min(nx, n - 1 - v));
  EXPECT_LE(grid.block_count(), band);
  EXPECT_GE(grid.block_count(), static_cast<std::size_t>(2 * n - nx - ny));  // the grid's edges
  EXPECT_LT(grid.block_count(), static_cast<std::size_t>(n * (n - 1) / 2) / 3);
}

TEST(VertexBlockFactor, ASolveAllocatesNothing) {
  const VertexBlockFactor factor(dense_factor(grid_matrix(5, 4, 5)));
  VectorXd x = VectorXd::Ones(factor.size());
  factor.solve_in_place(x);
  const std::uint64_t before = testing::allocations_here();
  for (int i = 0; i < 100; ++i) factor.solve_in_place(x);
  EXPECT_EQ(testing::allocations_here(), before);
  EXPECT_TRUE(x.allFinite());
}

}  // namespace
}  // namespace palpate::detail
