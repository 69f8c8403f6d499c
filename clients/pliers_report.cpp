#include "pliers_report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>

#include "palpate/core/error.hpp"
#include "palpate/core/statistics.hpp"

namespace palpate::pliers {

namespace {

constexpr std::array<ToolEventKind, 7> kEventKinds{
    ToolEventKind::kTouch,   ToolEventKind::kLeave,    ToolEventKind::kGrasp,
    ToolEventKind::kRelease, ToolEventKind::kWatchdog, ToolEventKind::kResumed,
    ToolEventKind::kEnded};

}  // namespace

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

ToolSummary summarize(const ToolRun& run, std::size_t first_counted, double budget_us) {
  ToolSummary s;
  std::vector<double> rtt, compute, lag;
  for (std::size_t i = first_counted; i < run.ticks.size(); ++i) {
    const TickRecord& r = run.ticks[i];
    ++s.ticks;
    lag.push_back(r.lag_us);
    s.max_rendered_n = std::max(s.max_rendered_n, r.rendered_n);
    s.max_rendered_step_n = std::max(s.max_rendered_step_n, r.rendered_max_n);
    s.max_damping = std::max(s.max_damping, r.damping_n_s_per_m);
    s.damped_ticks += r.damping_n_s_per_m > 0 ? 1 : 0;
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

nlohmann::json print_tool(const ToolRun& run, const ToolSummary& s, int anchor_vertex,
                          double budget_us, double device_rate_hz) {
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
  std::printf(
      "    rendered at %.0f Hz: max |force| %.3f N; passivity damping in %zu ticks, at most %.3g "
      "N·s/m\n",
      device_rate_hz, s.max_rendered_step_n, s.damped_ticks, s.max_damping);
  if (run.notices > 0)
    std::printf("    poses refused by palpated: %llu or more (first: %s)\n",
                static_cast<unsigned long long>(run.notices), run.first_refusal.c_str());
  if (s.ticks_while_lost > 0)
    std::printf("    while palpated was lost: %zu ticks, force rendered max %.3f N\n",
                s.ticks_while_lost, s.max_rendered_while_lost_n);
  return {{"id", run.id},
          {"anchor_vertex", anchor_vertex},
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
          {"max_rendered_step_force_n", s.max_rendered_step_n},
          {"max_damping_n_s_per_m", s.max_damping},
          {"damped_ticks", s.damped_ticks},
          {"ticks_while_daemon_lost", s.ticks_while_lost},
          {"max_rendered_force_while_daemon_lost_n", s.max_rendered_while_lost_n},
          {"events", events_json},
          {"refusal_notices", run.notices},
          {"first_refusal", run.first_refusal}};
}

void write_csv(const std::string& path, const std::vector<ToolRun>& runs, std::size_t first_counted,
               std::int64_t start_ns) {
  std::ofstream out(path);
  if (!out) throw palpate::InputError(fmt::format("--csv {}: cannot be written", path));
  out << "tick,tool,counted,time_s,sequence,send_ms,lag_us,outcome,newer_sequence,duplicates,rtt_"
         "us,"
         "force_x_n,force_y_n,force_z_n,grip_n,contacts,state,force_limited,watchdog,compute_us,"
         "tip_x_m,tip_y_m,tip_z_m,jaw_deg,rendered_n,daemon,rendered_x_n,rendered_y_n,rendered_z_n,"
         "rendered_max_n,damping_n_s_per_m,energy_j\n";
  for (std::size_t i = 0; !runs.empty() && i < runs.front().ticks.size(); ++i)
    for (const ToolRun& run : runs) {
      const TickRecord& r = run.ticks[i];
      out << fmt::format(
          "{},{},{},{:.4f},{},{:.4f},{:.1f},{},{},{},{:.1f},{:.6g},{:.6g},{:.6g},{:.6g},{},{},{:d},"
          "{:d},{:.2f},"
          "{:.6f},{:.6f},{:.6f},{:.2f},{:.6g},{},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g}\n",
          i, run.id, i >= first_counted ? 1 : 0, r.time_s, r.sequence,
          static_cast<double>(r.send_ns - start_ns) * 1e-6, r.lag_us, outcome_name(r.outcome),
          r.newer ? std::to_string(r.newer_sequence) : "", r.duplicates, r.rtt_us, r.force_n[0],
          r.force_n[1], r.force_n[2], r.grip_n, r.contacts,
          r.outcome == Outcome::kMissing ? "" : palpate::tool_state_name(r.state), r.force_limited,
          r.watchdog, r.compute_us, r.tip_m.x(), r.tip_m.y(), r.tip_m.z(),
          r.jaw_rad * 180 / std::numbers::pi, r.rendered_n, daemon_state_name(r.daemon),
          r.rendered_force_n[0], r.rendered_force_n[1], r.rendered_force_n[2], r.rendered_max_n,
          r.damping_n_s_per_m, r.energy_j);
    }
  if (!out) throw palpate::SystemError(fmt::format("--csv {}: write failed", path));
}

}  // namespace palpate::pliers
