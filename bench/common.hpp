#pragma once
// What several benchmarks share: the same-run dgemm baseline and the way
// they are given a compliance file.

#include <benchmark/benchmark.h>

#include <Eigen/Dense>
#include <cstdlib>
#include <string>

#include "palpate/offline/dense.hpp"

namespace palpate::bench {

/// The machine's dense rate, C = A B with n = range(0): the yardstick of the
/// ratios in BENCHMARKS.md.
inline void BM_dgemm(benchmark::State& state) {
  const auto n = state.range(0);
  const Eigen::MatrixXd A = Eigen::MatrixXd::Random(n, n), B = Eigen::MatrixXd::Random(n, n);
  Eigen::MatrixXd C(n, n);
  for (auto _ : state) {
    palpate::blas_gemm(A, B, C);
    benchmark::DoNotOptimize(C.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(2.0 * static_cast<double>(n * n * n) * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}

/// The compliance file to measure: the first argument that is not a --flag
/// (removed from argv for benchmark::Initialize), else PALPATE_BENCH_MODEL.
inline std::string take_model_path(int& argc, char** argv) {
  for (int a = 1; a < argc; ++a) {
    if (argv[a][0] == '-') continue;
    std::string path = argv[a];
    for (int b = a; b + 1 < argc; ++b) argv[b] = argv[b + 1];
    --argc;
    return path;
  }
  const char* env = std::getenv("PALPATE_BENCH_MODEL");
  return env != nullptr ? env : "";
}

/// Whether environment variable @p name is set to "1" (a benchmark's option).
inline bool env_is_one(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr && std::string(value) == "1";
}

}  // namespace palpate::bench
