// The machine's dense rates, the yardstick for precompute's dense phases:
// dgemm (the BLAS's best case) and the SPD inverse from a Cholesky factor
// (dpotri, what condensation runs on the Schur complement).

#include <benchmark/benchmark.h>

#include <Eigen/Dense>

#include "common.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/offline/dense.hpp"

namespace {

BENCHMARK(palpate::bench::BM_dgemm)
    ->Name("BM_dgemm")
    ->Arg(2000)
    ->Arg(4000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_spd_inverse_from_cholesky(benchmark::State& state) {
  const auto n = state.range(0);
  Eigen::MatrixXd S = Eigen::MatrixXd::Random(n, n);
  S = S * S.transpose() + n * Eigen::MatrixXd::Identity(n, n);
  const Eigen::MatrixXd L = S.llt().matrixL();
  Eigen::MatrixXd work(n, n);
  for (auto _ : state) {
    state.PauseTiming();
    work = L;
    state.ResumeTiming();
    palpate::invert_from_cholesky(work);
    benchmark::DoNotOptimize(work.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(2.0 * n * n * n / 3.0 * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_spd_inverse_from_cholesky)
    ->Arg(3000)
    ->Arg(6000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  benchmark::AddCustomContext("blas", palpate::blas_description());
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
}
