// Why the full surface field u_S = G_SC F_C (docs/model/surface-field.md) runs at
// the rate it does, and what would make it faster: the same product done
// several ways on the same model, forces and patch, timed side by side.
//
// The product reads 3N_S × 3k doubles of G (the k panels of 3 contiguous
// columns of the constrained vertices; 3.2 MB at k = 20 on
// openhelp-liver-h8) and does 2 flops per double read, so it is bound by the
// rate the core can read G_SC: from L3 once the panels exceed L2, from memory
// when they are not cached. Variants:
//
//   lib              palpate::surface_displacement as the library ships it
//                    (Eigen, one 3-column panel at a time, u updated k times).
//   row_blocked      rows in blocks of 2048 kept in L1, all k panels applied
//                    per block: u is written once, G_SC read once.
//   row_blocked_avx2 the same loop compiled for AVX2+FMA (the library is
//                    compiled for baseline x86-64: SSE2), chosen at run time.
//   blas_dgemv       one OpenBLAS dgemv per panel (run-time dispatched
//                    kernels, and OpenBLAS's own threads).
//   float_G          row_blocked_avx2 on a float copy of G (half the bytes;
//                    accumulation in double).
//   gathered         row_blocked_avx2 on a contiguous copy of G_SC (what a
//                    cache slot could keep per constraint structure).
//   gathered_float   the same copy in float (1.6 MB at k = 20: fits L2).
//   gathered_float_acc  the same, accumulated in float (8 lanes, no conversion).
//   huge_pages       row_blocked_avx2 on a copy of G on 2 MB pages.
//   two_threads      row_blocked_avx2 with the rows split between this
//                    thread and one persistent worker (spinning hand-off).
//   float_two_threads  both.
//
// Each variant reports its rate (Hz), the G_SC read rate (GB/s of the
// double matrix's size, so variants compare directly) and its largest
// difference from lib relative to max |u| (rel_diff).
//
// Usage: palpate_surface_field_bench [MODEL.h5] [--benchmark_...]
//        (or PALPATE_BENCH_MODEL=MODEL.h5); without a model it says so and exits 0.

#include <benchmark/benchmark.h>
#include <cblas.h>
#include <immintrin.h>
#include <sys/mman.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "common.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "patch.hpp"

namespace {

using Eigen::Index;

constexpr Index kRowBlock = 2048;  // 16 KB of double accumulators: stays in L1

/// The product's inputs: the model, the 3k columns of G_SC and F_C from a real solve.
struct Problem {
  palpate::SurfaceModel model;
  std::vector<float> G_float;           // column-major copy of G, built on first use
  std::vector<int> indices;             // compliance index per constrained vertex
  std::vector<Index> columns;           // 3k column indices into G
  std::vector<double> forces;           // 3k, N
  Eigen::VectorXd reference;            // lib's u_S
  std::vector<double> gathered;         // G_SC as one contiguous 3N_S × 3k column-major matrix
  std::vector<float> gathered_float;    // the same in float
  std::vector<Index> gathered_columns;  // 0 .. 3k-1
  double* huge_G = nullptr;             // a copy of G on transparent huge pages (2 MB)

  Problem(const std::filesystem::path& path, int k)
      : model(palpate::load_surface_model("bench", path)) {
    const palpate::DrawnSurface& surface = model.surface;
    const auto patch =
        palpate::bench::nearest_patch(surface, palpate::bench::main_seed(surface), k);
    palpate::ConstraintSolver solver(model, palpate::SolverLimits{});
    solver.begin(patch.vertex_ids.size());
    const double depth = palpate::bench::press_depth_m(0);
    const double value[3] = {depth * patch.inward_normal[0], depth * patch.inward_normal[1],
                             depth * patch.inward_normal[2]};
    const double none[3] = {0, 0, 0};
    for (auto id : patch.vertex_ids) solver.add(id, 1, value, none);
    if (solver.solve() != palpate::RequestStatus::kOk) {
      std::fprintf(stderr, "palpate_surface_field_bench: solve failed: %s\n", solver.message());
      std::exit(1);
    }
    indices.assign(solver.load_indices().begin(), solver.load_indices().end());
    forces.assign(solver.load_forces().begin(), solver.load_forces().end());
    for (int c : indices)
      for (int d = 0; d < 3; ++d) columns.push_back(3 * static_cast<Index>(c) + d);
    reference.resize(model.G.rows());
    palpate::surface_displacement(model.G, indices, forces.data(), reference);
    for (std::size_t c = 0; c < columns.size(); ++c) {
      gathered_columns.push_back(static_cast<Index>(c));
      const double* column = model.G.data() + columns[c] * model.G.rows();
      gathered.insert(gathered.end(), column, column + model.G.rows());
      for (Index r = 0; r < model.G.rows(); ++r)
        gathered_float.push_back(static_cast<float>(column[r]));
    }
  }
  ~Problem() { std::free(huge_G); }
  Problem(const Problem&) = delete;
  Problem& operator=(const Problem&) = delete;
  /// G copied to memory the kernel backs with 2 MB pages when it can
  /// (transparent huge pages in "madvise" mode need the madvise).
  const double* huge_page_G() {
    if (huge_G == nullptr) {
      constexpr std::size_t kHuge = std::size_t{2} << 20;
      const std::size_t bytes =
          (static_cast<std::size_t>(model.G.size()) * sizeof(double) + kHuge - 1) / kHuge * kHuge;
      huge_G = static_cast<double*>(std::aligned_alloc(kHuge, bytes));
      madvise(huge_G, bytes, MADV_HUGEPAGE);
      std::copy_n(model.G.data(), model.G.size(), huge_G);
    }
    return huge_G;
  }
  Index rows() const { return model.G.rows(); }
  const float* float_G() {
    if (G_float.empty()) {
      G_float.resize(static_cast<std::size_t>(model.G.size()));
      std::transform(model.G.data(), model.G.data() + model.G.size(), G_float.begin(),
                     [](double x) { return static_cast<float>(x); });
    }
    return G_float.data();
  }
};
Problem* problem = nullptr;

/// Rows [r0, r1) of u = Σ_j G(:, 3c_j..3c_j+2) f_j, one L1-sized block of
/// rows at a time, one 3-column panel per pass over the block (three streams
/// of G, accumulators loaded and stored once per panel). Acc is the
/// accumulation type (double, or float for a float G: no conversions).
template <typename Acc, typename Scalar>
[[gnu::always_inline]] inline void row_blocked_body(const Scalar* G, Index ld, const Index* columns,
                                                    int ncols, const double* f, Index r0, Index r1,
                                                    double* u) {
  alignas(64) Acc acc[kRowBlock];
  for (Index b = r0; b < r1; b += kRowBlock) {
    const Index n = std::min(kRowBlock, r1 - b);
    std::fill_n(acc, n, Acc(0));
    for (int c = 0; c + 2 < ncols; c += 3) {
      const Scalar* __restrict c0 = G + columns[c] * ld + b;
      const Scalar* __restrict c1 = G + columns[c + 1] * ld + b;
      const Scalar* __restrict c2 = G + columns[c + 2] * ld + b;
      Acc* __restrict a = acc;
      const Acc f0 = static_cast<Acc>(f[c]), f1 = static_cast<Acc>(f[c + 1]),
                f2 = static_cast<Acc>(f[c + 2]);
      // Independent rows: lets GCC vectorize without run-time alias checks.
#pragma GCC ivdep
      for (Index r = 0; r < n; ++r)
        a[r] += f0 * static_cast<Acc>(c0[r]) + f1 * static_cast<Acc>(c1[r]) +
                f2 * static_cast<Acc>(c2[r]);
    }
    for (Index r = 0; r < n; ++r) u[b + r] = static_cast<double>(acc[r]);
  }
}

void row_blocked(const double* G, Index ld, const Index* columns, int ncols, const double* f,
                 Index r0, Index r1, double* u) {
  row_blocked_body<double>(G, ld, columns, ncols, f, r0, r1, u);
}

template <typename Acc = double, typename Scalar>
__attribute__((target("avx2,fma"), noinline)) void row_blocked_avx2(const Scalar* G, Index ld,
                                                                    const Index* columns, int ncols,
                                                                    const double* f, Index r0,
                                                                    Index r1, double* u) {
  row_blocked_body<Acc>(G, ld, columns, ncols, f, r0, r1, u);
}

/// A second thread that computes the upper half of the rows when told; it
/// spins between requests (what a latency-critical split would do; it costs
/// a core).
class RowSplitter {
 public:
  RowSplitter() : worker_([this] { loop(); }) {}
  ~RowSplitter() {
    stop_.store(true, std::memory_order_release);
    worker_.join();
  }
  RowSplitter(const RowSplitter&) = delete;
  RowSplitter& operator=(const RowSplitter&) = delete;

  template <typename Scalar>
  void run(const Scalar* G, Index ld, const Index* columns, int ncols, const double* f, Index rows,
           double* u) {
    const Index half = (rows / 2 / 8) * 8;
    task_ = [=] { row_blocked_avx2(G, ld, columns, ncols, f, half, rows, u); };
    const auto generation = go_.load(std::memory_order_relaxed) + 1;
    go_.store(generation, std::memory_order_release);
    row_blocked_avx2(G, ld, columns, ncols, f, 0, half, u);
    while (done_.load(std::memory_order_acquire) != generation) _mm_pause();
  }

 private:
  void loop() {
    std::uint64_t seen = 0;
    while (!stop_.load(std::memory_order_acquire)) {
      const auto generation = go_.load(std::memory_order_acquire);
      if (generation == seen) {
        _mm_pause();
        continue;
      }
      task_();
      seen = generation;
      done_.store(generation, std::memory_order_release);
    }
  }

  std::function<void()> task_;
  std::atomic<std::uint64_t> go_{0}, done_{0};
  std::atomic<bool> stop_{false};
  std::thread worker_;
};

double relative_difference(const Eigen::VectorXd& u) {
  return (u - problem->reference).cwiseAbs().maxCoeff() / problem->reference.cwiseAbs().maxCoeff();
}

/// Times @p product (which writes u) and sets the common counters.
template <typename Product>
void time_product(benchmark::State& state, Product product) {
  Eigen::VectorXd u(problem->rows());
  for (auto _ : state) {
    product(u.data());
    benchmark::DoNotOptimize(u.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["Hz"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["G_SC_GB/s"] = benchmark::Counter(
      static_cast<double>(problem->rows()) * static_cast<double>(problem->columns.size()) * 8e-9,
      benchmark::Counter::kIsIterationInvariantRate);
  state.counters["rel_diff"] = relative_difference(u);
}

void BM_lib(benchmark::State& state) {
  time_product(state, [](double* u) {
    palpate::surface_displacement(problem->model.G, problem->indices, problem->forces.data(),
                                  Eigen::Map<Eigen::VectorXd>(u, problem->rows()));
  });
}

void BM_row_blocked(benchmark::State& state) {
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked(problem->model.G.data(), problem->rows(), problem->columns.data(), ncols,
                problem->forces.data(), 0, problem->rows(), u);
  });
}

void BM_row_blocked_avx2(benchmark::State& state) {
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked_avx2(problem->model.G.data(), problem->rows(), problem->columns.data(), ncols,
                     problem->forces.data(), 0, problem->rows(), u);
  });
}

void BM_blas_dgemv(benchmark::State& state) {
  const int m = static_cast<int>(problem->rows()), three = 3, one = 1;
  const double alpha = 1, zero = 0;
  time_product(state, [&](double* u) {
    for (std::size_t j = 0; j < problem->indices.size(); ++j) {
      const double* panel =
          problem->model.G.data() + 3 * static_cast<Index>(problem->indices[j]) * m;
      cblas_dgemv(CblasColMajor, CblasNoTrans, m, three, alpha, panel, m,
                  problem->forces.data() + 3 * j, one, j == 0 ? zero : alpha, u, one);
    }
  });
}

void BM_float_G(benchmark::State& state) {
  const float* G = problem->float_G();
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked_avx2(G, problem->rows(), problem->columns.data(), ncols, problem->forces.data(), 0,
                     problem->rows(), u);
  });
}

void BM_two_threads(benchmark::State& state) {
  RowSplitter splitter;
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    splitter.run(problem->model.G.data(), problem->rows(), problem->columns.data(), ncols,
                 problem->forces.data(), problem->rows(), u);
  });
}

void BM_float_two_threads(benchmark::State& state) {
  const float* G = problem->float_G();
  RowSplitter splitter;
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    splitter.run(G, problem->rows(), problem->columns.data(), ncols, problem->forces.data(),
                 problem->rows(), u);
  });
}

void BM_gathered(benchmark::State& state) {
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked_avx2(problem->gathered.data(), problem->rows(), problem->gathered_columns.data(),
                     ncols, problem->forces.data(), 0, problem->rows(), u);
  });
}

void BM_gathered_float(benchmark::State& state) {
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked_avx2(problem->gathered_float.data(), problem->rows(),
                     problem->gathered_columns.data(), ncols, problem->forces.data(), 0,
                     problem->rows(), u);
  });
}

void BM_gathered_float_acc(benchmark::State& state) {
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked_avx2<float>(problem->gathered_float.data(), problem->rows(),
                            problem->gathered_columns.data(), ncols, problem->forces.data(), 0,
                            problem->rows(), u);
  });
}

void BM_huge_pages(benchmark::State& state) {
  const double* G = problem->huge_page_G();
  const int ncols = static_cast<int>(problem->columns.size());
  time_product(state, [&](double* u) {
    row_blocked_avx2(G, problem->rows(), problem->columns.data(), ncols, problem->forces.data(), 0,
                     problem->rows(), u);
  });
}

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  const std::string path = palpate::bench::take_model_path(argc, argv);
  if (path.empty() || !std::filesystem::exists(path)) {
    std::fprintf(stderr,
                 "palpate_surface_field_bench: skipped: no compliance file%s%s; give MODEL.h5 or "
                 "PALPATE_BENCH_MODEL\n",
                 path.empty() ? "" : " at ", path.c_str());
    return 0;
  }
  const int k = 20;  // the target's patch size
  Problem loaded(path, k);
  problem = &loaded;
  benchmark::AddCustomContext("blas", palpate::blas_description());
  benchmark::AddCustomContext("model", path);
  benchmark::AddCustomContext("k", std::to_string(k));
  benchmark::Initialize(&argc, argv);
  const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  std::vector<benchmark::internal::Benchmark*> all = {
      benchmark::RegisterBenchmark("BM_lib", BM_lib),
      benchmark::RegisterBenchmark("BM_row_blocked", BM_row_blocked),
      benchmark::RegisterBenchmark("BM_blas_dgemv", BM_blas_dgemv)};
  if (avx2)
    for (auto* b : {benchmark::RegisterBenchmark("BM_row_blocked_avx2", BM_row_blocked_avx2),
                    benchmark::RegisterBenchmark("BM_float_G", BM_float_G),
                    benchmark::RegisterBenchmark("BM_gathered", BM_gathered),
                    benchmark::RegisterBenchmark("BM_gathered_float", BM_gathered_float),
                    benchmark::RegisterBenchmark("BM_gathered_float_acc", BM_gathered_float_acc),
                    benchmark::RegisterBenchmark("BM_huge_pages", BM_huge_pages),
                    benchmark::RegisterBenchmark("BM_two_threads", BM_two_threads),
                    benchmark::RegisterBenchmark("BM_float_two_threads", BM_float_two_threads)})
      all.push_back(b);
  else
    std::fprintf(
        stderr,
        "palpate_surface_field_bench: no AVX2+FMA on this CPU: the AVX2 variants are skipped\n");
  for (auto* b : all) b->Unit(benchmark::kMicrosecond)->UseRealTime();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
}
