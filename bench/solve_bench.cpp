// In-process request rates of the run-time model (docs/model/requests.md, "The reduced system of a
// request"): what ConstraintSolver sustains on one core for k imposed displacements on a clustered
// patch, before any transport. Three cases per k = 1, 3, 10, 20:
//
//   force_reused   F_C only, same constrained set every request: the
//                  factorization is reused, two triangular solves per request
//                  (the haptic loop holding tissue).
//   force_new_set  F_C only, a different set every request, cycling through
//                  more patches than the solver has cache slots: G_CC
//                  gather + Cholesky + condition estimate every request.
//   full_field     force_reused + u_S = G_SC F_C for every compliance vertex
//                  (3N_S × 3k doubles read per request).
//
// Same-run baselines, so that results can be quoted as ratios: the machine's
// dgemm rate, and the plain read rate of G_SC-sized data (the panels the k=20
// full field reads, which stay in cache when the set is reused) and of the
// whole of G (memory when G exceeds the cache).
//
// Usage: palpate_solve_bench [MODEL.h5] [--benchmark_...]
//        (or PALPATE_BENCH_MODEL=MODEL.h5); without a model it says so and
//        exits 0. Targets (issue 3, on openhelp-liver-h8): k=20 force_reused
//        ≥ 100 kHz, k=20 full_field ≥ 10 kHz; 1999: 3,300 / 800 / 130 / 30 Hz
//        for k = 1 / 3 / 10 / 20.

#include <benchmark/benchmark.h>

#include <Eigen/Dense>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "common.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/offline/dense.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "patch.hpp"

namespace {

using palpate::ConstraintKind;
using palpate::ConstraintSolver;
using palpate::RequestStatus;
using palpate::bench::Patch;

constexpr int kPatchSizes[] = {1, 3, 10, 20};

/// The loaded model and the patches every benchmark presses.
struct Fixture {
  palpate::SurfaceModel model;
  const palpate::DrawnSurface& surface;

  explicit Fixture(const std::filesystem::path& path)
      : model(palpate::load_surface_model("bench", path)), surface(model.surface) {}
  Patch patch(int k) const {
    return palpate::bench::nearest_patch(surface, palpate::bench::main_seed(surface), k);
  }
  /// More patches than @p cache_slots, so that cycling through them never hits the cache.
  std::vector<Patch> rotating_patches(int k, int cache_slots) const {
    std::vector<Patch> patches;
    for (int seed : palpate::bench::spread_seeds(surface, 2 * cache_slots + 1))
      patches.push_back(palpate::bench::nearest_patch(surface, seed, k));
    return patches;
  }
};
const Fixture* fixture = nullptr;

/// One request: every vertex of @p patch displaced by @p depth_m along the
/// patch's inward normal (a full imposed displacement, B = I: G_CC F_C = U_C).
RequestStatus press(ConstraintSolver& solver, const Patch& patch, double depth_m) {
  RequestStatus status = solver.begin(patch.vertex_ids.size());
  const double value[3] = {depth_m * patch.inward_normal[0], depth_m * patch.inward_normal[1],
                           depth_m * patch.inward_normal[2]};
  const double no_normal[3] = {0, 0, 0};
  for (std::uint32_t id : patch.vertex_ids) {
    if (status != RequestStatus::kOk) break;
    status =
        solver.add(id, static_cast<std::int32_t>(ConstraintKind::kDisplacement), value, no_normal);
  }
  return status == RequestStatus::kOk ? solver.solve() : status;
}

bool check(benchmark::State& state, const ConstraintSolver& solver, RequestStatus status) {
  if (status == RequestStatus::kOk) return true;
  state.SkipWithError(
      (std::string(palpate::status_name(status)) + ": " + solver.message()).c_str());
  return false;
}

void set_rate(benchmark::State& state) {
  state.SetItemsProcessed(state.iterations());
  state.counters["Hz"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_force_reused(benchmark::State& state) {
  const Patch patch = fixture->patch(static_cast<int>(state.range(0)));
  ConstraintSolver solver(fixture->model, palpate::SolverLimits{});
  std::uint64_t i = 0;
  for (auto _ : state) {
    if (!check(state, solver, press(solver, patch, palpate::bench::press_depth_m(i++)))) break;
    benchmark::DoNotOptimize(solver.forces().data());
    benchmark::ClobberMemory();
  }
  set_rate(state);
}

void BM_force_new_set(benchmark::State& state) {
  const palpate::SolverLimits limits;
  const auto patches =
      fixture->rotating_patches(static_cast<int>(state.range(0)), limits.cache_slots);
  ConstraintSolver solver(fixture->model, limits);
  std::uint64_t i = 0, reused = 0;
  for (auto _ : state) {
    const Patch& patch = patches[i % patches.size()];
    if (!check(state, solver, press(solver, patch, palpate::bench::press_depth_m(i++)))) break;
    reused += solver.reused_factorization() ? 1 : 0;
    benchmark::DoNotOptimize(solver.forces().data());
    benchmark::ClobberMemory();
  }
  set_rate(state);
  // Must be 0: every request pays its factorization.
  state.counters["reused"] =
      static_cast<double>(reused) / static_cast<double>(std::max<std::uint64_t>(i, 1));
}

/// range(0) = k, range(1) = threads for the surface product (1 or 2: palpated's
/// default on a machine with two cores or more).
void BM_full_field(benchmark::State& state) {
  const auto k = static_cast<int>(state.range(0));
  const Patch patch = fixture->patch(k);
  ConstraintSolver solver(
      fixture->model, palpate::SolverLimits{.surface_threads = static_cast<int>(state.range(1))});
  Eigen::VectorXd u(fixture->model.G.rows());
  std::uint64_t i = 0;
  for (auto _ : state) {
    if (!check(state, solver, press(solver, patch, palpate::bench::press_depth_m(i++)))) break;
    solver.surface_displacement(u);
    benchmark::DoNotOptimize(u.data());
    benchmark::ClobberMemory();
  }
  set_rate(state);
  // G_SC is 3N_S × 3k doubles; this is the rate the product reads it at.
  state.counters["G_SC_GB/s"] =
      benchmark::Counter(static_cast<double>(u.size()) * 3.0 * k * 8.0 * 1e-9,
                         benchmark::Counter::kIsIterationInvariantRate);
}

/// Plain read (a sum) of the k panels of 3 columns of G the full field of
/// the main patch reads: the bandwidth bound of full_field for that k.
void BM_read_G_SC(benchmark::State& state) {
  const Patch patch = fixture->patch(static_cast<int>(state.range(0)));
  const Eigen::MatrixXd& G = fixture->model.G;
  std::vector<int> columns;
  for (std::uint32_t id : patch.vertex_ids)
    columns.push_back(3 * fixture->model.compliance_index_of_vertex[id]);
  for (auto _ : state) {
    double sum = 0;
    for (int c : columns) sum += G.middleCols<3>(c).sum();
    benchmark::DoNotOptimize(sum);
  }
  state.counters["GB/s"] = benchmark::Counter(
      static_cast<double>(G.rows()) * 3.0 * static_cast<double>(columns.size()) * 8.0 * 1e-9,
      benchmark::Counter::kIsIterationInvariantRate);
}

/// Plain read of all of G: the memory rate when data does not stay in cache.
void BM_read_G_all(benchmark::State& state) {
  const Eigen::MatrixXd& G = fixture->model.G;
  for (auto _ : state) {
    double sum = G.sum();
    benchmark::DoNotOptimize(sum);
  }
  state.counters["GB/s"] = benchmark::Counter(static_cast<double>(G.size()) * 8.0 * 1e-9,
                                              benchmark::Counter::kIsIterationInvariantRate);
}

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  const std::string path = palpate::bench::take_model_path(argc, argv);
  if (path.empty() || !std::filesystem::exists(path)) {
    std::fprintf(
        stderr,
        "palpate_solve_bench: skipped: no compliance file%s%s; give MODEL.h5 or "
        "PALPATE_BENCH_MODEL "
        "(e.g. build/precompute/palpate-precompute --job config/openhelp-liver-h8.toml -q writes "
        "out/openhelp-liver-h8.h5)\n",
        path.empty() ? "" : " at ", path.c_str());
    return 0;
  }
  const Fixture loaded(path);
  fixture = &loaded;

  benchmark::AddCustomContext("blas", palpate::blas_description());
  benchmark::AddCustomContext("model", path);
  benchmark::AddCustomContext("compliance_vertices",
                              std::to_string(loaded.model.compliance_vertex_count()));
  benchmark::Initialize(&argc, argv);
  benchmark::RegisterBenchmark("BM_dgemm", palpate::bench::BM_dgemm)
      ->Arg(1000)
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime();
  benchmark::RegisterBenchmark("BM_read_G_SC", BM_read_G_SC)
      ->Arg(20)
      ->Unit(benchmark::kMicrosecond)
      ->UseRealTime();
  benchmark::RegisterBenchmark("BM_read_G_all", BM_read_G_all)
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime();
  for (auto* b : {benchmark::RegisterBenchmark("BM_force_reused", BM_force_reused),
                  benchmark::RegisterBenchmark("BM_force_new_set", BM_force_new_set)})
    for (int k : kPatchSizes) b->Arg(k)->Unit(benchmark::kMicrosecond)->UseRealTime();
  for (int threads : {1, 2})
    for (int k : kPatchSizes)
      benchmark::RegisterBenchmark("BM_full_field", BM_full_field)
          ->Args({k, threads})
          ->ArgNames({"k", "threads"})
          ->Unit(benchmark::kMicrosecond)
          ->UseRealTime();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
}
