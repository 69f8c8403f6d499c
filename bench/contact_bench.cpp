// One haptic tick without transport: ToolContactEngine::update (contacts on
// the deformed organ, one solve for every tool, feedback limits) for
// scripted gestures on a compliance file, timed tick by tick so that the
// tail is seen (p50 / p99 / p99.9 / max, µs per tick). Target (issue 4, on
// openhelp-liver-h8): ≤ 100 µs p99 per tick.
//
//   press_glide   one grasper pressed 5 mm along the inward normal at the
//                 main seed of bench/patch.hpp, then glided 20 mm along the
//                 surface, then withdrawn: 4,000 ticks.
//   two_tools     the same with a second grasper pressing 25 mm away: both
//                 tools' constraints in one solve, two updates per tick.
//   wide_press    press_glide with a 15 mm sphere 8 mm deep (a palpating
//                 finger or retractor): many contacts per tick.
//   wide_press_64 a 50 mm frictionless sphere 10 mm deep, glided, up to 64
//                 contact points (issue 17: ≤ 100 µs p99 with 64 points).
//   press_64      a 200 mm frictionless sphere (a flat plate, nearly) 15 mm
//                 deep, glided, with room for 64 points on the tool (the
//                 engine's two tools share max_constraints = 128; at the
//                 default 64 each has 32, wide_press_64's real cap): the
//                 synthetic 64-point tick of issue 17.
//   grasp_pull    jaws open at 40°, in 3 mm, closed, pulled 10 mm, opened.
//   two_grasps    grasp_pull with both tools, 25 mm apart (issue 17's target:
//                 two tools grasping, p99 ≤ 250 µs per update).
//
// Counters: mean_contacts (points per update of the tool), max_contacts
// (most points of one tool in one update), solves_per_update; and the
// contact-set changes within a tick: settled_p50_us / changed_p50_us /
// changed_p99_us (updates of one solve, of more than one), us_per_change
// ((mean of changed − mean of settled) / extra solves of the changed: what
// one change of the set, rows leaving, sliding or joining, costs).
//
// Each gesture runs twice, /incremental:0 (the active set refactors every
// solve, the reference) and /incremental:1 (it edits one factorization;
// ContactSettings::incremental_active_set): the same-run baseline. Also
// BM_dgemm (common.hpp), the machine's dense rate.
//
// The 64-point gestures (wide_press_64, press_64) also time, apart from the
// engine after each update, what no exact tick can skip (tick_floor.hpp):
// floor_p50_us / floor_p99_us, of which floor_positions_p50_us (the
// deformed positions within the search radius) and floor_G_UU_p50_us (G
// among the contacts' vertices), floor_candidates, floor_loads and floor_U their counts.
//
// Usage: palpate_contact_bench MODEL.h5 [--benchmark_...]
//        (or PALPATE_BENCH_MODEL=MODEL.h5); without a model it says so and exits 0.
//        PALPATE_BENCH_FLOAT32=1 keeps a float32 file's G in float32 (half
//        the bytes; the engine's sums stay double); PALPATE_BENCH_LAYOUTS=1
//        also times the floor's positions read two other ways (tick_floor.hpp).

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "common.hpp"
#include "palpate/core/rotation.hpp"
#include "palpate/core/statistics.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "patch.hpp"
#include "tick_floor.hpp"

namespace {

using Eigen::Vector3d;
using palpate::ToolContactEngine;
using palpate::ToolPoseInput;

const palpate::SurfaceModel* g_model = nullptr;

const palpate::DrawnSurface& drawn(const palpate::SurfaceModel& m) { return m.surface; }

Vector3d rest(const palpate::SurfaceModel& m, int v) { return m.surface.rest_position(v); }

/// A tool pose along a straight path: the hinge at @p tip_target − reach·axis,
/// pointing along @p inward.
struct Path {
  Vector3d start, inward, tangent;
  Eigen::Quaterniond orientation;
};

Path path_at(int seed, const palpate::ToolGeometry& g) {
  const auto& m = *g_model;
  const auto n = palpate::bench::inward_normal(drawn(m), seed);
  Path p;
  p.inward = Vector3d(n[0], n[1], n[2]);
  p.tangent = p.inward.unitOrthogonal();
  p.orientation = palpate::rotation_taking(Vector3d::UnitZ(), p.inward);
  p.start = rest(m, seed) - (g.tip_length_m + g.tip_radius_m + 0.002) * p.inward;
  return p;
}

/// The seed of the second tool: the compliance vertex nearest 25 mm from the first along the
/// tangent.
int second_seed(int seed, const Path& path) {
  const auto& m = *g_model;
  const Vector3d want = rest(m, seed) + 0.025 * path.tangent;
  int best = seed;
  double best_d = 1e9;
  for (int j = 0; j < m.compliance_vertex_count(); ++j)
    if (const double d = (rest(m, j) - want).norm(); d < best_d) best_d = d, best = j;
  return best;
}

struct Keyframe {
  double depth_m, slide_m, jaw_deg;
  int ticks;  // to reach it from the previous one
};

void run_gesture(benchmark::State& state, int tools, const std::vector<Keyframe>& keys,
                 double sphere_radius_m = 0, double friction = 0.3, int contacts_cap = 24,
                 int max_constraints = 64, bool floor = false) {
  const auto& m = *g_model;
  palpate::ContactSettings settings;
  settings.max_contacts_per_tool = contacts_cap;
  settings.incremental_active_set = state.range(0) != 0;
  std::vector<palpate::ToolGeometry> geometry(2);
  geometry[0].id = "left";
  geometry[1].id = "right";
  if (sphere_radius_m > 0)
    for (auto& g : geometry) {
      g.tip = palpate::TipShape::kSphere;
      g.tip_length_m = 0;
      g.tip_radius_m = sphere_radius_m;
      g.jaw_length_m = 0;
      g.friction = friction;
    }
  // Each of the two tools gets max_constraints / 2 rows at most.
  palpate::SolverLimits limits;
  limits.max_constraints = max_constraints;
  ToolContactEngine engine(m, geometry, settings, limits);
  const int seed = palpate::bench::main_seed(drawn(m));
  std::vector<Path> paths{path_at(seed, geometry[0])};
  paths.push_back(path_at(second_seed(seed, paths[0]), geometry[1]));
  int total_ticks = 0;
  for (const auto& k : keys) total_ticks += k.ticks;
  std::vector<double> tick_us, settled_us, changed_us;
  tick_us.reserve(static_cast<std::size_t>(total_ticks) * 64);
  settled_us.reserve(tick_us.capacity());
  changed_us.reserve(tick_us.capacity());
  std::uint64_t extra_solves = 0;
  palpate::bench::TickFloor reads;
  if (floor && palpate::bench::env_is_one("PALPATE_BENCH_LAYOUTS")) reads.time_layouts_too(m);
  std::uint64_t sequence = 0, contacts = 0, failures = 0;
  int max_contacts = 0;
  double now = 0;
  for (auto _ : state) {
    Keyframe from{0, 0, keys.front().jaw_deg, 0};
    for (const auto& to : keys) {
      for (int i = 1; i <= to.ticks; ++i) {
        const double a = static_cast<double>(i) / to.ticks;
        const double depth = from.depth_m + a * (to.depth_m - from.depth_m);
        const double slide = from.slide_m + a * (to.slide_m - from.slide_m);
        const double jaw = from.jaw_deg + a * (to.jaw_deg - from.jaw_deg);
        ++sequence;
        now += 1e-3;
        for (int t = 0; t < tools; ++t) {
          const Path& p = paths[static_cast<std::size_t>(t)];
          ToolPoseInput pose;
          pose.sequence = sequence;
          pose.position_m = p.start + (0.002 + depth) * p.inward + slide * p.tangent;
          pose.orientation = p.orientation;
          pose.jaw_angle_rad = palpate::degrees(jaw);
          const std::uint64_t solves = engine.solves();
          const auto start = std::chrono::steady_clock::now();
          if (engine.update(t, pose, now) != palpate::RequestStatus::kOk && failures++ == 0)
            std::fprintf(stderr, "first failed tick: %s\n", engine.solver_message());
          const double us =
              std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start)
                  .count();
          tick_us.push_back(us);
          if (const std::uint64_t n = engine.solves() - solves; n > 1) {
            changed_us.push_back(us);
            extra_solves += n - 1;
          } else if (n == 1) {
            settled_us.push_back(us);
          }
          if (floor && t == 0)  // outside the tick's time
            reads.measure(m, engine, pose.position_m,
                          geometry[0].tip_radius_m + settings.search_margin_m);
          contacts += static_cast<std::uint64_t>(engine.output(t).contacts);
          max_contacts = std::max(max_contacts, engine.output(t).contacts);
        }
      }
      from = to;
    }
  }
  std::sort(tick_us.begin(), tick_us.end());
  auto at = [&](double q) { return palpate::sorted_percentile(tick_us, q); };
  state.counters["p50_us"] = at(0.5);
  state.counters["p99_us"] = at(0.99);
  state.counters["p999_us"] = at(0.999);
  state.counters["max_us"] = tick_us.back();
  state.counters["mean_contacts"] =
      static_cast<double>(contacts) / static_cast<double>(tick_us.size());
  state.counters["max_contacts"] = max_contacts;
  state.counters["solves_per_update"] =
      static_cast<double>(engine.solves()) / static_cast<double>(tick_us.size());
  state.counters["failed"] = static_cast<double>(failures);
  const auto mean = [](const std::vector<double>& v) {
    double sum = 0;
    for (const double x : v) sum += x;
    return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
  };
  const auto quantile = [](std::vector<double>& v, double q) {
    std::sort(v.begin(), v.end());
    return palpate::sorted_percentile(v, q);
  };
  const auto times = engine.solve_times();
  state.counters["first_solve_us"] =
      times.first > 0 ? 1e6 * times.first_s / static_cast<double>(times.first) : 0.0;
  state.counters["change_solve_us"] =
      times.changed > 0 ? 1e6 * times.changed_s / static_cast<double>(times.changed) : 0.0;
  state.counters["settled_p50_us"] = quantile(settled_us, 0.5);
  state.counters["changed_p50_us"] = quantile(changed_us, 0.5);
  state.counters["changed_p99_us"] = quantile(changed_us, 0.99);
  state.counters["us_per_change"] = extra_solves > 0 ? (mean(changed_us) - mean(settled_us)) *
                                                           static_cast<double>(changed_us.size()) /
                                                           static_cast<double>(extra_solves)
                                                     : 0.0;
  reads.report(state);
  state.SetItemsProcessed(static_cast<std::int64_t>(tick_us.size()));
}

void BM_press_glide(benchmark::State& state) {
  run_gesture(state, 1,
              {{0, 0, 0, 1},
               {0.005, 0, 0, 500},
               {0.005, 0, 0, 500},
               {0.005, 0.020, 0, 2000},
               {0, 0.020, 0, 500},
               {0, 0.020, 0, 500}});
}
void BM_two_tools(benchmark::State& state) {
  run_gesture(state, 2,
              {{0, 0, 0, 1},
               {0.005, 0, 0, 500},
               {0.005, 0, 0, 500},
               {0.005, 0.020, 0, 2000},
               {0, 0.020, 0, 500},
               {0, 0.020, 0, 500}});
}
void BM_wide_press(benchmark::State& state) {
  run_gesture(state, 1,
              {{0, 0, 0, 1},
               {0.008, 0, 0, 500},
               {0.008, 0, 0, 500},
               {0.008, 0.020, 0, 2000},
               {0, 0.020, 0, 500},
               {0, 0.020, 0, 500}},
              0.015);
}
/// A 50 mm frictionless sphere (a palm, a retractor's blade) pressed 10 mm
/// and glided: up to 64 contact points on one tool (issue 17's target:
/// p99 ≤ 100 µs per tick).
void BM_wide_press_64(benchmark::State& state) {
  run_gesture(state, 1,
              {{0, 0, 0, 1},
               {0.010, 0, 0, 500},
               {0.010, 0, 0, 500},
               {0.010, 0.020, 0, 2000},
               {0, 0.020, 0, 500},
               {0, 0.020, 0, 500}},
              0.025, 0.0, 64, 64, true);
}
/// A 200 mm frictionless sphere, nearly a plate, pressed 15 mm and glided,
/// 64 rows for the tool: the 64 contact points of issue 17's target on h8.
void BM_press_64(benchmark::State& state) {
  run_gesture(state, 1,
              {{0, 0, 0, 1},
               {0.015, 0, 0, 500},
               {0.015, 0, 0, 500},
               {0.015, 0.020, 0, 2000},
               {0, 0.020, 0, 500},
               {0, 0.020, 0, 500}},
              0.1, 0.0, 64, 128, true);
}
void BM_grasp_pull(benchmark::State& state) {
  run_gesture(state, 1,
              {{0, 0, 40, 1},
               {0.003, 0, 40, 500},
               {0.003, 0, 0, 400},
               {-0.007, 0, 0, 1000},
               {-0.007, 0, 40, 400},
               {-0.010, 0, 40, 500}});
}
void BM_two_grasps(benchmark::State& state) {
  run_gesture(state, 2,
              {{0, 0, 40, 1},
               {0.003, 0, 40, 500},
               {0.003, 0, 0, 400},
               {-0.007, 0, 0, 1000},
               {-0.007, 0, 40, 400},
               {-0.010, 0, 40, 500}});
}

}  // namespace

BENCHMARK(palpate::bench::BM_dgemm)->Arg(512)->Unit(benchmark::kMillisecond);
#define PALPATE_BOTH_WAYS(name)       \
  BENCHMARK(name)                     \
      ->ArgName("incremental")        \
      ->Arg(0)                        \
      ->Arg(1)                        \
      ->Unit(benchmark::kMillisecond) \
      ->Iterations(5)
PALPATE_BOTH_WAYS(BM_press_glide);
PALPATE_BOTH_WAYS(BM_two_tools);
PALPATE_BOTH_WAYS(BM_wide_press);
PALPATE_BOTH_WAYS(BM_wide_press_64);
PALPATE_BOTH_WAYS(BM_press_64);
PALPATE_BOTH_WAYS(BM_grasp_pull);
PALPATE_BOTH_WAYS(BM_two_grasps);

int main(int argc, char** argv) {
  const std::string path = palpate::bench::take_model_path(argc, argv);
  if (path.empty()) {
    std::printf("palpate_contact_bench: give a compliance file (or PALPATE_BENCH_MODEL)\n");
    return 0;
  }
  palpate::ensure_optimized_blas(argv);
  // PALPATE_BENCH_FLOAT32=1: a float32 file's G stays float32 in memory.
  const palpate::SurfaceModel model = palpate::load_surface_model(
      "bench", path, palpate::bench::env_is_one("PALPATE_BENCH_FLOAT32"));
  g_model = &model;
  benchmark::Initialize(&argc, argv);
  benchmark::AddCustomContext("model", path);
  benchmark::AddCustomContext("compliance_vertices",
                              std::to_string(model.compliance_vertex_count()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
