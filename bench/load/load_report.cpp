// palpate_load_generator's measurements and report (load_report.hpp).

#include "load_report.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <sstream>

namespace palpate::load {

std::optional<ProcSample> sample_process(pid_t pid) {
  ProcSample s;
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  if (!status) return std::nullopt;
  for (std::string line; std::getline(status, line);) {
    auto kb = [&](const char* key) {
      return std::stod(line.substr(std::strlen(key))) / 1024.0;  // "VmRSS:   12345 kB"
    };
    if (line.rfind("VmRSS:", 0) == 0) s.rss_mb = kb("VmRSS:");
    if (line.rfind("VmHWM:", 0) == 0) s.hwm_mb = kb("VmHWM:");
  }
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(stat)), {});
  const auto paren = text.rfind(')');
  if (paren == std::string::npos) return std::nullopt;
  std::istringstream fields(text.substr(paren + 2));
  std::string field;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  for (int i = 3; i <= 15 && fields >> field; ++i)  // field 3 is the state
    if (i == 14 || i == 15) s.cpu_s += std::stod(field) / tick;
  std::ifstream machine("/proc/stat");
  std::string cpu;
  machine >> cpu;
  double v[8] = {};
  for (double& x : v) machine >> x;
  for (const double x : v) s.machine_total_s += x / tick;
  s.machine_busy_s = s.machine_total_s - (v[3] + v[4]) / tick;  // idle, iowait
  return s;
}

std::string read_text(const fs::path& file) {
  std::ifstream in(file);
  return {std::istreambuf_iterator<char>(in), {}};
}

/// /proc/loadavg's 1, 5 and 15 minute figures.
json load_average() {
  std::ifstream in("/proc/loadavg");
  double a[3] = {};
  in >> a[0] >> a[1] >> a[2];
  return {a[0], a[1], a[2]};
}

std::string machine_model() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

ToolSummary summarize(const std::string& id, const std::vector<TickRecord>& ticks,
                      double budget_us) {
  ToolSummary s;
  s.id = id;
  std::vector<double> rtt, compute, lag;
  rtt.reserve(ticks.size());
  for (const TickRecord& r : ticks) {
    ++s.ticks;
    lag.push_back(r.lag_us);
    s.newer += r.newer;
    if (r.outcome == 0) {
      ++s.missing;
      continue;
    }
    (r.outcome == 1 ? s.in_time : s.late)++;
    rtt.push_back(r.rtt_us);
    compute.push_back(r.compute_us);
    s.within_1ms += r.rtt_us <= budget_us ? 1 : 0;
    if (r.state < 3) ++s.states[r.state];
  }
  s.rtt = distribution(std::move(rtt), budget_us);
  s.compute = distribution(std::move(compute), budget_us);
  s.lag = distribution(std::move(lag), budget_us);
  return s;
}

double share(std::size_t part, std::size_t whole) {
  return whole == 0 ? 0 : static_cast<double>(part) / static_cast<double>(whole);
}

json to_json(const ToolSummary& s, double seconds) {
  const std::size_t answered = s.in_time + s.late;
  return {{"id", s.id},
          {"ticks", s.ticks},
          {"poses_per_s", static_cast<double>(s.ticks) / seconds},
          {"in_time", s.in_time},
          {"late", s.late},
          {"missing", s.missing},
          {"newer", s.newer},
          {"answered_share", share(answered, s.ticks)},
          {"within_1ms_share", share(s.within_1ms, s.ticks)},
          {"round_trip", to_json(s.rtt)},
          {"compute", to_json(s.compute)},
          {"schedule_lag", to_json(s.lag)},
          {"states",
           {{"free", share(s.states[0], answered)},
            {"touching", share(s.states[1], answered)},
            {"grasping", share(s.states[2], answered)}}}};
}

StationData read_station(const fs::path& work, const std::string& role) {
  StationData d;
  d.meta = json::parse(read_text(work / (role + ".json")));
  for (const auto& t : d.meta["tools"])
    d.tools.emplace_back(t["id"].get<std::string>(),
                         read_ticks(work / t["ticks_file"].get<std::string>()));
  return d;
}

std::string fmt_lost(const json& r) {
  std::string text = fmt::format("{} sent, {} answered OK, {} lost (no reply within {} s)",
                                 r["sent"].get<std::uint64_t>(), r["ok"].get<std::uint64_t>(),
                                 r["lost"].get<std::uint64_t>(), r["timeout_s"].get<double>());
  if (r["lost"] != 0) text += ": request ids " + r["lost_ids"].dump();
  return text;
}

std::string fmt_rss(const ProcSample& first, const ProcSample& last, double tolerance_mb) {
  return fmt::format(
      "VmRSS {:.1f} MB at {:.0f} s, {:.1f} MB at {:.0f} s: {:+.2f} MB (tolerance {:g} MB)",
      first.rss_mb, first.t_s, last.rss_mb, last.t_s, last.rss_mb - first.rss_mb, tolerance_mb);
}

void print_tool_row(const char* phase, const json& t) {
  const json& r = t["round_trip"];
  const json& st = t["states"];
  std::printf(
      "%-9s %-9s %8.1f %8.2f%% %7.2f%% %6.0f %6.0f %6.0f %7.0f %7.0f %6.1f/%-6.1f %7.0f %6.1f%% "
      "%6.1f%%\n",
      phase, t["id"].get<std::string>().c_str(), t["poses_per_s"].get<double>(),
      100 * t["answered_share"].get<double>(), 100 * t["within_1ms_share"].get<double>(),
      r["p50_us"].get<double>(), r["p90_us"].get<double>(), r["p99_us"].get<double>(),
      r["p999_us"].get<double>(), r["max_us"].get<double>(), t["compute"]["p50_us"].get<double>(),
      t["compute"]["p99_us"].get<double>(), t["schedule_lag"]["p99_us"].get<double>(),
      100 * st["touching"].get<double>(), 100 * st["grasping"].get<double>());
}

void print_table(const json& s) {
  const json& set = s["settings"];
  std::printf(
      "palpate load test, %s: %d stations (%s), %d tools at %.0f Hz, %d viewers, requests at %.0f "
      "Hz, "
      "%.0f s"
      " (baseline: station 1 alone, %.0f s)\n",
      s["date"].get<std::string>().c_str(), set["stations"].get<int>(),
      set["shared_organ"].get<bool>() ? "all on one organ" : "each on its own organ",
      set["tools"].get<int>(), set["rate_hz"].get<double>(), set["viewers"].get<int>(),
      set["request_hz"].get<double>(), set["seconds"].get<double>(),
      set["baseline_s"].get<double>());
  const json& m = s["machine"];
  std::printf("machine: %u CPUs, %s; load average before: %s\n\n", m["cpus"].get<unsigned>(),
              m["model"].get<std::string>().c_str(), m["load_average_before"].dump().c_str());
  std::printf(
      "Tool round trip, pose sent -> its feedback taken, us (answered: in the tick or late; <=1ms: "
      "of all poses)\n");
  std::printf("%-9s %-9s %8s %9s %8s %6s %6s %6s %7s %7s %13s %7s %7s %7s\n", "phase", "tool",
              "poses/s", "answered", "<=1ms", "p50", "p90", "p99", "p99.9", "max", "compute50/99",
              "lag99", "touch", "grasp");
  for (const auto& t : s["baseline"]["tools"]) print_tool_row("baseline", t);
  for (const auto& t : s["load"]["tools"]) print_tool_row("load", t);
  print_tool_row("load", s["load"]["all_tools"]);
  for (const auto& r : s["ratios_to_baseline"])
    std::printf("  %s load / baseline: p50 x%.2f, p99 x%.2f, p99.9 x%.2f\n",
                r["tool"].get<std::string>().c_str(), r["p50"].get<double>(),
                r["p99"].get<double>(), r["p999"].get<double>());
  for (const auto& st : s["load"]["stations"])
    std::printf(
        "  %s: feedback of other stations' tools taken and ignored %llu; late feedback dropped "
        "%llu\n",
        st["role"].get<std::string>().c_str(), st["foreign_feedback"].get<unsigned long long>(),
        st["dropped_late_feedback"].get<unsigned long long>());
  if (const json& r = s["load"]["requests"]; !r.is_null()) {
    const json& rt = r["round_trip"];
    std::printf(
        "\nRequests: %s, %llu errors; %.1f/s, sent late %llu; round trip p50 %.0f p90 %.0f p99 "
        "%.0f p99.9 %.0f max %.0f us\n",
        fmt_lost(r).c_str(), r["errors"].get<unsigned long long>(), r["rate_hz"].get<double>(),
        r["sent_late"].get<unsigned long long>(), rt["p50_us"].get<double>(),
        rt["p90_us"].get<double>(), rt["p99_us"].get<double>(), rt["p999_us"].get<double>(),
        rt["max_us"].get<double>());
  }
  std::printf("\nViewers (surface stream, every model):\n");
  for (const auto& v : s["load"]["viewers"]) {
    std::string per_model;
    for (const auto& [id, pm] : v["models"].items())
      per_model += fmt::format(" {} {:.1f}/s gaps {};", id, pm["rate_hz"].get<double>(),
                               pm["sequence_gaps"].get<std::uint64_t>());
    const json& l = v["latency"];
    std::printf("  %s:%s latency p50 %.0f p99 %.0f max %.0f us; %llu heartbeats\n",
                v["role"].get<std::string>().c_str(), per_model.c_str(), l["p50_us"].get<double>(),
                l["p99_us"].get<double>(), l["max_us"].get<double>(),
                v["heartbeats"].get<unsigned long long>());
  }
  const json& d = s["daemon"];
  std::printf("\npalpated: ");
  if (d.contains("rss_mb")) {
    const json& r = d["rss_mb"];
    std::printf(
        "VmRSS %.1f MB at the start, %.1f MB after the warm-up (%.0f s), %.1f MB at the end, max "
        "%.1f MB;"
        " growth after the warm-up %+.2f MB, slope %+.3f MB/min; VmHWM %.1f MB\n"
        "          CPU %.0f %% of one core (max %.0f %% over 1 s); machine busy %.0f %% of all "
        "CPUs; ",
        r["at_start"].get<double>(), r["after_warmup"].get<double>(),
        r["after_warmup_at_s"].get<double>(), r["end"].get<double>(), r["max"].get<double>(),
        r["growth_after_warmup"].get<double>(), r["slope_mb_per_min"].get<double>(),
        d["hwm_mb"].get<double>(), d["cpu_percent_of_one_core"]["mean"].get<double>(),
        d["cpu_percent_of_one_core"]["max_1s"].get<double>(),
        d["machine_busy_percent"].get<double>());
  }
  const json& cc = s["load"]["clients_cpu_percent_of_one_core"];
  std::printf(
      "clients' CPU (%% of one core, setup included): stations %.0f %%, viewers %.0f %%, requests "
      "%.0f %%;"
      " load average after %s\n          ",
      cc["stations"].get<double>(), cc["viewers"].get<double>(), cc["requests"].get<double>(),
      s["machine"]["load_average_after"].dump().c_str());
  std::printf("log: %llu warnings, %llu errors; exit status %d\n",
              d["log_warnings"].get<unsigned long long>(),
              d["log_errors"].get<unsigned long long>(), d["exit_status"].get<int>());
  if (s["load"]["timeline"].size() > 1) {
    std::printf(
        "\nPer minute (all tools): minute, answered, p50, p99, p99.9, max (us), VmRSS (MB), "
        "palpated's CPU (%% of a core), machine busy (%% of all CPUs)\n");
    for (const auto& t : s["load"]["timeline"])
      std::printf("  %3d %8.2f%% %6.0f %6.0f %7.0f %7.0f %8.1f %5.0f %%  %5.0f %%\n",
                  t["minute"].get<int>(), 100 * t["answered_share"].get<double>(),
                  t["round_trip"]["p50_us"].get<double>(), t["round_trip"]["p99_us"].get<double>(),
                  t["round_trip"]["p999_us"].get<double>(), t["round_trip"]["max_us"].get<double>(),
                  t["rss_mb"].get<double>(), t["palpated_cpu_percent"].get<double>(),
                  t["machine_busy_percent"].get<double>());
  }
  std::printf("\nChecks:\n");
  for (const auto& c : s["checks"])
    std::printf("  %s  %s: %s\n", c["passed"].get<bool>() ? "pass" : "FAIL",
                c["check"].get<std::string>().c_str(), c["detail"].get<std::string>().c_str());
  std::printf("%s\n", s["passed"].get<bool>() ? "all checks passed" : "SOME CHECKS FAILED");
  std::fflush(stdout);
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return text;
}

}  // namespace palpate::load
