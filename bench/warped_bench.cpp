// What a warped request costs against the linear one, same run (docs/model.md,
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
//
// Usage: palpate_warped_bench [MODEL.h5] [--benchmark_...]
//        (or PALPATE_BENCH_MODEL=MODEL.h5); without a model it says so and exits 0.

#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <string>
#include <vector>

#include "common.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/surface_model.hpp"
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
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
