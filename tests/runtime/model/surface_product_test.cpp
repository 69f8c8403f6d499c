// The surface field u_S = G_SC f_C (surface_product.hpp): the row kernel
// against an extended-precision dense reference, for a float64 and a float32
// G; SplitSurfaceProduct against the one-thread kernel bit for bit, over a
// changing constrained set; no constraint, no displacement; and no heap
// allocation per product.

#include "palpate/runtime/surface_product.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <vector>

#include "support/allocation_counter.hpp"

namespace palpate {
namespace {

/// A random G of 3N × 3N entries ~1e-4 m/N of both signs (symmetric: G is;
/// the kernel reads columns, which for a symmetric G are its rows).
Eigen::MatrixXd random_G(int vertices, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-1e-4, 1e-4);
  const int n3 = 3 * vertices;
  Eigen::MatrixXd A(n3, n3);
  for (int j = 0; j < n3; ++j)
    for (int i = 0; i < n3; ++i) A(i, j) = value(rng);
  return 0.5 * (A + A.transpose());
}

struct Constraints {
  std::vector<int> indices;    // compliance vertices, distinct
  std::vector<double> forces;  // 3 per index, N
};

Constraints random_constraints(int vertices, int k, std::mt19937& rng) {
  std::vector<int> all(static_cast<std::size_t>(vertices));
  std::iota(all.begin(), all.end(), 0);
  std::shuffle(all.begin(), all.end(), rng);
  Constraints c;
  c.indices.assign(all.begin(), all.begin() + k);
  std::uniform_real_distribution<double> force(-2.0, 2.0);
  for (int j = 0; j < 3 * k; ++j) c.forces.push_back(force(rng));
  return c;
}

/// The dense product G(:, C) f in long double, and per row Σ|G(r, c)| |f_c|
/// (the scale of the round-off of any double summation order).
template <typename Matrix>
void reference(const Matrix& G, const Constraints& c, Eigen::VectorXd* u, Eigen::VectorXd* scale) {
  u->setZero(G.rows());
  scale->setZero(G.rows());
  for (Eigen::Index r = 0; r < G.rows(); ++r) {
    long double sum = 0, magnitude = 0;
    for (std::size_t j = 0; j < c.indices.size(); ++j)
      for (int d = 0; d < 3; ++d) {
        const long double g = static_cast<long double>(G(r, 3 * c.indices[j] + d));
        const long double f = c.forces[3 * j + static_cast<std::size_t>(d)];
        sum += g * f;
        magnitude += std::abs(g * f);
      }
    (*u)[r] = static_cast<double>(sum);
    (*scale)[r] = static_cast<double>(magnitude);
  }
}

/// Any order of summing the 3k products in double is within γ_{3k} =
/// 3k·ε/(1 − 3k·ε) of Σ|g f| of the exact sum (Higham, "Accuracy and
/// Stability", §3.1; products exact to ε each, the float32 entries widen to
/// double exactly); the long double reference is 2⁻¹¹ closer still. So
/// (3k + 2)·ε·Σ|g f| + the reference's own rounding bounds the difference.
template <typename Matrix>
void expect_dense_product(const Matrix& G, const Constraints& c, const Eigen::VectorXd& u) {
  Eigen::VectorXd exact, scale;
  reference(G, c, &exact, &scale);
  const double eps = std::numeric_limits<double>::epsilon();
  const double k3 = 3.0 * static_cast<double>(c.indices.size());
  ASSERT_EQ(u.size(), G.rows());
  for (Eigen::Index r = 0; r < u.size(); ++r)
    ASSERT_LE(std::abs(u[r] - exact[r]), (k3 + 2) * eps * scale[r] + eps * std::abs(exact[r]))
        << "row " << r << " of " << u.size() << ", k = " << c.indices.size();
}

bool same_bits(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

TEST(SurfaceProduct, RowsEqualTheDenseProductToRoundOff) {
  std::mt19937 rng(1);
  for (const int vertices : {1, 6, 37}) {
    const Eigen::MatrixXd G = random_G(vertices, 2 + static_cast<std::uint32_t>(vertices));
    const Eigen::MatrixXf G32 = G.cast<float>();
    for (const int k : {1, std::min(vertices, 3), vertices}) {
      const Constraints c = random_constraints(vertices, k, rng);
      Eigen::VectorXd u = Eigen::VectorXd::Constant(G.rows(), std::nan(""));
      surface_displacement_rows(G, c.indices, c.forces.data(), 0, G.rows(), u.data());
      expect_dense_product(G, c, u);
      Eigen::VectorXd u32 = Eigen::VectorXd::Constant(G.rows(), std::nan(""));
      surface_displacement_rows(G32, c.indices, c.forces.data(), 0, G.rows(), u32.data());
      expect_dense_product(G32, c, u32);  // G32's own values: the sums are in double
    }
  }
}

TEST(SurfaceProduct, RowsWritesOnlyItsRowRange) {
  std::mt19937 rng(3);
  const Eigen::MatrixXd G = random_G(10, 4);
  const Constraints c = random_constraints(10, 4, rng);
  Eigen::VectorXd whole(G.rows());
  surface_displacement_rows(G, c.indices, c.forces.data(), 0, G.rows(), whole.data());
  Eigen::VectorXd part = Eigen::VectorXd::Constant(G.rows(), -5.0);
  surface_displacement_rows(G, c.indices, c.forces.data(), 7, 19, part.data());
  EXPECT_TRUE((part.head(7).array() == -5.0).all());
  EXPECT_TRUE((part.tail(G.rows() - 19).array() == -5.0).all());
  EXPECT_TRUE(same_bits(part.segment(7, 12), whole.segment(7, 12)));
}

TEST(SurfaceProduct, TwoThreadsGiveTheOneThreadBitsOverAChangingConstrainedSet) {
  // Each row is computed by the same kernel, the same sum in the same order,
  // on whichever thread (the split is on a cache-line boundary): bit for bit.
  std::mt19937 rng(5);
  SplitSurfaceProduct split;
  for (const int vertices : {1, 5, 6, 37, 64}) {  // 3N < 16 (one thread does all), ≥ 16, odd halves
    const Eigen::MatrixXd G = random_G(vertices, 6 + static_cast<std::uint32_t>(vertices));
    const Eigen::MatrixXf G32 = G.cast<float>();
    std::uniform_int_distribution<int> size(0, std::min(vertices, 12));
    for (int round = 0; round < 12; ++round) {
      const Constraints c = random_constraints(vertices, size(rng), rng);
      Eigen::VectorXd one(G.rows()), two = Eigen::VectorXd::Constant(G.rows(), std::nan(""));
      surface_displacement_rows(G, c.indices, c.forces.data(), 0, G.rows(), one.data());
      split(G, c.indices, c.forces.data(), two);
      EXPECT_TRUE(same_bits(one, two)) << vertices << " vertices, round " << round;
      expect_dense_product(G, c, two);
      // The same product object alternating with a float32 G.
      Eigen::VectorXd one32(G.rows()), two32 = Eigen::VectorXd::Constant(G.rows(), std::nan(""));
      surface_displacement_rows(G32, c.indices, c.forces.data(), 0, G.rows(), one32.data());
      split(G32, c.indices, c.forces.data(), two32);
      EXPECT_TRUE(same_bits(one32, two32)) << vertices << " vertices, round " << round;
      expect_dense_product(G32, c, two32);
    }
  }
}

TEST(SurfaceProduct, NoConstraintGivesNoDisplacement) {
  const Eigen::MatrixXd G = random_G(20, 7);
  const Eigen::MatrixXf G32 = G.cast<float>();
  const std::vector<int> none;
  Eigen::VectorXd u = Eigen::VectorXd::Constant(G.rows(), std::nan(""));
  surface_displacement_rows(G, none, nullptr, 0, G.rows(), u.data());
  EXPECT_TRUE(u.isZero(0)) << u.transpose();
  SplitSurfaceProduct split;
  u.setConstant(std::nan(""));
  split(G, none, nullptr, u);
  EXPECT_TRUE(u.isZero(0)) << u.transpose();
  u.setConstant(std::nan(""));
  split(G32, none, nullptr, u);
  EXPECT_TRUE(u.isZero(0)) << u.transpose();
}

TEST(SurfaceProduct, TheSplitProductWritesIntoAViewAndOnlyThere) {
  std::mt19937 rng(8);
  const Eigen::MatrixXd G = random_G(30, 9);
  const Constraints c = random_constraints(30, 5, rng);
  Eigen::VectorXd expected(G.rows());
  surface_displacement_rows(G, c.indices, c.forces.data(), 0, G.rows(), expected.data());
  Eigen::VectorXd big = Eigen::VectorXd::Constant(G.rows() + 8, -3.0);
  SplitSurfaceProduct split;
  split(G, c.indices, c.forces.data(), big.segment(3, G.rows()));
  EXPECT_TRUE(same_bits(big.segment(3, G.rows()), expected));
  EXPECT_TRUE((big.head(3).array() == -3.0).all());
  EXPECT_TRUE((big.tail(5).array() == -3.0).all());
  // A vector of the wrong length is refused, not written past.
  Eigen::VectorXd short_u = Eigen::VectorXd::Constant(G.rows() - 3, -3.0);
  EXPECT_THROW(split(G, c.indices, c.forces.data(), short_u), std::logic_error);
  EXPECT_TRUE((short_u.array() == -3.0).all());
}

TEST(SurfaceProduct, AllocatesNothingPerProduct) {
  std::mt19937 rng(10);
  const Eigen::MatrixXd G = random_G(40, 11);
  const Eigen::MatrixXf G32 = G.cast<float>();
  std::vector<Constraints> sets;
  for (const int k : {0, 1, 7, 20}) sets.push_back(random_constraints(40, k, rng));
  Eigen::VectorXd u(G.rows());
  SplitSurfaceProduct split;
  for (const auto& c : sets) split(G, c.indices, c.forces.data(), u);  // warm-up
  const std::uint64_t before = testing::allocations_here();
  for (int i = 0; i < 400; ++i) {
    const Constraints& c = sets[static_cast<std::size_t>(i) % sets.size()];
    if (i % 2 == 0)
      split(G, c.indices, c.forces.data(), u);
    else
      split(G32, c.indices, c.forces.data(), u);
    surface_displacement_rows(G, c.indices, c.forces.data(), 0, G.rows(), u.data());
    surface_displacement_rows(G32, c.indices, c.forces.data(), 0, G.rows(), u.data());
  }
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  // The counter does count.
  std::vector<double> one(3, 1.0);
  EXPECT_EQ(testing::allocations_here() - before, 1u);
  EXPECT_EQ(one[2], 1.0);
}

}  // namespace
}  // namespace palpate
