// The hybrid model as served (issue 20): one haptic tick of the cuttable
// region — HybridRegion::advance over 1 ms: u_Γ⁰ = G_ΓS f_S from eight loads
// on the rest, the region's step with the coupling and a tip pressing its
// surface, then f_Γ = S (u_Γ − u_Γ⁰) — and one cut (HybridRegion::cut: the
// blade's query, the removals, the Γ vertices released, and the step's
// update), on the sample organ with balls of two radii at its lower front
// (docs/benchmarks-history.md, "The hybrid model as served"). Targets: a tick p99 ≤
// 500 µs at up to 2,000 tetrahedra, a cut ≤ 10 ms. The served step is the
// implicit one (one backward-Euler step per tick); same-run baselines: the
// explicit substeps it replaced, on the same loads, and those substeps of
// the uncoupled TensorMassModel::step alone. Cuts are timed with a tick
// after each (a blade moving through the region, one cut per tick: what
// the Woodbury update adds to the tick, and when the worker's
// refactorization lands). And the contact tick of a probe on the rest next
// to the region, with the region's push as background loads and without
// (what they cost), and the whole served tick around it: that contact
// tick, the region's step under the probe's loads, its push to the engine.
//
//   build/bench/palpate_hybrid_tick_bench [mesh_size_m] [ticks] [ball_radius_mm: 16 or 25]
//
// A small timed program: every tick and every cut is timed; the
// percentiles are printed.

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "palpate/core/rotation.hpp"
#include "palpate/core/statistics.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/hybrid_region.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "palpate/runtime/tool_tick.hpp"

namespace {

using namespace palpate;
using Clock = std::chrono::steady_clock;
using Eigen::Vector3d;

double microseconds(Clock::time_point since) {
  return std::chrono::duration<double, std::micro>(Clock::now() - since).count();
}

struct Quantiles {
  double p50, p99, max;
};
Quantiles quantiles(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return {sorted_percentile(v, 0.5), sorted_percentile(v, 0.99), v.empty() ? 0 : v.back()};
}

// The ball's centre: (40, 0, −34.64) mm is on the sample organ's surface.
const Vector3d kCentre(0.040, 0, -0.03464);

void run(const std::filesystem::path& dir, double radius_m, int ticks) {
  PrecomputeJob job;
  job.mesh_file = dir / "organ.msh";
  job.young_modulus_pa = 85e3;
  job.poisson_ratio = 0.45;
  job.attachment.spheres.push_back({Vector3d(-0.03, 0, 0.04), 0.025});
  job.cut_region = CutRegionJob{RegionSpec::sphere(kCentre, radius_m), 1060, 20};
  job.output = dir / "organ-cut.h5";
  job.write_xdmf = false;
  run_precompute(job, {});
  const SurfaceModel model = load_surface_model("organ", job.output);
  auto construction = Clock::now();
  HybridRegion region(model);
  const double construction_ms = microseconds(construction) / 1e3;
  const double first_factorization_ms = region.last_factorization_s() * 1e3;
  HybridRegionSettings explicit_settings;
  explicit_settings.integrator = RegionIntegrator::kExplicit;
  HybridRegion explicit_region(model, explicit_settings);
  const CutRegionData& data = *model.cut_region;

  // Eight loads on the rest (0.1 N inward), the compliance vertices nearest
  // a point on its top; a 4 mm sphere pressing the region's surface 2 mm
  // deep at its lowest point, sliding 5 mm along y and back each second.
  std::vector<int> rest_indices;
  std::vector<double> rest_forces;
  std::vector<std::pair<double, int>> by_distance;
  for (int a = 0; a < model.compliance_vertex_count(); ++a)
    by_distance.emplace_back((model.surface.rest_position(a) - Vector3d(0, 0, 0.04)).norm(), a);
  std::partial_sort(by_distance.begin(), by_distance.begin() + 8, by_distance.end());
  for (int i = 0; i < 8; ++i) {
    rest_indices.push_back(by_distance[static_cast<std::size_t>(i)].second);
    rest_forces.insert(rest_forces.end(), {0, 0, -0.1});
  }
  int lowest = 0;
  for (int v = 0; v < static_cast<int>(data.vertices_m.rows()); ++v)
    if (data.vertices_m(v, 2) < data.vertices_m(lowest, 2)) lowest = v;
  const Vector3d touch = data.vertices_m.row(lowest).transpose();
  const double r = 0.004;

  TensorMassModel uncoupled(
      data.vertices_m, data.tetrahedra,
      [&] {
        std::vector<Matrix12d> k(static_cast<std::size_t>(data.tetrahedra.rows()));
        for (Eigen::Index t = 0; t < data.tetrahedra.rows(); ++t)
          for (int i = 0; i < 12; ++i)
            for (int j = 0; j < 12; ++j)
              k[static_cast<std::size_t>(t)](i, j) = data.element_stiffness_n_per_m(t, 12 * i + j);
        return k;
      }(),
      {data.density_kg_m3, data.damping_per_s},
      std::vector<int>(data.fixed_vertices.begin(), data.fixed_vertices.end()));
  const Eigen::VectorXd no_load = Eigen::VectorXd::Zero(3 * data.vertices_m.rows());

  const auto tip_at = [&](int n) {
    const double y = 0.005 * std::sin(2 * 3.14159265358979 * n * 1e-3);
    return RegionTip{touch + Vector3d(0, y, r - 0.002), touch + Vector3d(0, y, r - 0.002), r};
  };
  std::vector<double> tick_us, explicit_us, baseline_us;
  long substeps = 0;
  // Each region's ticks in a loop of their own: interleaved, each would
  // evict the other's dense matrices from the caches.
  for (int n = 0; n < ticks; ++n) {
    const RegionTip tip = tip_at(n);
    const auto start = Clock::now();
    region.advance(1e-3, rest_indices, rest_forces, {&tip, 1});
    tick_us.push_back(microseconds(start));
  }
  for (int n = 0; n < ticks; ++n) {
    const RegionTip tip = tip_at(n);
    const auto start = Clock::now();
    explicit_region.advance(1e-3, rest_indices, rest_forces, {&tip, 1});
    explicit_us.push_back(microseconds(start));
    substeps += explicit_region.substeps();
    const auto base = Clock::now();
    for (int s = 0; s < explicit_region.substeps(); ++s)
      uncoupled.step(explicit_region.substep_s(), no_load);
    baseline_us.push_back(microseconds(base));
  }
  const Quantiles tick = quantiles(tick_us), explicit_tick = quantiles(explicit_us),
                  base = quantiles(baseline_us);

  // The contact tick next to the region: a 3 mm sphere 1.5 mm into the
  // rest's surface at its vertex off Γ nearest the ball, 3–8 mm outside it,
  // with the region's push as background loads (what palpated does), and
  // the same engine without them (same run, same poses).
  const Eigen::MatrixX3d normals = vertex_normals(model.surface);
  int near = -1;
  std::vector<char> on_gamma(static_cast<std::size_t>(model.compliance_vertex_count()), 0);
  for (int a : region.interface_compliance_indices()) on_gamma[static_cast<std::size_t>(a)] = 1;
  for (int a = 0; a < model.compliance_vertex_count(); ++a) {
    if (on_gamma[static_cast<std::size_t>(a)] != 0) continue;  // Γ: the cavity's wall too
    const double d = (model.surface.rest_position(a) - kCentre).norm();
    if (d > radius_m + 0.003 && d < radius_m + 0.008 &&
        (near < 0 || d < (model.surface.rest_position(near) - kCentre).norm()))
      near = a;
  }
  ToolGeometry probe;
  probe.id = "probe";
  probe.tip = TipShape::kSphere;
  probe.tip_radius_m = 0.003;
  probe.tip_length_m = 0;
  probe.jaw_length_m = 0;
  probe.friction = 0;
  // Served as palpated serves it (ToolTick: the contact solve with the
  // region's push as background loads, the region's step, its push to the
  // engine, the answer), and a bare engine on the rest without the region.
  ToolTick served_tick(model, {probe}, {}, {}, nullptr, &region);
  ToolContactEngine without(model, {probe}, {}, {});
  std::vector<double> without_us, served_us;
  if (near >= 0) {
    const Vector3d n = normals.row(near).transpose();
    ToolPoseInput pose;
    pose.position_m = model.surface.rest_position(near) + (probe.tip_radius_m - 0.0015) * n;
    pose.orientation = palpate::rotation_taking(Vector3d::UnitZ(), -n);
    for (int step = 1; step <= 2000; ++step) {
      pose.sequence = static_cast<std::uint64_t>(step);
      served_tick.engine().check(0, pose);
      auto start = Clock::now();
      served_tick.update(0, pose, 1e-3 * step);
      served_us.push_back(microseconds(start));
      without.check(0, pose);
      start = Clock::now();
      without.update(0, pose, 1e-3 * step);
      without_us.push_back(microseconds(start));
    }
  }
  const Quantiles contact_without = quantiles(without_us), served = quantiles(served_us);
  const int contacts = near >= 0 ? served_tick.output(0).contacts : -1;

  // An incision at 20 mm/s (a brisk one): a vertical blade 30 mm long
  // through the ball's centre swept 0.02 mm along y per 1 ms tick across
  // the ball (HybridRegion::cut(before, after), as palpated cuts), each
  // cut and each tick timed, the implicit region only (the served one).
  std::vector<double> incision_cut_us, incision_tick_us;
  int incision_factorizations = 0;
  double incision_factorization_ms = 0;
  {
    HybridRegion incised(model);
    const auto blade_at = [&](double y) {
      return Blade{kCentre + Vector3d(0, y, 0.015), kCentre + Vector3d(0, y, -0.015)};
    };
    Blade before = blade_at(-radius_m);
    int step = 0;
    for (double y = -radius_m + 2e-5; y <= radius_m; y += 2e-5, ++step) {
      const Blade after = blade_at(y);
      auto start = Clock::now();
      incised.cut(before, after);
      incision_cut_us.push_back(microseconds(start));
      before = after;
      const RegionTip tip = tip_at(step);
      start = Clock::now();
      incised.advance(1e-3, rest_indices, rest_forces, {&tip, 1});
      incision_tick_us.push_back(microseconds(start));
    }
    incision_factorizations = incised.factorizations();
    incision_factorization_ms = incised.last_factorization_s() * 1e3;
  }
  const Quantiles incision_cut = quantiles(incision_cut_us),
                  incision_tick = quantiles(incision_tick_us);

  // The stress case: the same blade 0.5 mm per cut (0.5 m/s), a tick of
  // each region after each cut.
  std::vector<double> cut_us, explicit_cut_us, cutting_tick_us;
  int removed = 0, cuts_that_removed = 0, n = 0;
  for (double y = -radius_m; y <= radius_m; y += 5e-4, ++n) {
    const Vector3d a = kCentre + Vector3d(0, y, 0.015), b = kCentre + Vector3d(0, y, -0.015);
    auto start = Clock::now();
    const int k = region.cut(a, b);
    cut_us.push_back(microseconds(start));
    start = Clock::now();
    explicit_region.cut(a, b);
    explicit_cut_us.push_back(microseconds(start));
    removed += k;
    cuts_that_removed += k > 0;
    const RegionTip tip = tip_at(n);
    start = Clock::now();
    region.advance(1e-3, rest_indices, rest_forces, {&tip, 1});
    cutting_tick_us.push_back(microseconds(start));
    explicit_region.advance(1e-3, rest_indices, rest_forces, {&tip, 1});
  }
  const Quantiles cut = quantiles(cut_us), explicit_cut = quantiles(explicit_cut_us),
                  cutting_tick = quantiles(cutting_tick_us);

  region.finish_background_work();
  std::printf(
      "ball %.0f mm: %d tetrahedra, %d vertices, %zu on Γ; the region built in %.1f ms (S, its "
      "eigenvalues, A factored in %.1f ms)\n"
      "  implicit tick (advance 1 ms, one step): p50 %.1f µs, p99 %.1f µs, max %.1f µs\n"
      "  baseline, explicit (substep %.1f µs, %.2f per tick): p50 %.1f µs, p99 %.1f µs, max "
      "%.1f µs\n"
      "  baseline, the same substeps of the uncoupled step alone: p50 %.1f µs, p99 %.1f µs\n"
      "  stress: cut (0.5 mm per cut, %zu blades, %d removing, %d tetrahedra in all), implicit: "
      "p50 %.1f µs, p99 %.1f "
      "µs, max %.1f µs; A factored %d times in all, update rank at the end %d; explicit: p50 "
      "%.1f µs, p99 %.1f µs, max %.1f µs; Γ vertices still held %zu\n"
      "  implicit tick after each cut: p50 %.1f µs, p99 %.1f µs, max %.1f µs\n"
      "  an incision at 20 mm/s (%zu ticks, A factored %d times, the last in %.1f ms): cut p50 "
      "%.1f µs, p99 %.1f µs, "
      "max %.1f µs; tick "
      "p50 %.1f µs, p99 %.1f µs, max %.1f µs\n"
      "  contact tick next to the region (%d contacts), baseline without the region: p50 %.1f "
      "µs, p99 %.1f µs\n"
      "  served tick (ToolTick::update: that contact tick with the region's push as background "
      "loads, the region's step, its push to the engine): p50 %.1f µs, p99 %.1f µs, max %.1f "
      "µs\n",
      radius_m * 1e3, static_cast<int>(data.tetrahedra.rows()),
      static_cast<int>(data.vertices_m.rows()),
      static_cast<std::size_t>(data.interface_vertices.size()), construction_ms,
      first_factorization_ms, tick.p50, tick.p99, tick.max, explicit_region.substep_s() * 1e6,
      static_cast<double>(substeps) / ticks, explicit_tick.p50, explicit_tick.p99,
      explicit_tick.max, base.p50, base.p99, cut_us.size(), cuts_that_removed, removed, cut.p50,
      cut.p99, cut.max, region.factorizations(), region.update_rank(), explicit_cut.p50,
      explicit_cut.p99, explicit_cut.max, region.interface_vertices().size(), cutting_tick.p50,
      cutting_tick.p99, cutting_tick.max, incision_cut_us.size(), incision_factorizations,
      incision_factorization_ms, incision_cut.p50, incision_cut.p99, incision_cut.max,
      incision_tick.p50, incision_tick.p99, incision_tick.max, contacts, contact_without.p50,
      contact_without.p99, served.p50, served.p99, served.max);
}

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  palpate::set_blas_threads(1);  // as palpated: the haptic tick's products on its own thread
  const double size_m = argc > 1 ? std::atof(argv[1]) : 0.004;
  const int ticks = argc > 2 ? std::atoi(argv[2]) : 5000;
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("palpate-hybrid-bench-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  write_sample_organ(dir / "organ.msh", size_m);
  std::printf("sample organ at %.1f mm, %s\n", size_m * 1e3, palpate::utc_timestamp().c_str());
  for (const double radius_m : {0.016, 0.025})
    if (argc <= 3 || std::atof(argv[3]) * 1e-3 == radius_m) run(dir, radius_m, ticks);
  std::filesystem::remove_all(dir);
}
