// palpate-pliers: a haptic device in software. Plays a gesture file
// (docs/pliers.md) at the haptic rate over DDS for one or two tools: each
// tick publishes every tool's pose, waits for its ToolFeedback until the
// next tick, and records the round trip, the force, the grip and the state.
// Prints a summary per tool; --csv writes every tick, --json the summary.
// Ends each tool's session when done (palpate_tool_command END), so that
// palpated lets go at once rather than by its watchdog.
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
#include "palpate/runtime/gesture.hpp"
#include "palpate/transport/realtime.hpp"
#include "palpate/transport/tool_client.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using palpate::ToolEventKind;
using palpate::ToolState;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kNoAnswer = 3;  // palpated did not answer (see the header comment)

/// palpated is not there, or does not answer: exit 3.
struct NoAnswer : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::atomic<bool> interrupted{false};
extern "C" void on_signal(int) { interrupted = true; }

enum class Outcome : std::uint8_t {
  kMissing,  ///< no feedback for this pose (yet)
  kInTime,   ///< its feedback was taken before the next tick
  kLate,     ///< its feedback came during a later tick
};
const char* outcome_name(Outcome o) {
  switch (o) {
    case Outcome::kMissing:
      return "missing";
    case Outcome::kInTime:
      return "in_time";
    case Outcome::kLate:
      return "late";
  }
  return "?";
}

/// One tick of one tool.
struct TickRecord {
  double time_s = 0;           ///< gesture time played
  std::uint64_t sequence = 0;  ///< of the pose sent
  std::int64_t send_ns = 0;    ///< steady clock
  double lag_us = 0;           ///< send time − scheduled tick time
  Outcome outcome = Outcome::kMissing;
  bool newer = false;  ///< this tick's wait got feedback for a newer sequence
  std::uint64_t newer_sequence = 0;
  int duplicates = 0;    ///< further feedback for this sequence (watchdog ramp, resends)
  double rtt_us = kNaN;  ///< receive − send_time_ns of its own feedback, client clock
  std::array<double, 3> force_n{kNaN, kNaN, kNaN};
  double grip_n = kNaN;
  std::uint32_t contacts = 0;
  ToolState state = ToolState::kFree;
  bool force_limited = false, watchdog = false;
  double compute_us = kNaN;
  Eigen::Vector3d tip_m = Eigen::Vector3d::Zero();
  double jaw_rad = 0;
  /// |ToolClient::force_to_render()| after this tick's wait: what a device
  /// would render (zero while palpated is lost).
  double rendered_n = 0;
  palpate::DaemonState daemon = palpate::DaemonState::kUnknown;  ///< at that time
};

struct ToolRun {
  std::string id;
  int gesture_index = 0;
  std::vector<TickRecord> ticks;
  std::array<std::uint64_t, 7> events{};  // by ToolEventKind
  std::uint64_t notices = 0;              // poses palpated said it refused (rate limited)
  std::string first_refusal;              // the first reason palpated gave
};

void fill(TickRecord& r, const palpate::ToolFeedbackSample& f) {
  r.rtt_us = static_cast<double>(f.round_trip_ns()) * 1e-3;
  r.force_n = f.force_n;
  r.grip_n = f.grip_n;
  r.contacts = f.contacts;
  r.state = f.state;
  r.force_limited = f.force_limited;
  r.watchdog = f.watchdog;
  r.compute_us = static_cast<double>(f.compute_ns) * 1e-3;
}

struct Percentiles {
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};
Percentiles percentiles(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  Percentiles p;
  p.p50 = palpate::sorted_percentile(v, 0.5);
  p.p99 = palpate::sorted_percentile(v, 0.99);
  p.p999 = palpate::sorted_percentile(v, 0.999);
  p.max = v.empty() ? 0 : v.back();
  return p;
}
nlohmann::json to_json(const Percentiles& p) {
  return {{"p50_us", p.p50}, {"p99_us", p.p99}, {"p999_us", p.p999}, {"max_us", p.max}};
}

/// What one tool's run amounts to (the counted ticks: after --warmup).
struct ToolSummary {
  std::size_t ticks = 0, in_time = 0, late = 0, missing = 0, newer = 0, duplicates = 0;
  std::size_t within_budget = 0;  // own feedback with round trip ≤ one tick
  Percentiles rtt, compute, lag;
  double max_force_n = 0, max_grip_n = 0;
  std::uint32_t max_contacts = 0;
  std::size_t force_limited = 0, watchdog = 0;
  std::array<std::size_t, 3> states{};  // ticks answered in each state
  double max_rendered_n = 0;
  std::size_t ticks_while_lost = 0;  // palpated lost (heartbeat silent)
  double max_rendered_while_lost_n = 0;
};

ToolSummary summarize(const ToolRun& run, std::size_t first_counted, double budget_us) {
  ToolSummary s;
  std::vector<double> rtt, compute, lag;
  for (std::size_t i = first_counted; i < run.ticks.size(); ++i) {
    const TickRecord& r = run.ticks[i];
    ++s.ticks;
    lag.push_back(r.lag_us);
    s.max_rendered_n = std::max(s.max_rendered_n, r.rendered_n);
    if (r.daemon == palpate::DaemonState::kLost) {
      ++s.ticks_while_lost;
      s.max_rendered_while_lost_n = std::max(s.max_rendered_while_lost_n, r.rendered_n);
    }
    s.newer += r.newer ? 1 : 0;
    s.duplicates += static_cast<std::size_t>(r.duplicates);
    if (r.outcome == Outcome::kMissing) {
      ++s.missing;
      continue;
    }
    (r.outcome == Outcome::kInTime ? s.in_time : s.late)++;
    rtt.push_back(r.rtt_us);
    compute.push_back(r.compute_us);
    s.within_budget += r.rtt_us <= budget_us ? 1 : 0;
    s.max_force_n = std::max(s.max_force_n, std::hypot(r.force_n[0], r.force_n[1], r.force_n[2]));
    s.max_grip_n = std::max(s.max_grip_n, r.grip_n);
    s.max_contacts = std::max(s.max_contacts, r.contacts);
    s.force_limited += r.force_limited ? 1 : 0;
    s.watchdog += r.watchdog ? 1 : 0;
    const auto state = static_cast<std::size_t>(r.state);
    if (state < s.states.size()) ++s.states[state];
  }
  s.rtt = percentiles(std::move(rtt));
  s.compute = percentiles(std::move(compute));
  s.lag = percentiles(std::move(lag));
  return s;
}

const char* daemon_state_name(palpate::DaemonState state) {
  switch (state) {
    case palpate::DaemonState::kUnknown:
      return "unknown";
    case palpate::DaemonState::kPresent:
      return "present";
    case palpate::DaemonState::kLost:
      return "lost";
  }
  return "?";
}

double share(std::size_t part, std::size_t whole) {
  return whole == 0 ? 0 : 100.0 * static_cast<double>(part) / static_cast<double>(whole);
}

constexpr std::array<ToolEventKind, 7> kEventKinds{
    ToolEventKind::kTouch,   ToolEventKind::kLeave,    ToolEventKind::kGrasp,
    ToolEventKind::kRelease, ToolEventKind::kWatchdog, ToolEventKind::kResumed,
    ToolEventKind::kEnded};

struct Settings {
  std::string gesture_file, model_id = "sample-organ", csv, json;
  std::vector<std::string> only_tools;
  double rate_hz = 1000, timeout_s = 10, warmup_s = 0;
  int repeat = 1;
  bool busy_wait = false, quiet = false;
  std::uint32_t domain = 0;
  std::string dds_config;
  palpate::RealtimeOptions realtime;  // --rt-priority, --cpus, --lock-memory (docs/realtime.md)
  std::string cpus;
};

void write_csv(const std::string& path, const std::vector<ToolRun>& runs, std::size_t first_counted,
               std::int64_t start_ns) {
  std::ofstream out(path);
  if (!out) throw palpate::InputError(fmt::format("--csv {}: cannot be written", path));
  out << "tick,tool,counted,time_s,sequence,send_ms,lag_us,outcome,newer_sequence,duplicates,rtt_"
         "us,"
         "force_x_n,force_y_n,force_z_n,grip_n,contacts,state,force_limited,watchdog,compute_us,"
         "tip_x_m,tip_y_m,tip_z_m,jaw_deg,rendered_n,daemon\n";
  for (std::size_t i = 0; !runs.empty() && i < runs.front().ticks.size(); ++i)
    for (const ToolRun& run : runs) {
      const TickRecord& r = run.ticks[i];
      out << fmt::format(
          "{},{},{},{:.4f},{},{:.4f},{:.1f},{},{},{},{:.1f},{:.6g},{:.6g},{:.6g},{:.6g},{},{},{:d},"
          "{:d},{:.2f},"
          "{:.6f},{:.6f},{:.6f},{:.2f},{:.6g},{}\n",
          i, run.id, i >= first_counted ? 1 : 0, r.time_s, r.sequence,
          static_cast<double>(r.send_ns - start_ns) * 1e-6, r.lag_us, outcome_name(r.outcome),
          r.newer ? std::to_string(r.newer_sequence) : "", r.duplicates, r.rtt_us, r.force_n[0],
          r.force_n[1], r.force_n[2], r.grip_n, r.contacts,
          r.outcome == Outcome::kMissing ? "" : palpate::tool_state_name(r.state), r.force_limited,
          r.watchdog, r.compute_us, r.tip_m.x(), r.tip_m.y(), r.tip_m.z(),
          r.jaw_rad * 180 / std::numbers::pi, r.rendered_n, daemon_state_name(r.daemon));
    }
  if (!out) throw palpate::SystemError(fmt::format("--csv {}: write failed", path));
}

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
  if (static_cast<int>(runs.size()) > palpate::ToolClient::kMaxTools)
    throw palpate::InputError(fmt::format("{}: {} tools; palpate-pliers plays at most {}",
                                          o.gesture_file, runs.size(),
                                          static_cast<int>(palpate::ToolClient::kMaxTools)));

  // 2. palpated: the model's description, then a reader of the poses.
  if (!o.cpus.empty()) o.realtime.cpus = palpate::realtime::parse_cpu_list(o.cpus, "--cpus");
  palpate::realtime::validate(o.realtime, palpate::realtime::kFlagNames);
  palpate::realtime::check_permitted(o.realtime, palpate::realtime::kFlagNames);
  palpate::ToolClientOptions client_options;
  client_options.domain_id = o.domain;
  client_options.dds_config = o.dds_config;
  client_options.busy_wait = o.busy_wait;
  client_options.realtime = {o.realtime.priority, o.realtime.cpus, /*lock_memory=*/false};
  palpate::ToolClient client(client_options);
  const auto timeout = std::chrono::milliseconds(static_cast<std::int64_t>(o.timeout_s * 1e3));
  const auto give_up = Clock::now() + timeout;
  const auto model = client.wait_for_model(o.model_id, timeout);
  if (!model) {
    const auto seen = client.models_seen();
    if (seen.empty())
      throw NoAnswer(fmt::format(
          "no palpated within {:g} s: no model description on DDS domain {} (is palpated running, "
          "in this network namespace?)",
          o.timeout_s, o.domain));
    std::string ids;
    for (const auto& id : seen) ids += (ids.empty() ? "" : ", ") + id;
    throw palpate::InputError(fmt::format(
        "model '{}' is not served by palpated; served: {} (use --model)", o.model_id, ids));
  }
  const palpate::DrawnSurface& surface = model->surface;
  const palpate::GesturePlayer player(gesture, palpate::place_gesture(gesture, surface));
  // Each tool's answers come in its own partition: its readers first, so
  // that the answers to the first poses are not lost while they are matched.
  for (const auto& run : runs) client.open_tool(run.id);
  if (!client.wait_for_daemon(
          std::max(std::chrono::milliseconds(100),
                   std::chrono::duration_cast<std::chrono::milliseconds>(give_up - Clock::now()))))
    throw NoAnswer(fmt::format(
        "palpated serves model '{}' but reads no tool poses (or writes no feedback) within {:g} s: "
        "is it a palpated with tools?",
        o.model_id, o.timeout_s));

  const double period_s = 1.0 / o.rate_hz;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s));
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
  std::array<palpate::ToolFeedbackSample, 64> late{};
  // Sequences continue from the steady clock in µs: above those of any
  // earlier run on this host (at most one per ms), so that palpated never
  // takes a new run's poses for stale ones of the last (its watchdog resets
  // a tool only 50 ms after its poses stop).
  const std::uint64_t first_sequence =
      static_cast<std::uint64_t>(palpate::ToolClient::now_ns() / 1000);
  std::uint64_t other_sessions = 0;  // feedback for sequences this run never sent
  auto collect_late = [&](ToolRun& run, std::size_t now_tick) {
    for (;;) {
      const std::size_t n = client.take_late_feedback(run.id, late);
      for (std::size_t k = 0; k < n; ++k) {
        const auto& f = late[k];
        if (f.sequence < first_sequence || f.sequence > first_sequence + now_tick) {
          ++other_sessions;
          continue;
        }
        TickRecord& r = run.ticks[f.sequence - first_sequence];
        if (r.outcome != Outcome::kMissing) {
          ++r.duplicates;
          continue;
        }
        r.outcome = Outcome::kLate;
        fill(r, f);
      }
      if (n < late.size()) return;
    }
  };
  int event_lines = 0;
  constexpr int kMaxEventLines = 24;
  // palpated going and coming back: one line each, however quiet (docs/faults.md).
  palpate::DaemonPresence presence = client.daemon_presence();
  std::size_t played = 0;
  const auto start = Clock::now() + std::chrono::milliseconds(5);
  const std::int64_t start_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(start.time_since_epoch()).count();
  // Events and notices: printed (notices on stderr, even with -q) and counted.
  auto take_events_and_notices = [&] {
    for (const auto& e : client.take_events()) {
      const auto it = std::find_if(runs.begin(), runs.end(),
                                   [&](const ToolRun& r) { return r.id == e.tool_id; });
      // Another client's tools, or the end of an earlier run (its watchdog).
      if (it == runs.end() || e.model_id != o.model_id || e.pose_sequence < first_sequence)
        continue;
      const auto kind = static_cast<std::size_t>(e.kind);
      if (kind < it->events.size()) ++it->events[kind];
      if (!o.quiet && ++event_lines <= kMaxEventLines) {
        std::printf("  %7.3f s  %-6s %s", static_cast<double>(e.receive_time_ns - start_ns) * 1e-9,
                    e.tool_id.c_str(), palpate::tool_event_name(e.kind));
        if (e.kind == ToolEventKind::kGrasp)
          std::printf(" (%u point%s held)", e.held_vertices, e.held_vertices == 1 ? "" : "s");
        std::printf("  [pose %llu]\n",
                    static_cast<unsigned long long>(e.pose_sequence - first_sequence + 1));
        if (event_lines == kMaxEventLines)
          std::printf("  … further events are only counted (summary)\n");
        std::fflush(stdout);
      }
    }
    for (const auto& n : client.take_notices()) {
      const auto it = std::find_if(runs.begin(), runs.end(),
                                   [&](const ToolRun& r) { return r.id == n.tool_id; });
      if (it == runs.end() || n.model_id != o.model_id || n.pose_sequence < first_sequence)
        continue;
      if (it->notices++ == 0) it->first_refusal = n.message;
      std::fprintf(stderr, "palpate-pliers: palpated refused pose %llu of tool '%s': %s\n",
                   static_cast<unsigned long long>(n.pose_sequence - first_sequence + 1),
                   n.tool_id.c_str(), n.message.c_str());
    }
  };
  for (std::size_t i = 0; i < total && !interrupted; ++i, ++played) {
    const auto scheduled = start + i * period;
    std::this_thread::sleep_until(scheduled);
    const double t = static_cast<double>(i % ticks_per_play) * period_s;
    const std::uint64_t sequence = first_sequence + i;
    for (ToolRun& run : runs) {
      const palpate::GesturePose pose = player.sample(run.gesture_index, t);
      TickRecord& r = run.ticks[i];
      r.time_s = t;
      r.sequence = sequence;
      r.tip_m = pose.tip_m;
      r.jaw_rad = pose.jaw_angle_rad;
      const auto& q = pose.orientation;
      r.send_ns = client.send_pose(run.id, o.model_id, sequence,
                                   {pose.hinge_m.x(), pose.hinge_m.y(), pose.hinge_m.z()},
                                   {q.w(), q.x(), q.y(), q.z()}, pose.jaw_angle_rad);
      r.lag_us = static_cast<double>(r.send_ns - start_ns) * 1e-3 -
                 std::chrono::duration<double, std::micro>(i * period).count();
    }
    // Each tool's answer must come before the next tick.
    const auto deadline = scheduled + period;
    for (ToolRun& run : runs) {
      TickRecord& r = run.ticks[i];
      if (const auto f = client.wait_feedback(run.id, sequence, deadline)) {
        if (f->sequence == sequence) {
          r.outcome = Outcome::kInTime;
          fill(r, *f);
        } else {
          r.newer = true;
          r.newer_sequence = f->sequence;
        }
      }
      collect_late(run, i);
    }
    const palpate::DaemonPresence now_presence = client.daemon_presence();
    if (const auto line = palpate::describe_presence_change(presence, now_presence)) {
      std::printf("  %7.3f s  %s\n",
                  static_cast<double>(palpate::ToolClient::now_ns() - start_ns) * 1e-9,
                  line->c_str());
      std::fflush(stdout);
    }
    presence = now_presence;
    const std::int64_t render_ns = palpate::ToolClient::now_ns();
    for (ToolRun& run : runs) {
      const auto f = client.force_to_render(run.id, render_ns);
      run.ticks[i].rendered_n = std::hypot(f[0], f[1], f[2]);
      run.ticks[i].daemon = presence.state;
    }
    take_events_and_notices();
  }
  // Stragglers: feedback still on its way when the last tick ended.
  const auto drain_until = Clock::now() + std::chrono::milliseconds(20);
  for (ToolRun& run : runs) {
    if (played == 0) break;
    client.wait_feedback(run.id, first_sequence + played, drain_until);
    collect_late(run, played - 1);
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
      ended = client.end_session(run.id, o.model_id, std::chrono::milliseconds(500)) && ended;
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
    std::printf(
        "  %s: %zu poses; feedback in the tick %zu, late %zu, missing %zu; for a newer pose %zu\n"
        "    round trip p50 %.0f µs  p99 %.0f µs  p99.9 %.0f µs  max %.0f µs; within %.3g ms: %.2f "
        "%%\n"
        "    max |force| %.3f N, max grip %.3f N, max contacts %u; answered free %zu, touching "
        "%zu, "
        "grasping %zu; force limited %zu, during a watchdog ramp %zu\n",
        run.id.c_str(), s.ticks, s.in_time, s.late, s.missing, s.newer, s.rtt.p50, s.rtt.p99,
        s.rtt.p999, s.rtt.max, budget_us * 1e-3, share(s.within_budget, s.ticks), s.max_force_n,
        s.max_grip_n, s.max_contacts, s.states[0], s.states[1], s.states[2], s.force_limited,
        s.watchdog);
    std::string events;
    nlohmann::json events_json = nlohmann::json::object();
    for (const auto kind : kEventKinds) {
      const auto n = run.events[static_cast<std::size_t>(kind)];
      events_json[palpate::tool_event_name(kind)] = n;
      if (n > 0)
        events +=
            fmt::format("{}{} {}", events.empty() ? "" : ", ", palpate::tool_event_name(kind), n);
    }
    std::printf("    events: %s; palpated's compute p50 %.1f µs p99 %.1f µs\n",
                events.empty() ? "none" : events.c_str(), s.compute.p50, s.compute.p99);
    if (run.notices > 0)
      std::printf("    poses refused by palpated: %llu or more (first: %s)\n",
                  static_cast<unsigned long long>(run.notices), run.first_refusal.c_str());
    if (s.ticks_while_lost > 0)
      std::printf("    while palpated was lost: %zu ticks, force rendered max %.3f N\n",
                  s.ticks_while_lost, s.max_rendered_while_lost_n);
    tools_json.push_back(
        {{"id", run.id},
         {"anchor_vertex", player.anchor(run.gesture_index).vertex_id},
         {"ticks", s.ticks},
         {"in_time", s.in_time},
         {"late", s.late},
         {"missing", s.missing},
         {"newer", s.newer},
         {"duplicates", s.duplicates},
         {"round_trip", to_json(s.rtt)},
         {"within_budget_share", share(s.within_budget, s.ticks) / 100},
         {"compute", to_json(s.compute)},
         {"schedule_lag", to_json(s.lag)},
         {"max_force_n", s.max_force_n},
         {"max_grip_n", s.max_grip_n},
         {"max_contacts", s.max_contacts},
         {"states", {{"free", s.states[0]}, {"touching", s.states[1]}, {"grasping", s.states[2]}}},
         {"force_limited", s.force_limited},
         {"watchdog", s.watchdog},
         {"max_rendered_force_n", s.max_rendered_n},
         {"ticks_while_daemon_lost", s.ticks_while_lost},
         {"max_rendered_force_while_daemon_lost_n", s.max_rendered_while_lost_n},
         {"events", events_json},
         {"refusal_notices", run.notices},
         {"first_refusal", run.first_refusal}});
  }
  if (client.foreign_feedback() > 0 || client.dropped_late_feedback() > 0 || other_sessions > 0)
    std::printf(
        "  feedback for other clients' tools %llu, for poses this run did not send %llu (an "
        "earlier run's, or another client driving the same tool), late feedback dropped %llu\n",
        static_cast<unsigned long long>(client.foreign_feedback()),
        static_cast<unsigned long long>(other_sessions),
        static_cast<unsigned long long>(client.dropped_late_feedback()));
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
                                    {"foreign_feedback", client.foreign_feedback()},
                                    {"other_session_feedback", other_sessions},
                                    {"dropped_late_feedback", client.dropped_late_feedback()},
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
