#pragma once
/// @file
/// The surface field u_S = G_SC f_C (docs/model/surface-field.md, "The surface field"), the one
/// memory-bound product of the run time: it reads 3N_S × 3k doubles of G per
/// request (3.2 MB for k = 20 on a 2,192-vertex surface), more than one
/// core's L2 cache. Split by rows over two cores, each half stays in its
/// core's L2 from one request to the next while the constrained set is the
/// same, and the product runs at cache rather than memory bandwidth
/// (BENCHMARKS.md).

#include <atomic>
#include <chrono>
#include <span>
#include <thread>

#include "palpate/core/eigen.hpp"

namespace palpate {

/// u_m[r] = Σ_j (G_SC)[r, j] f_j for rows r in [row_begin, row_end): the
/// kernel each thread runs. @p u_m points at row 0 of the full 3N_S vector.
void surface_displacement_rows(const Eigen::MatrixXd& G, std::span<const int> indices,
                               const double* forces_n, Eigen::Index row_begin, Eigen::Index row_end,
                               double* u_m);
/// The same from a float32 G (each entry widened to double, sums in double).
void surface_displacement_rows(const Eigen::MatrixXf& G, std::span<const int> indices,
                               const double* forces_n, Eigen::Index row_begin, Eigen::Index row_end,
                               double* u_m);

/// u_S = G_SC f_C by the calling thread and one worker, half of the rows
/// each. The worker spins for @p spin after each product (so that a stream of
/// requests finds it awake), then sleeps on a futex until the next one.
/// Allocation-free after construction; one caller at a time.
class SplitSurfaceProduct {
 public:
  explicit SplitSurfaceProduct(std::chrono::microseconds spin = std::chrono::microseconds(200));
  ~SplitSurfaceProduct();
  SplitSurfaceProduct(const SplitSurfaceProduct&) = delete;
  SplitSurfaceProduct& operator=(const SplitSurfaceProduct&) = delete;

  /// @param forces_n 3 per index, N; @p u_m receives 3N_S displacements, m
  void operator()(const Eigen::MatrixXd& G, std::span<const int> indices, const double* forces_n,
                  Eigen::Ref<Eigen::VectorXd> u_m);
  void operator()(const Eigen::MatrixXf& G, std::span<const int> indices, const double* forces_n,
                  Eigen::Ref<Eigen::VectorXd> u_m);

 private:
  void work();

  std::chrono::microseconds spin_;
  // The worker's half, published by the release store of go_.
  template <typename Matrix>
  void run(const Matrix& G, std::span<const int> indices, const double* forces_n,
           Eigen::Ref<Eigen::VectorXd> u_m);
  const Eigen::MatrixXd* G_ = nullptr;
  const Eigen::MatrixXf* G32_ = nullptr;  // instead of G_, for a float32 model
  std::span<const int> indices_;
  const double* forces_ = nullptr;
  Eigen::Index row_begin_ = 0, row_end_ = 0;
  double* u_ = nullptr;
  std::atomic<std::uint64_t> go_{0}, done_{0};
  std::atomic<bool> stop_{false};
  std::thread worker_;
};

}  // namespace palpate
