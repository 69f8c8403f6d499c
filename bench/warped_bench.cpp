// What a warped request costs against the linear one, same run (docs/model/warped.md,
// "Large rotations: warped compliance"): a lift of the k = 6 compliance vertices
// nearest the surface point farthest from the attachment, rotated by θ about
// the axis through the attachment's centroid perpendicular to the point's
// lever and its normal (so the patch swings up and away), on one core.
//
//   linear/θ   ConstraintSolver: the factorization reused, one solve
//   warped/θ   WarpedSolver: the fixed point (the counter `solves`), each
//              solve a reused factorization plus the field u = G f̂ over the
//              whole surface and the rotations ω = S Ω u
//   rotations  RotationField::rotations alone, the whole surface
//   tick_linear/tick_warped  the contact engine's tick, linear and warped
//              (ρ = kToolEdges median edges), on the same poses, interleaved
//              tick by tick: one grasper pressing 4 mm at the patch's seed,
//              gliding 10 mm, closing its jaws and pulling 5 mm out; p50
//              and p99 per tick (the target: warped within 2× linear)
//
// Usage: palpate_warped_bench [MODEL.h5] [--benchmark_...]
//        (or PALPATE_BENCH_MODEL=MODEL.h5); without a model it says so and exits 0.

#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "common.hpp"
#include "palpate/core/rotation.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "palpate/runtime/warped_solver.hpp"
#include "patch.hpp"

namespace {

struct Lift {
  palpate::SurfaceModel model;
  palpate::RotationField field;
  std::vector<std::uint32_t> ids;
  std::vector<Eigen::Vector3d> rest;
  Eigen::Vector3d pivot, axis;

  explicit Lift(const std::string& path)
      : model(palpate::load_surface_model("bench", path)),
        field(model.surface, palpate::default_smoothing_radius(model.surface)) {
    const auto& s = model.surface;
    pivot.setZero();
    for (int v = s.compliance_vertex_count; v < s.vertex_count(); ++v) pivot += s.rest_position(v);
    pivot /= std::max(1, s.vertex_count() - s.compliance_vertex_count);
    int far = 0;
    for (int v = 0; v < s.compliance_vertex_count; ++v)
      if ((s.rest_position(v) - pivot).norm() > (s.rest_position(far) - pivot).norm()) far = v;
    const auto patch = palpate::bench::nearest_patch(s, far, 6);
    ids = patch.vertex_ids;
    for (const auto id : ids) rest.push_back(s.rest_position(model.compliance_index_of_vertex[id]));
    const Eigen::Vector3d lever = s.rest_position(far) - pivot;
    const Eigen::Vector3d n(-patch.inward_normal[0], -patch.inward_normal[1],
                            -patch.inward_normal[2]);
    axis = n.cross(lever).normalized();
  }

  template <typename Solver>
  palpate::RequestStatus run(Solver& solver, double degrees) const {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(degrees * M_PI / 180, axis).toRotationMatrix();
    solver.begin(ids.size());
    const double normal[3] = {0, 0, 0};
    for (std::size_t j = 0; j < ids.size(); ++j) {
      const Eigen::Vector3d d = pivot + R * (rest[j] - pivot) - rest[j];
      solver.add(ids[j], 1, d.data(), normal);
    }
    return solver.solve();
  }
};

Lift* lift = nullptr;

void BM_linear(benchmark::State& state) {
  palpate::ConstraintSolver solver(lift->model, {});
  for (auto _ : state)
    if (lift->run(solver, static_cast<double>(state.range(0))) != palpate::RequestStatus::kOk)
      state.SkipWithError(solver.message());
}

void BM_warped(benchmark::State& state) {
  palpate::WarpedSolver solver(lift->model, {}, lift->field);
  for (auto _ : state)
    if (lift->run(solver, static_cast<double>(state.range(0))) != palpate::RequestStatus::kOk)
      state.SkipWithError(solver.message());
  state.counters["solves"] = solver.iterations();
  state.counters["force_N"] = solver.total_force().norm();
}

void BM_rotations(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(lift->model.compliance_rows());
  std::vector<double> u(n, 1e-3), omega(n);
  for (auto _ : state) {
    lift->field.rotations(u, omega);
    benchmark::DoNotOptimize(omega.data());
  }
  state.counters["neighbours"] = lift->field.mean_neighbourhood();
}

/// Both engines on the same gesture, tick by tick; per-tick times of each.
void BM_tick(benchmark::State& state) {
  const auto& m = lift->model;
  const palpate::RotationField tool_field(
      m.surface, palpate::default_smoothing_radius(m.surface, palpate::kToolEdges));
  palpate::ToolGeometry g;
  g.id = "grasper";
  palpate::ToolContactEngine linear(m, {g}, {}, {});
  palpate::ToolContactEngine warped(m, {g}, {}, {}, &tool_field);
  const int seed = palpate::bench::main_seed(m.surface);
  const auto n = palpate::bench::inward_normal(m.surface, seed);
  const Eigen::Vector3d inward(n[0], n[1], n[2]), tangent = inward.unitOrthogonal();
  const Eigen::Quaterniond orientation = palpate::rotation_taking(Eigen::Vector3d::UnitZ(), inward);
  const Eigen::Vector3d start =
      m.surface.rest_position(seed) - (g.tip_length_m + g.tip_radius_m + 0.002) * inward;
  std::vector<double> times[2];
  std::uint64_t sequence = 0;
  double now = 0;
  for (auto _ : state) {
    for (int i = 0; i < 1500; ++i) {
      // 0–400 press to 4 mm, 400–900 glide 10 mm, 900–1000 close, then pull 5 mm.
      const double depth =
          0.002 + 0.004 * std::min(1.0, i / 400.0) - (i > 1000 ? 0.005 * (i - 1000) / 500.0 : 0.0);
      const double slide = 0.010 * std::clamp((i - 400) / 500.0, 0.0, 1.0);
      const double jaw = i < 900 ? 30.0 : std::max(0.0, 30.0 - 0.3 * (i - 900));
      palpate::ToolPoseInput pose;
      pose.sequence = ++sequence;
      pose.position_m = start + depth * inward + slide * tangent;
      pose.orientation = orientation;
      pose.jaw_angle_rad = palpate::degrees(jaw);
      now += 1e-3;
      palpate::ToolContactEngine* engines[2] = {&linear, &warped};
      for (int e = 0; e < 2; ++e) {
        const auto t0 = std::chrono::steady_clock::now();
        engines[e]->update(0, pose, now);
        times[e].push_back(
            std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0)
                .count());
      }
    }
  }
  for (int e = 0; e < 2; ++e) {
    auto& t = times[e];
    std::sort(t.begin(), t.end());
    const char* name = e == 0 ? "linear" : "warped";
    state.counters[std::string(name) + "_p50_us"] = t[t.size() / 2];
    state.counters[std::string(name) + "_p99_us"] =
        t[static_cast<std::size_t>(0.99 * (t.size() - 1))];
  }
  state.counters["held"] = warped.output(0).held;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string path = palpate::bench::take_model_path(argc, argv);
  if (path.empty()) {
    std::printf("palpate_warped_bench: no model (give MODEL.h5 or PALPATE_BENCH_MODEL)\n");
    return 0;
  }
  Lift loaded(path);
  lift = &loaded;
  std::printf("warped bench: %s, %d compliance vertices, radius %.4g m\n", path.c_str(),
              loaded.model.compliance_vertex_count(), loaded.field.smoothing_radius_m());
  for (const int degrees : {1, 15, 30}) {
    benchmark::RegisterBenchmark("linear", BM_linear)->Arg(degrees)->Unit(benchmark::kMicrosecond);
    benchmark::RegisterBenchmark("warped", BM_warped)->Arg(degrees)->Unit(benchmark::kMicrosecond);
  }
  benchmark::RegisterBenchmark("rotations", BM_rotations)->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("tick", BM_tick)->Unit(benchmark::kMillisecond)->Iterations(3);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
