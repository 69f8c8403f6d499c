#include "palpate/runtime/surface_product.hpp"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

#include "palpate/core/error.hpp"

namespace palpate {

namespace {
/// Tells the CPU we are spinning (less power, the sibling hyperthread runs).
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_pause();
#endif
}
}  // namespace

void surface_displacement_rows(const Eigen::MatrixXd& G, std::span<const int> indices,
                               const double* forces_n, Eigen::Index row_begin, Eigen::Index row_end,
                               double* u_m) {
  Eigen::Map<Eigen::VectorXd> u(u_m + row_begin, row_end - row_begin);
  u.setZero();
  // G is symmetric and column-major: the three columns of vertex c are
  // contiguous, so G_SC f_C reads k panels of rows × 3 once each.
  for (std::size_t j = 0; j < indices.size(); ++j)
    u.noalias() += G.block(row_begin, 3 * indices[j], row_end - row_begin, 3) *
                   Eigen::Map<const Eigen::Vector3d>(forces_n + 3 * j);
}

void surface_displacement_rows(const Eigen::MatrixXf& G, std::span<const int> indices,
                               const double* forces_n, Eigen::Index row_begin, Eigen::Index row_end,
                               double* u_m) {
  Eigen::Map<Eigen::VectorXd> u(u_m + row_begin, row_end - row_begin);
  u.setZero();
  // Half the bytes read per product; the sums stay in double.
  for (std::size_t j = 0; j < indices.size(); ++j)
    u.noalias() += G.block(row_begin, 3 * indices[j], row_end - row_begin, 3).cast<double>() *
                   Eigen::Map<const Eigen::Vector3d>(forces_n + 3 * j);
}

SplitSurfaceProduct::SplitSurfaceProduct(std::chrono::microseconds spin)
    : spin_(spin), worker_([this] { work(); }) {}

SplitSurfaceProduct::~SplitSurfaceProduct() {
  stop_.store(true, std::memory_order_release);
  go_.fetch_add(1, std::memory_order_release);
  go_.notify_one();
  worker_.join();
}

void SplitSurfaceProduct::operator()(const Eigen::MatrixXd& G, std::span<const int> indices,
                                     const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m) {
  G_ = &G;
  G32_ = nullptr;
  run(G, indices, forces_n, u_m);
}

void SplitSurfaceProduct::operator()(const Eigen::MatrixXf& G, std::span<const int> indices,
                                     const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m) {
  G_ = nullptr;
  G32_ = &G;
  run(G, indices, forces_n, u_m);
}

template <typename Matrix>
void SplitSurfaceProduct::run(const Matrix& G, std::span<const int> indices, const double* forces_n,
                              Eigen::Ref<Eigen::VectorXd> u_m) {
  PALPATE_DEMAND(u_m.size() == G.rows() && u_m.innerStride() == 1);
  const Eigen::Index rows = G.rows();
  // Split on a cache-line boundary (8 doubles) so the halves share no line of u.
  const Eigen::Index half = rows / 16 * 8;
  indices_ = indices;
  forces_ = forces_n;
  row_begin_ = half;
  row_end_ = rows;
  u_ = u_m.data();
  const std::uint64_t generation = go_.fetch_add(1, std::memory_order_release) + 1;
  go_.notify_one();
  surface_displacement_rows(G, indices, forces_n, 0, half, u_m.data());
  // The worker's half takes about as long as ours: spin, yielding if it was
  // descheduled.
  for (int polls = 0; done_.load(std::memory_order_acquire) != generation; ++polls) {
    if (polls < 4096)
      cpu_relax();
    else
      std::this_thread::yield();
  }
}

void SplitSurfaceProduct::work() {
  std::uint64_t seen = 0;
  for (;;) {
    const auto spin_until = std::chrono::steady_clock::now() + spin_;
    std::uint64_t generation = go_.load(std::memory_order_acquire);
    for (int polls = 0; generation == seen; ++polls) {
      if ((polls & 63) == 63 && std::chrono::steady_clock::now() > spin_until) {
        go_.wait(seen, std::memory_order_acquire);  // futex: no CPU while idle
      } else {
        cpu_relax();
      }
      generation = go_.load(std::memory_order_acquire);
    }
    if (stop_.load(std::memory_order_acquire)) return;
    if (G32_)
      surface_displacement_rows(*G32_, indices_, forces_, row_begin_, row_end_, u_);
    else
      surface_displacement_rows(*G_, indices_, forces_, row_begin_, row_end_, u_);
    seen = generation;
    done_.store(generation, std::memory_order_release);
  }
}

}  // namespace palpate
