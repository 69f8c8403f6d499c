// Writes the known session that tests/scripts/session_report_test.py and
// tests/scripts/session_plots_test.py check scripts/session_report.py and
// scripts/session_plots.py against (its values are computed by hand there).
// Usage: palpate_session_writer_for_tests OUT.h5 [--crash]
//   --crash: wait until every tick is flushed, then SIGKILL this process, so
//   that OUT.h5.partial is left as a crash leaves it.
//
// Tool "left", 1000 ticks at 1 kHz (t = k ms), x = k·0.1 mm:
//   free [0,200) touching [200,500) grasping [500,600) touching [600,650)
//   grasping [650,700) free [700,1000); |force| 2 N touching, 3 N grasping
//   (5 N at k = 550); grip 1.5 N grasping (2.5 N at k = 660); contacts:
//   1 + k mod 3 touching, 4 grasping. compute 20 µs + 10 ns·k for k < 985,
//   150 µs + 1 µs·(k − 985) for the 15 slow ticks k ≥ 985 (nearest-rank
//   p50 25 µs, p99 154 µs).
// Tool "right", 500 ticks at 500 Hz (t = 2k ms), y = k mm: touching
//   [100,200) with 1 N, free otherwise; one contact while touching; compute
//   40 µs + 20 ns·k (p50 45 µs, p99 49.88 µs).
// Events: left touch, grasp, release, grasp, release, leave; right touch, leave.
// What left's device rendered: 4 steps per tick over ticks [200, 300), at
//   send_time_ns + j·0.25 ms, force z 2 + 0.1 j N (j = 0..3); right: none.

#include <signal.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <thread>
#include <vector>

#include "palpate/runtime/session_recorder.hpp"

namespace {

using palpate::ToolState;

ToolState left_state(int k) {
  if (k < 200 || k >= 700) return ToolState::kFree;
  if ((k >= 500 && k < 600) || k >= 650) return ToolState::kGrasping;
  return ToolState::kTouching;
}

void record(palpate::SessionRecorder& recorder, const palpate::ToolTickRecord& t, int contacts) {
  std::vector<std::uint32_t> ids;
  std::vector<double> forces;
  for (int i = 0; i < contacts; ++i) {
    ids.push_back(static_cast<std::uint32_t>(100 * t.tool + i));
    for (int j = 0; j < 3; ++j) forces.push_back(-t.force_n[j] / contacts);
  }
  // The default ring holds the whole session: nothing is refused.
  if (!recorder.record(t, ids, forces)) throw std::runtime_error("a tick was refused");
}

void write(const char* out, bool crash) {
  palpate::SessionInfo info;
  info.model_id = "sample-organ";
  info.model_file = "out/sample-organ.h5";
  info.input_hash = "sha256:test";
  info.daemon_id = "palpated";
  info.tools.resize(2);
  info.tools[0].id = "left";
  info.tools[1].id = "right";
  info.start_unix_ns = 1'700'000'000'000'000'000;
  palpate::RecorderLimits limits;
  limits.write_interval_s = 0.01;
  limits.flush_interval_s = 0.02;
  palpate::SessionRecorder recorder(out, info, limits);

  // Events first: when the last tick is flushed, so are they (--crash).
  using K = palpate::ToolEventKind;
  recorder.record_event(0.200, 0, K::kTouch, 201);
  recorder.record_event(0.500, 0, K::kGrasp, 501);
  recorder.record_event(0.600, 0, K::kRelease, 601);
  recorder.record_event(0.650, 0, K::kGrasp, 651);
  recorder.record_event(0.700, 0, K::kRelease, 701);
  recorder.record_event(0.700, 0, K::kLeave, 701);
  recorder.record_event(0.200, 1, K::kTouch, 101);
  recorder.record_event(0.400, 1, K::kLeave, 201);

  for (int k = 0; k < 1000; ++k) {
    palpate::ToolTickRecord t;
    t.tool = 0;
    t.time_s = k * 1e-3;
    t.sequence = static_cast<std::uint64_t>(k + 1);
    t.send_time_ns = 1'000'000'000 + k * 1'000'000;
    t.position_m[0] = k * 1e-4;
    t.orientation_wxyz[0] = 1;
    t.state = left_state(k);
    const bool grasping = t.state == ToolState::kGrasping;
    if (t.state == ToolState::kTouching) t.force_n[2] = 2;
    if (grasping) t.force_n[2] = 3;
    if (k == 550) {
      t.force_n[1] = 3;
      t.force_n[2] = 4;
    }
    t.grip_n = grasping ? (k == 660 ? 2.5 : 1.5) : 0;
    t.held = grasping ? 4 : 0;
    t.compute_ns = k < 985 ? 20'000 + 10 * static_cast<std::uint64_t>(k)
                           : 150'000 + 1'000 * static_cast<std::uint64_t>(k - 985);
    record(recorder, t, t.state == ToolState::kFree ? 0 : grasping ? 4 : 1 + k % 3);
    for (int j = 0; j < 4 && k >= 200 && k < 300; ++j) {
      palpate::RenderedRecord r;
      r.tool = 0;
      r.time_ns = t.send_time_ns + j * 250'000;
      r.answer_sequence = t.sequence;
      r.position_m[0] = t.position_m[0];
      r.force_n[2] = 2 + 0.1 * j;
      if (!recorder.record_rendered(r)) throw std::runtime_error("a rendered step was refused");
    }
  }
  for (int k = 0; k < 500; ++k) {
    palpate::ToolTickRecord t;
    t.tool = 1;
    t.time_s = k * 2e-3;
    t.sequence = static_cast<std::uint64_t>(k + 1);
    t.position_m[1] = k * 1e-3;
    t.orientation_wxyz[0] = 1;
    const bool touching = k >= 100 && k < 200;
    t.state = touching ? ToolState::kTouching : ToolState::kFree;
    t.force_n[0] = touching ? 1 : 0;
    t.compute_ns = 40'000 + 20 * static_cast<std::uint64_t>(k);
    record(recorder, t, touching ? 1 : 0);
  }
  if (crash) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (recorder.flushed() < recorder.recorded()) {
      if (std::chrono::steady_clock::now() > deadline) throw std::runtime_error("no flush in 60 s");
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    raise(SIGKILL);
  }
  recorder.close();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || (argc == 3 && std::strcmp(argv[2], "--crash") != 0) || argc > 3) {
    std::fprintf(stderr, "usage: %s OUT.h5 [--crash]\n", argv[0]);
    return 2;
  }
  try {
    write(argv[1], argc == 3);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 1;
  }
  return 0;
}
