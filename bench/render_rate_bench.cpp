// What one device step costs the device's loop: HapticRenderer::render (the
// local model at the device's pose, limits, the passivity observer) on a
// pressed contact's answer, in process, the device moving a little each
// step. The rate a device can render at is its inverse; issue 19 asks for
// at least 4 kHz (250 µs a step). Same-run baseline: the held answer
// (local_model = false), the least a renderer does.
//
// Usage: palpate_render_rate_bench [--benchmark_...]

#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <cmath>

#include "palpate/runtime/haptic_renderer.hpp"

namespace {

using Eigen::Vector3d;
using palpate::HapticRenderer;
using palpate::RenderAnswer;
using palpate::RenderSettings;

/// A press's answer: F₀ along +z, a full 6 × 6 stiffness.
RenderAnswer pressed() {
  RenderAnswer a;
  a.sequence = 1;
  a.model.valid = true;
  a.model.position_m = Vector3d(0.01, 0.02, 0.03);
  a.model.force_n = Vector3d(0.1, -0.05, 2.0);
  a.model.torque_nm = Vector3d(0.002, 0.001, -0.0005);
  for (int i = 0; i < 36; ++i) a.model.stiffness(i / 6, i % 6) = i % 7 == 0 ? -300.0 : 0.1 * i;
  a.fed_back_force_n = a.model.force_n;
  return a;
}

void render(benchmark::State& state, bool local_model, bool passivity) {
  RenderSettings settings;
  settings.local_model = local_model;
  settings.passivity = passivity;
  HapticRenderer renderer(settings);
  const RenderAnswer answer = pressed();
  double t = 0;
  std::uint64_t step = 0;
  for (auto _ : state) {
    if (step % 4 == 0) {  // a new answer every fourth step, as at 1 kHz
      RenderAnswer next = answer;
      next.sequence = step + 1;
      renderer.take(next, t);
    }
    const double phase = 1e-3 * static_cast<double>(step);
    const Vector3d x =
        answer.model.position_m + Vector3d(1e-4 * std::sin(phase), 0, -1e-4 * std::cos(3 * phase));
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.01 * std::sin(phase), Vector3d::UnitX()));
    benchmark::DoNotOptimize(renderer.render(t, x, q));
    t += 250e-6;
    ++step;
  }
}

void BM_render_local_model(benchmark::State& s) { render(s, true, true); }
void BM_render_local_model_without_observer(benchmark::State& s) { render(s, true, false); }
void BM_render_held_answer(benchmark::State& s) { render(s, false, true); }
BENCHMARK(BM_render_local_model);
BENCHMARK(BM_render_local_model_without_observer);
BENCHMARK(BM_render_held_answer);

}  // namespace

BENCHMARK_MAIN();
