// palpate-pliers: a haptic device in software. Plays a gesture file
// (docs/pliers.md) over DDS for one or two tools through palpate's C API
// for devices (palpate/device.h), as a device's servo loop would: at the
// device's rate (4 kHz) it gives each tool's pose and renders the newest
// answer's local contact model there; at the haptic rate (1 kHz) a pose goes
// to palpated, whose answer is awaited until the next tick and recorded with
// its round trip, force, grip and state, beside what was rendered. Prints a
// summary per tool; --csv writes every tick, --json the summary. Ends each
// tool's session when done (palpate_tool_command END), so that palpated lets
// go at once rather than by its watchdog.
//
// Exit codes: 0 played; 2 bad command line, gesture file or model (unknown
// model id, unknown tool, anchor), or palpated refused poses (its reason is
// printed: a jaw angle over the tool's limit, a pose out of the workspace);
// 3 palpated did not answer (no model description or no tool-pose reader
// within --timeout, or no feedback at all for a tool); 5 DDS failed; 130
// interrupted (the summary is still printed).

#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/core/statistics.hpp"
#include "palpate/core/suggest.hpp"
#include "palpate/device.h"
#include "palpate/runtime/gesture.hpp"
#include "palpate/runtime/tool_state.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/presence.hpp"
#include "palpate/transport/realtime.hpp"
#include "pliers_report.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using palpate::ToolEventKind;
using palpate::ToolState;
using namespace palpate::pliers;

constexpr int kNoAnswer = 3;  // palpated did not answer (see the header comment)

/// palpated is not there, or does not answer: exit 3.
struct NoAnswer : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::atomic<bool> interrupted{false};
extern "C" void on_signal(int) { interrupted = true; }

void fill(TickRecord& r, const palpate_device_answer& a) {
  r.rtt_us = static_cast<double>(a.receive_time_ns - a.send_time_ns) * 1e-3;
  r.force_n = {a.force_n[0], a.force_n[1], a.force_n[2]};
  r.grip_n = a.grip_n;
  r.contacts = a.contacts;
  r.state = static_cast<ToolState>(a.tool_state);
  r.force_limited = a.force_limited != 0;
  r.watchdog = a.watchdog != 0;
  r.compute_us = static_cast<double>(a.compute_ns) * 1e-3;
}

/// A failed call of the C API (palpate/device.h) as the exception of its
/// class: the exit code palpate-pliers gives it (docs/errors.md).
[[noreturn]] void throw_device_error(int status, const char* message) {
  switch (status) {
    case PALPATE_DEVICE_E_NO_PALPATED:
    case PALPATE_DEVICE_E_NO_TOOLS:
      throw NoAnswer(message);
    case PALPATE_DEVICE_E_NO_MODEL:
      throw palpate::InputError(std::string(message) + " (use --model)");
    case PALPATE_DEVICE_E_ARGUMENT:
    case PALPATE_DEVICE_E_CONFIG:
      throw palpate::InputError(message);
    case PALPATE_DEVICE_E_DDS:
      throw palpate::SystemError(message);
    default:
      throw std::runtime_error(std::string("palpate/device.h: ") +
                               palpate_device_status_name(status) + ": " + message);
  }
}

struct Settings {
  std::string gesture_file, model_id = "sample-organ", csv, json;
  std::vector<std::string> only_tools;
  double rate_hz = 1000, device_rate_hz = 4000, timeout_s = 10, warmup_s = 0;
  int repeat = 1;
  bool busy_wait = false, quiet = false;
  std::uint32_t domain = 0;
  std::string dds_config;
  palpate::RealtimeOptions realtime;  // --rt-priority, --cpus, --lock-memory (docs/realtime.md)
  std::string cpus;
};

int run(int argc, char** argv) {
  Settings o;
  CLI::App app{
      "palpate-pliers: plays a gesture file on palpated's tool topics at the haptic rate and "
      "measures the round trip (docs/pliers.md)"};
  app.add_option("gesture", o.gesture_file, "gesture file (TOML, e.g. config/gestures/press.toml)")
      ->required();
  app.add_option("--model", o.model_id, "model id palpated serves (default sample-organ)");
  app.add_option("--tool", o.only_tools,
                 "play only this tool of the gesture (repeatable; default: all)")
      ->allow_extra_args(false);
  app.add_option("--rate", o.rate_hz, "ticks per second (default 1000)")
      ->check(CLI::Range(10.0, 20000.0));
  app.add_option("--device-rate", o.device_rate_hz,
                 "device steps per second: the local model rendered (default 4000; a multiple of "
                 "--rate, at least it)")
      ->check(CLI::Range(10.0, 20000.0));
  app.add_option("--repeat", o.repeat, "play the gesture this many times in a row (default 1)")
      ->check(CLI::Range(1, 100000));
  app.add_option("--warmup", o.warmup_s,
                 "seconds played first but left out of the summary (default 0)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag(
      "--busy-wait", o.busy_wait,
      "poll for each feedback instead of sleeping on a waitset (keeps a core busy while waiting)");
  app.add_option("--timeout", o.timeout_s,
                 "seconds to wait for palpated and the model (default 10)")
      ->check(CLI::PositiveNumber);
  app.add_option("--csv", o.csv, "write every tick of every tool to this CSV file");
  app.add_option("--json", o.json, "write the summary to this JSON file");
  app.add_flag("-q,--quiet", o.quiet, "print only the summary (not the anchors and events)");
  app.add_option("--domain", o.domain, "DDS domain id")->check(CLI::Range(0, 232));
  app.add_option("--dds-config", o.dds_config,
                 "Cyclone DDS configuration (default: loopback only)");
  app.add_option("--rt-priority", o.realtime.priority,
                 "SCHED_FIFO priority (1-99) of the tick loop and of Cyclone's receive thread "
                 "(default 0: normal scheduling)");
  app.add_option("--cpus", o.cpus, "CPUs of the tick loop and Cyclone's threads, as taskset -c");
  app.add_flag("--lock-memory", o.realtime.lock_memory, "lock the process's memory (mlockall)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "palpate-pliers: error: %s%s (see --help)\n", e.what(),
                 palpate::flag_suggestions(std::vector<std::string>(argv + 1, argv + argc),
                                           palpate::long_flag_names(app))
                     .c_str());
    return static_cast<int>(palpate::ExitCode::kUsage);
  }

  // 1. The gesture, and the tools to play.
  const palpate::Gesture gesture = palpate::read_gesture_file(o.gesture_file);
  std::vector<ToolRun> runs;
  for (std::size_t t = 0; t < gesture.tools.size(); ++t)
    if (o.only_tools.empty() || std::find(o.only_tools.begin(), o.only_tools.end(),
                                          gesture.tools[t].id) != o.only_tools.end()) {
      ToolRun run;
      run.id = gesture.tools[t].id;
      run.gesture_index = static_cast<int>(t);
      runs.push_back(std::move(run));
    }
  for (const auto& wanted : o.only_tools)
    if (std::none_of(runs.begin(), runs.end(), [&](const ToolRun& r) { return r.id == wanted; })) {
      std::string ids;
      for (const auto& t : gesture.tools) ids += (ids.empty() ? "" : ", ") + t.id;
      throw palpate::InputError(
          fmt::format("--tool {}: not a tool of {} (its tools: {})", wanted, o.gesture_file, ids));
    }
  // 2. palpated: each tool opened through the C API (the model's
  // description, then palpated's tool topics, within --timeout in all).
  // Sequences start at the steady clock in µs, the same for every tool:
  // above those of any earlier run on this host (at most one per ms), so
  // that palpated never takes a new run's poses for stale ones of the last
  // (its watchdog resets a tool only 50 ms after its poses stop).
  const std::uint64_t first_sequence = static_cast<std::uint64_t>(palpate_device_now_ns() / 1000);
  // Real-time operation: the process's DDS domain made first, here, with
  // Cyclone's receive thread at the priority and on the CPUs; the tools'
  // clients join it (one domain per process).
  if (!o.cpus.empty()) o.realtime.cpus = palpate::realtime::parse_cpu_list(o.cpus, "--cpus");
  palpate::realtime::validate(o.realtime, palpate::realtime::kFlagNames);
  palpate::realtime::check_permitted(o.realtime, palpate::realtime::kFlagNames);
  const auto domain = palpate::dds::acquire_domain(
      o.domain, palpate::dds::resolve_domain_config(o.dds_config, o.realtime));
  const auto give_up = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(o.timeout_s));
  for (ToolRun& run : runs) {
    palpate_device_options options;
    palpate_device_options_init(&options);
    options.model_id = o.model_id.c_str();
    options.tool_id = run.id.c_str();
    options.domain_id = o.domain;
    options.dds_config = o.dds_config.c_str();
    options.pose_rate_hz = o.rate_hz;
    options.busy_wait = o.busy_wait ? 1 : 0;
    options.first_sequence = first_sequence - 1;  // the first pose is first_sequence
    // What was rendered goes into palpated's session recording.
    options.report_rendering = 1;
    // The first tool waits for palpated up to --timeout, the next ones for what is left.
    options.timeout_s = std::max(
        0.1, &run == &runs.front() ? o.timeout_s
                                   : std::chrono::duration<double>(give_up - Clock::now()).count());
    char error[512];
    palpate_device* device = nullptr;
    const int status = palpate_device_open(&options, &device, error, sizeof error);
    if (status != PALPATE_DEVICE_OK) throw_device_error(status, error);
    run.device.reset(device);
  }
  palpate_device_model description;
  description.struct_size = sizeof description;
  if (const int status =
          palpate_device_get_model(runs.front().device.get(), &description, nullptr, 0);
      status != PALPATE_DEVICE_OK)
    throw_device_error(status, "the model's description");
  palpate::DrawnSurface surface;
  surface.compliance_vertex_count = static_cast<int>(description.compliance_vertex_count);
  surface.vertex_ids.assign(description.vertex_ids,
                            description.vertex_ids + description.vertex_count);
  surface.rest_positions_m.assign(description.rest_positions_m,
                                  description.rest_positions_m + 3 * description.vertex_count);
  surface.triangles.assign(description.triangles,
                           description.triangles + 3 * description.triangle_count);
  // A served cut region: the rest's triangles it covers (one surface
  // sample's hidden_triangles) mark its interface, where no anchor goes.
  std::vector<std::uint32_t> covered;
  if (description.cut_region != nullptr && description.cut_region[0] != '\0') {
    palpate::Client viewer(palpate::ClientOptions{fmt::format("palpate-pliers-{}", first_sequence),
                                                  o.domain, o.dds_config, true, false});
    const auto sample = viewer.wait_surface(
        o.model_id, 1, 0,
        std::max(std::chrono::milliseconds(100),
                 std::chrono::duration_cast<std::chrono::milliseconds>(give_up - Clock::now())));
    if (!sample)
      throw NoAnswer(fmt::format(
          "model '{}' has a cut region ({}) but no surface sample came within --timeout: the "
          "anchors need the triangles it covers",
          o.model_id, description.cut_region));
    covered = sample->hidden_triangles;
  }
  const palpate::GesturePlayer player(gesture, palpate::place_gesture(gesture, surface, covered));

  // Ticks at --rate, each of `steps` device steps. One clock in integer ns
  // for the ticks and the C API's pose rate, so that the pose of tick i is
  // sent at its first step, exactly (palpate_device_set_pose: at most
  // pose_rate_hz, on the clock it is given).
  const auto period_ns = std::llround(1e9 / o.rate_hz);
  const double period_s = static_cast<double>(period_ns) * 1e-9;
  const auto period = std::chrono::nanoseconds(period_ns);
  const auto steps =
      static_cast<std::int64_t>(std::max(1.0, std::round(o.device_rate_hz / o.rate_hz)));
  const double device_rate_hz = static_cast<double>(steps) / period_s;
  const auto ticks_per_play =
      static_cast<std::size_t>(std::floor(player.duration_s() * o.rate_hz + 1e-9)) + 1;
  const std::size_t total = ticks_per_play * static_cast<std::size_t>(o.repeat);
  const auto first_counted =
      std::min(total, static_cast<std::size_t>(std::llround(o.warmup_s * o.rate_hz)));
  for (auto& r : runs) r.ticks.resize(total);
  if (!o.quiet) {
    std::printf("palpate-pliers: %s (%s), %.2f s × %d at %.0f Hz on model %s, %zu tool%s, %s\n",
                gesture.name.c_str(), o.gesture_file.c_str(), player.duration_s(), o.repeat,
                o.rate_hz, o.model_id.c_str(), runs.size(), runs.size() == 1 ? "" : "s",
                o.busy_wait ? "busy-wait" : "waitset");
    std::printf(
        "  rendering at %.0f Hz through palpate/device.h: the local model, the device's limits, "
        "passivity\n",
        device_rate_hz);
    for (const auto& r : runs) {
      const auto& a = player.anchor(r.gesture_index);
      std::printf(
          "  %s: anchor vertex %u at (%.4f, %.4f, %.4f) m, outward normal (%.3f, %.3f, %.3f)\n",
          r.id.c_str(), a.vertex_id, a.origin_m.x(), a.origin_m.y(), a.origin_m.z(), a.normal.x(),
          a.normal.y(), a.normal.z());
    }
    std::fflush(stdout);
  }

  // 3. The ticks. Nothing below allocates per tick but the events (rare).
  palpate::realtime::lock_memory(o.realtime, palpate::realtime::kFlagNames);
  palpate::realtime::apply_to_this_thread(o.realtime, palpate::realtime::kFlagNames);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::size_t played = 0;
  const auto start = Clock::now() + std::chrono::milliseconds(5);
  const std::int64_t start_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(start.time_since_epoch()).count();
  std::uint64_t other_sessions = 0;  // feedback for sequences this run never sent
  std::uint64_t dropped_answers = 0;
  // Every answer each handle took (in its wait, or while rendering): to the
  // tick of its pose, in the tick or late by when it was taken against that
  // tick's deadline (the next tick's start).
  auto collect_answers = [&](ToolRun& run, std::size_t now_tick) {
    palpate_device_answer a;
    a.struct_size = sizeof a;
    while (palpate_device_next_answer(run.device.get(), &a, nullptr, 0) == PALPATE_DEVICE_OK) {
      if (a.sequence < first_sequence) {
        ++other_sessions;
        continue;
      }
      const std::uint64_t k = a.sequence - first_sequence;
      if (k > now_tick) {  // a pose this run has not sent: another client drives the tool
        TickRecord& r = run.ticks[now_tick];
        if (!r.newer) r.newer_sequence = a.sequence;
        r.newer = true;
        ++other_sessions;
        continue;
      }
      TickRecord& r = run.ticks[k];
      if (r.outcome != Outcome::kMissing) {
        ++r.duplicates;
        continue;
      }
      const std::int64_t deadline = start_ns + static_cast<std::int64_t>(k + 1) * period_ns;
      r.outcome = a.receive_time_ns <= deadline ? Outcome::kInTime : Outcome::kLate;
      fill(r, a);
    }
  };
  int event_lines = 0;
  constexpr int kMaxEventLines = 24;
  // palpated going and coming back: one line each, however quiet (docs/faults.md).
  auto presence_of = [](palpate_device* device) {
    palpate_device_state st;
    st.struct_size = sizeof st;
    palpate::DaemonPresence p;
    if (palpate_device_get_state(device, &st, nullptr, 0) != PALPATE_DEVICE_OK) return p;
    p.state = st.daemon == PALPATE_DEVICE_DAEMON_PRESENT ? palpate::DaemonState::kPresent
              : st.daemon == PALPATE_DEVICE_DAEMON_LOST  ? palpate::DaemonState::kLost
                                                         : palpate::DaemonState::kUnknown;
    p.losses = st.daemon_losses;
    p.restarts = st.daemon_restarts;
    p.silent_s = st.daemon_silent_s;
    p.uptime_s = st.daemon_uptime_s;
    return p;
  };
  palpate::DaemonPresence presence = presence_of(runs.front().device.get());
  // Events and refusals: printed (refusals on stderr, even with -q) and counted.
  auto take_events_and_notices = [&] {
    for (ToolRun& run : runs) {
      palpate_device_event e;
      e.struct_size = sizeof e;
      while (palpate_device_next_event(run.device.get(), &e, nullptr, 0) == PALPATE_DEVICE_OK) {
        const unsigned long long pose = e.pose_sequence - first_sequence + 1;
        if (e.kind == PALPATE_DEVICE_EVENT_REFUSED) {
          if (run.notices++ == 0) run.first_refusal = e.message;
          std::fprintf(stderr, "palpate-pliers: palpated refused pose %llu of tool '%s': %s\n",
                       pose, run.id.c_str(), e.message);
          continue;
        }
        const auto kind = static_cast<std::size_t>(e.kind);
        if (kind < run.events.size()) ++run.events[kind];
        if (!o.quiet && ++event_lines <= kMaxEventLines) {
          std::printf("  %7.3f s  %-6s %s",
                      static_cast<double>(e.receive_time_ns - start_ns) * 1e-9, run.id.c_str(),
                      e.message);
          if (e.kind == PALPATE_DEVICE_EVENT_GRASP)
            std::printf(" (%u point%s held)", e.held_points, e.held_points == 1 ? "" : "s");
          // Not a fault: palpated ramps a silent tool's force out, and this
          // client's poses were late (a busy machine); said once, in words.
          const bool first = kind < run.events.size() && run.events[kind] == 1;
          if (e.kind == PALPATE_DEVICE_EVENT_WATCHDOG && first)
            std::printf(
                " (no pose reached palpated within its watchdog timeout: this process "
                "was late, e.g. a busy machine; the force ramps down until poses come)");
          if (e.kind == PALPATE_DEVICE_EVENT_RESUMED && first)
            std::printf(" (poses arrive again: the force comes back)");
          std::printf("  [pose %llu]\n", pose);
          if (event_lines == kMaxEventLines)
            std::printf("  … further events are only counted (summary)\n");
          std::fflush(stdout);
        }
      }
    }
  };
  char error[512];
  auto check = [&](int status) {
    if (status != PALPATE_DEVICE_OK) throw_device_error(status, error);
  };
  for (std::size_t i = 0; i < total && !interrupted; ++i, ++played) {
    const auto scheduled = start + i * period;
    const std::uint64_t sequence = first_sequence + i;
    const double tick_t = static_cast<double>(i % ticks_per_play) * period_s;
    for (std::int64_t j = 0; j < steps; ++j) {
      // Step j of the tick: the device's clock is the schedule, so that the
      // rendering sees the gesture's own motion, not the thread's jitter.
      const auto step_at = scheduled + j * period / steps;
      const std::int64_t step_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(step_at.time_since_epoch()).count();
      std::this_thread::sleep_until(step_at);
      const double t = tick_t + static_cast<double>(j) * period_s / static_cast<double>(steps);
      const bool last = j == steps - 1;
      if (last) {
        const palpate::DaemonPresence now_presence = presence_of(runs.front().device.get());
        if (const auto line = palpate::describe_presence_change(presence, now_presence)) {
          std::printf("  %7.3f s  %s\n",
                      static_cast<double>(palpate_device_now_ns() - start_ns) * 1e-9,
                      line->c_str());
          std::fflush(stdout);
        }
        presence = now_presence;
      }
      for (ToolRun& run : runs) {
        const palpate::GesturePose pose = player.sample(run.gesture_index, t);
        TickRecord& r = run.ticks[i];
        const auto& q = pose.orientation;
        const double hinge[3] = {pose.hinge_m.x(), pose.hinge_m.y(), pose.hinge_m.z()};
        const double wxyz[4] = {q.w(), q.x(), q.y(), q.z()};
        std::uint64_t sent = 0;
        const std::int64_t before_ns = palpate_device_now_ns();
        check(palpate_device_set_pose(run.device.get(), step_ns, hinge, wxyz, pose.jaw_angle_rad,
                                      &sent, error, sizeof error));
        if (j == 0) {
          r.time_s = t;
          r.sequence = sent != 0 ? sent : sequence;
          r.tip_m = pose.tip_m;
          r.jaw_rad = pose.jaw_angle_rad;
          r.send_ns = before_ns;
          r.lag_us = static_cast<double>(before_ns - step_ns) * 1e-3;
        }
        double force[3], torque[3];
        check(palpate_device_force(run.device.get(), step_ns, force, torque, error, sizeof error));
        palpate_device_state st;
        st.struct_size = sizeof st;
        check(palpate_device_get_state(run.device.get(), &st, error, sizeof error));
        const double magnitude = std::hypot(force[0], force[1], force[2]);
        r.rendered_max_n = std::max(r.rendered_max_n, magnitude);
        r.damping_n_s_per_m = std::max(r.damping_n_s_per_m, st.damping_n_s_per_m);
        if (last) {
          r.rendered_n = magnitude;
          r.rendered_force_n = {force[0], force[1], force[2]};
          r.energy_j = st.energy_j;
          r.daemon = presence.state;
        }
      }
      // Until the next step: each tool's answer to its newest pose, if it
      // has not come yet.
      const auto next_step = scheduled + (j + 1) * period / steps;
      const std::int64_t next_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(next_step.time_since_epoch())
              .count();
      for (ToolRun& run : runs) {
        const int status = palpate_device_wait(run.device.get(), next_ns, error, sizeof error);
        if (status != PALPATE_DEVICE_NONE) check(status);
        collect_answers(run, i);
      }
    }
    take_events_and_notices();
  }
  // Stragglers: answers still on their way when the last tick ended.
  const std::int64_t drain_until = palpate_device_now_ns() + 20'000'000;
  for (ToolRun& run : runs) {
    if (played == 0) break;
    palpate_device_wait(run.device.get(), drain_until, nullptr, 0);
    collect_answers(run, played - 1);
  }
  for (ToolRun& run : runs) {
    palpate_device_state st;
    st.struct_size = sizeof st;
    if (palpate_device_get_state(run.device.get(), &st, nullptr, 0) == PALPATE_DEVICE_OK)
      dropped_answers += st.answers_dropped;
  }
  for (auto& r : runs) r.ticks.resize(played);
  // The end of each tool's session: palpated lets go now (an `ended` event),
  // not 50 ms later by its watchdog, and the next run starts afresh. The
  // wait ends as soon as every event is in; 5 s leaves room for a daemon
  // on a machine that is busy (or under a sanitizer).
  const auto end_by = Clock::now() + std::chrono::seconds(5);
  bool ended = true;
  for (const ToolRun& run : runs)
    if (played > 0)
      ended = palpate_device_end_session(run.device.get(), 0.5, nullptr, 0) == PALPATE_DEVICE_OK &&
              ended;
  // Only a tool palpated answered has a session to end (and an event to wait for).
  auto all_ended = [&] {
    return std::all_of(runs.begin(), runs.end(), [](const ToolRun& r) {
      const bool answered = std::any_of(r.ticks.begin(), r.ticks.end(), [](const TickRecord& t) {
        return t.outcome != Outcome::kMissing;
      });
      return !answered || r.events[static_cast<std::size_t>(ToolEventKind::kEnded)] > 0;
    });
  };
  while (played > 0 && ended && !all_ended() && Clock::now() < end_by) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    take_events_and_notices();
  }
  take_events_and_notices();

  // 4. The summary.
  const double budget_us = period_s * 1e6;
  std::printf(
      "%s: %zu ticks at %.0f Hz (%.2f s)%s%s\n", gesture.name.c_str(), played, o.rate_hz,
      static_cast<double>(played) * period_s, interrupted ? ", interrupted" : "",
      first_counted > 0 ? fmt::format(", first {} left out (warm-up)", first_counted).c_str() : "");
  nlohmann::json tools_json = nlohmann::json::array();
  std::string silent_tools;  // tools palpated never answered
  for (const ToolRun& run : runs) {
    const ToolSummary s = summarize(run, std::min(first_counted, played), budget_us);
    if (s.ticks > 0 && s.in_time + s.late == 0)
      silent_tools += (silent_tools.empty() ? "'" : ", '") + run.id + "'";
    tools_json.push_back(
        print_tool(run, s, player.anchor(run.gesture_index).vertex_id, budget_us, device_rate_hz));
  }
  // Answers of another tool in this tool's partition: none since palpated
  // writes each tool's in its own (docs/dds.md, "Per-tool delivery").
  constexpr std::uint64_t foreign_feedback = 0;
  if (foreign_feedback > 0 || dropped_answers > 0 || other_sessions > 0)
    std::printf(
        "  feedback for other clients' tools %llu, for poses this run did not send %llu (an "
        "earlier run's, or another client driving the same tool), late feedback dropped %llu\n",
        static_cast<unsigned long long>(foreign_feedback),
        static_cast<unsigned long long>(other_sessions),
        static_cast<unsigned long long>(dropped_answers));
  if (presence.losses > 0 || presence.restarts > 0)
    std::printf("  palpated lost %llu time(s), restarted %llu time(s); now %s\n",
                static_cast<unsigned long long>(presence.losses),
                static_cast<unsigned long long>(presence.restarts),
                daemon_state_name(presence.state));
  if (!o.csv.empty()) write_csv(o.csv, runs, first_counted, start_ns);
  if (!o.json.empty()) {
    const nlohmann::json summary = {{"gesture", gesture.name},
                                    {"gesture_file", o.gesture_file},
                                    {"model", o.model_id},
                                    {"rate_hz", o.rate_hz},
                                    {"device_rate_hz", device_rate_hz},
                                    {"repeat", o.repeat},
                                    {"busy_wait", o.busy_wait},
                                    {"rt_priority", o.realtime.priority},
                                    {"cpus", palpate::realtime::format_cpu_list(o.realtime.cpus)},
                                    {"lock_memory", o.realtime.lock_memory},
                                    {"ticks", played},
                                    {"counted_from_tick", first_counted},
                                    {"budget_us", budget_us},
                                    {"interrupted", interrupted.load()},
                                    {"first_sequence", first_sequence},
                                    {"foreign_feedback", foreign_feedback},
                                    {"other_session_feedback", other_sessions},
                                    {"dropped_late_feedback", dropped_answers},
                                    {"daemon_losses", presence.losses},
                                    {"daemon_restarts", presence.restarts},
                                    {"tools", tools_json}};
    std::ofstream out(o.json);
    out << summary.dump(2) << "\n";
    if (!out) throw palpate::InputError(fmt::format("--json {}: cannot be written", o.json));
  }
  std::fflush(stdout);  // the summary before any error on stderr
  if (interrupted) return static_cast<int>(palpate::ExitCode::kInterrupted);
  std::string refusals;
  for (const ToolRun& run : runs)
    if (run.notices > 0)
      refusals +=
          fmt::format("{}tool '{}': {}", refusals.empty() ? "" : "; ", run.id, run.first_refusal);
  if (!refusals.empty())
    throw palpate::InputError(fmt::format("palpated refused poses of {}", refusals));
  if (!silent_tools.empty())
    throw NoAnswer(fmt::format(
        "palpated sent no feedback at all for tool {}: is it one of palpated's tools ([[tools]], "
        "docs/configuration.md; default: left, right)?",
        silent_tools));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const NoAnswer& e) {
    std::fprintf(stderr, "palpate-pliers: error: %s\n", e.what());
    return kNoAnswer;
  } catch (...) {
    return palpate::report_current_exception("palpate-pliers");
  }
}
