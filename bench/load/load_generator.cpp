// palpate_load_generator: palpated under the load of a teaching room, for
// the load test of issue 6 (BENCHMARKS.md "Load"; the short version is the
// CTest test load_short, the long one bench/load_test.sh).
//
// It starts palpated itself (--palpated, --config, the compliance file served
// once per station as models station1 .. stationN) and drives it from
// separate processes, as separate machines or programs would:
//
// - N stations (default 4), each a simulator with its own organ (model
//   stationK) and two haptic tools: a ToolClient playing a gesture file
//   (the scripts give config/gestures/demo.toml: one hand presses and
//   glides, the other grasps, pulls and releases) in a loop at 1 kHz, renamed
//   sK-<gesture tool id>. Each tick sends both poses (best effort) and waits
//   for their feedback until the next tick, as palpate-pliers does
//   (docs/pliers.md). Stations start their ticks a fraction of a period
//   apart and their gestures at different phases: devices are not in step.
//   With --shared-organ every station works on one model ("organ"), its
//   gesture anchored at its own place (shared_anchor()): palpated then
//   solves all 8 tools' contacts together at every pose, its worst case.
// - V viewers (default 4) reading the surface stream of every model and the
//   status heartbeat with the raw C API (as palpate-viewer's bridge does),
//   counting samples and sequence gaps per model.
// - One requester sending reliable constraint requests at a steady rate
//   (default 100 Hz), one in flight, cycling over the models and over 12
//   patches of 1 to 10 vertices (more patches than the solver's 8 cache
//   slots: most requests factor a new set), update_state = false, every 10th
//   with want_surface. A request not answered within --request-timeout is
//   lost; an answer that is not STATUS_OK is an error.
//
// Phases: a same-run baseline (station 1 alone, nobody else, --baseline s),
// then the load (everything, --seconds s). Meanwhile this process samples
// palpated's VmRSS, VmHWM and CPU time every second (/proc/<pid>), and the
// machine's CPU use (/proc/stat). At the end it stops palpated with SIGTERM
// and expects exit status 0.
//
// Output: a table on stdout, the summary as JSON (--json), every child's
// raw data in --work. Checks (no timing in any of them): palpated alive at
// the end and exiting 0; every child exiting 0; no lost and no error reply;
// every tool answered and touching the organ at some point; no station
// receiving another station's answers (per-tool partitions); no pose refused;
// every viewer received surface samples of every model and a heartbeat;
// palpated's RSS growth after the warm-up ≤ --rss-tolerance-mb.
//
// The parent never touches DDS and runs no thread: it forks the children
// before any DDS entity exists, each child joins the domain on its own.
// Like every DDS process of palpate, run it inside a private network
// namespace whose only interface is loopback (bench/load_test.sh and the
// CTest test do).
//
// Exit codes: 0 every check passed; 1 a check failed (the summary says
// which); 2 bad command line; 3 palpated or a child did not come up.

#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <thread>

#include "load_common.hpp"
#include "load_report.hpp"
#include "palpate/core/suggest.hpp"
#include "palpate/transport/tool_client.hpp"
#include "support/child_process.hpp"

namespace palpate::load {

namespace {

// -------------------------------------------------------------------- parent

/// A child process of this program (forked before any DDS exists).
struct Child {
  std::string role;
  pid_t pid = -1;
  int ready_fd = -1, start_fd = -1;  // our ends
  bool ready = false, exited = false;
  int status = -1;   // exit code, or 128 + signal
  double cpu_s = 0;  // user + system time it used (wait4)
};

Child spawn(const std::string& role, const std::function<int(const Rendezvous&)>& body) {
  int ready[2], start[2];
  if (pipe(ready) != 0 || pipe(start) != 0)
    throw palpate::SystemError("pipe: " + std::string(std::strerror(errno)));
  std::fflush(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) throw palpate::SystemError("fork: " + std::string(std::strerror(errno)));
  if (pid == 0) {
    testing::die_with_parent(parent);
    close(ready[0]);
    close(start[1]);
    int code = 1;
    try {
      code = body(Rendezvous(ready[1], start[0]));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "palpate_load_generator [%s]: error: %s\n", role.c_str(), e.what());
    }
    std::fflush(nullptr);
    _exit(code);
  }
  close(ready[1]);
  close(start[0]);
  return {role, pid, ready[0], start[1]};
}

/// Waits for every child's "ready" (false if one exits first or the time runs out).
bool wait_ready(std::vector<Child>& children, double timeout_s) {
  const auto give_up = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(timeout_s));
  for (Child& c : children) {
    while (!c.ready) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(give_up - Clock::now());
      if (left.count() <= 0) return false;
      pollfd p{c.ready_fd, POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
      char r = 0;
      if (read(c.ready_fd, &r, 1) != 1) return false;  // it exited
      c.ready = true;
    }
  }
  return true;
}

void send_start(const std::vector<Child>& children, std::int64_t start_ns) {
  for (const Child& c : children)
    if (write(c.start_fd, &start_ns, sizeof start_ns) != static_cast<ssize_t>(sizeof start_ns))
      throw palpate::SystemError("sending the start to " + c.role);
}

/// Reaps the children, killing those still there after @p deadline.
void reap(std::vector<Child>& children, Clock::time_point deadline) {
  for (Child& c : children) {
    while (!c.exited) {
      int status = 0;
      rusage usage{};
      if (wait4(c.pid, &status, WNOHANG, &usage) == c.pid) {
        c.exited = true;
        c.status = testing::exit_code(status);
      } else if (Clock::now() > deadline) {
        kill(c.pid, SIGKILL);
        wait4(c.pid, &status, 0, &usage);
        c.exited = true;
        c.status = testing::exit_code(status);
        std::fprintf(stderr, "palpate_load_generator: %s did not finish in time: killed\n",
                     c.role.c_str());
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      if (c.exited)
        c.cpu_s = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                  static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;
    }
    close(c.ready_fd);
    close(c.start_fd);
  }
}

int run(int argc, char** argv) {
  Settings s;
  CLI::App app{
      "palpate_load_generator: palpated under 8 tools at 1 kHz, viewers and requests "
      "(BENCHMARKS.md, \"Load\"); run it in a loopback-only network namespace"};
  app.add_option("--palpated", s.palpated, "the palpated program")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--config", s.config,
                 "palpated's configuration (its [[tools]] must name sK-<tool>)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--model-file", s.model_file, "compliance file, served as station1..N")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--gesture", s.gesture_file, "gesture file each station plays in a loop")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--stations", s.stations,
                 "simulators, each with its model and the gesture's tools")
      ->check(CLI::Range(1, 8));
  app.add_flag("--shared-organ", s.shared_organ,
               "every station's tools on one model (\"organ\") instead of one model per station");
  app.add_option("--viewers", s.viewers, "surface-stream readers")->check(CLI::Range(0, 16));
  app.add_option("--seconds", s.seconds, "length of the load phase")
      ->check(CLI::Range(1.0, 86400.0));
  app.add_option("--baseline", s.baseline_s, "station 1 alone first, s (0: none)")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_option("--warmup", s.warmup_s, "RSS is compared from this second of the load on")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--rate", s.rate_hz, "tool ticks per second")->check(CLI::Range(10.0, 5000.0));
  app.add_option("--request-hz", s.request_hz, "constraint requests per second (0: none)")
      ->check(CLI::Range(0.0, 2000.0));
  app.add_option("--request-timeout", s.request_timeout_s, "a reply later than this is lost, s")
      ->check(CLI::PositiveNumber);
  app.add_option("--rss-tolerance-mb", s.rss_tolerance_mb,
                 "largest RSS growth after the warm-up, MB")
      ->check(CLI::PositiveNumber);
  app.add_option("--work", s.work, "directory for palpated's log and the children's data");
  app.add_option("--json", s.json, "write the summary here");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "palpate_load_generator: error: %s%s (see --help)\n", e.what(),
                 palpate::flag_suggestions(std::vector<std::string>(argv + 1, argv + argc),
                                           palpate::long_flag_names(app))
                     .c_str());
    return static_cast<int>(palpate::ExitCode::kUsage);
  }
  if (s.warmup_s >= s.seconds) throw palpate::InputError("--warmup must be shorter than --seconds");
  fs::create_directories(s.work);
  s.work = fs::absolute(s.work).string();

  const json load_before = load_average();
  const std::string started = utc_now();

  std::vector<std::string> daemon_args{"--config", s.config};
  for (const std::string& id : model_ids(s))
    daemon_args.insert(daemon_args.end(), {"--model", id + "=" + s.model_file});
  testing::ChildProcess daemon(s.palpated, daemon_args, fs::path(s.work) / "palpated.log");
  auto fail_start = [&](const std::string& what) {
    std::fprintf(stderr, "palpate_load_generator: %s; palpated's log:\n%s\n", what.c_str(),
                 read_text(fs::path(s.work) / "palpated.log").c_str());
    return kNoStart;
  };

  // 1. The baseline: station 1 alone.
  std::vector<Child> baseline;
  if (s.baseline_s > 0) {
    baseline.push_back(spawn("baseline-station1", [&](const Rendezvous& r) {
      return station_child(s, 1, "baseline-station1", s.baseline_s, r);
    }));
    if (!wait_ready(baseline, s.start_timeout_s)) {
      reap(baseline, Clock::now());
      return fail_start("the baseline station did not come up");
    }
    const std::int64_t start_ns = palpate::ToolClient::now_ns() + 100'000'000;
    send_start(baseline, start_ns);
    reap(baseline,
         steady_time(start_ns) + std::chrono::seconds(static_cast<int>(s.baseline_s) + 30));
  }

  // 2. The load.
  std::vector<Child> children;
  for (int k = 1; k <= s.stations; ++k) {
    const std::string role = "station" + std::to_string(k);
    children.push_back(spawn(role, [&, k, role](const Rendezvous& r) {
      return station_child(s, k, role, s.seconds, r);
    }));
  }
  for (int v = 1; v <= s.viewers; ++v) {
    const std::string role = "viewer" + std::to_string(v);
    children.push_back(spawn(
        role, [&, role](const Rendezvous& r) { return viewer_child(s, role, s.seconds, r); }));
  }
  if (s.request_hz > 0)
    children.push_back(spawn("requests", [&](const Rendezvous& r) {
      return requester_child(s, "requests", s.seconds, r);
    }));
  if (!wait_ready(children, s.start_timeout_s)) {
    for (Child& c : children) kill(c.pid, SIGTERM);
    reap(children, Clock::now() + std::chrono::seconds(5));
    return fail_start("a child of the load did not come up");
  }
  const std::int64_t start_ns = palpate::ToolClient::now_ns() + 200'000'000;
  send_start(children, start_ns);
  std::vector<ProcSample> samples;
  bool daemon_died = false;
  double died_at_s = -1;
  const int last_second = static_cast<int>(std::floor(s.seconds));
  for (int i = 0; i <= last_second; ++i) {
    std::this_thread::sleep_until(steady_time(start_ns) + std::chrono::seconds(i));
    if (!daemon.running()) {
      daemon_died = true;
      died_at_s = i;
      break;
    }
    if (auto p = sample_process(daemon.pid())) {
      p->t_s = i;
      samples.push_back(*p);
    }
  }
  reap(children, steady_time(start_ns) + std::chrono::seconds(last_second + 30));
  const bool alive_at_end = !daemon_died && daemon.running();
  const int daemon_exit = daemon.terminate(std::chrono::seconds(20));
  const std::string log = read_text(fs::path(s.work) / "palpated.log");
  auto count = [&](const std::string& needle) {
    std::size_t n = 0;
    for (auto at = log.find(needle); at != std::string::npos; at = log.find(needle, at + 1)) ++n;
    return n;
  };

  // 3. What it amounts to.
  const double budget_us = 1e6 / s.rate_hz;
  json summary;
  summary["date"] = started;
  summary["machine"] = {{"cpus", std::thread::hardware_concurrency()},
                        {"model", machine_model()},
                        {"load_average_before", load_before},
                        {"load_average_after", load_average()}};
  summary["settings"] = {{"stations", s.stations},
                         {"shared_organ", s.shared_organ},
                         {"tools", nullptr},
                         {"viewers", s.viewers},
                         {"seconds", s.seconds},
                         {"baseline_s", s.baseline_s},
                         {"warmup_s", s.warmup_s},
                         {"rate_hz", s.rate_hz},
                         {"request_hz", s.request_hz},
                         {"request_timeout_s", s.request_timeout_s},
                         {"rss_tolerance_mb", s.rss_tolerance_mb},
                         {"model_file", s.model_file},
                         {"gesture", s.gesture_file},
                         {"config", s.config}};
  json checks = json::array();
  bool passed = true;
  auto check = [&](const std::string& name, bool ok, const std::string& detail) {
    checks.push_back({{"check", name}, {"passed", ok}, {"detail", detail}});
    passed = passed && ok;
  };
  for (const Child& c : baseline)
    check(c.role + " exited 0", c.status == 0, "exit status " + std::to_string(c.status));
  for (const Child& c : children)
    check(c.role + " exited 0", c.status == 0, "exit status " + std::to_string(c.status));

  json baseline_tools = json::array();
  std::map<std::string, ToolSummary> baseline_by_tool;
  if (!baseline.empty() && baseline.front().status == 0) {
    const StationData d = read_station(s.work, "baseline-station1");
    for (const auto& [id, ticks] : d.tools) {
      baseline_by_tool[id] = summarize(id, ticks, budget_us);
      baseline_tools.push_back(to_json(baseline_by_tool[id], s.baseline_s));
    }
  }

  json load_tools = json::array(), ratios = json::array(), stations_json = json::array();
  std::vector<TickRecord> all_ticks;
  std::vector<ToolSummary> tool_summaries;
  // Per-minute round trips of every tool, for the timeline.
  const auto minutes = static_cast<std::size_t>(std::ceil(s.seconds / 60.0));
  std::vector<std::vector<double>> rtt_by_minute(minutes);
  std::vector<std::size_t> ticks_by_minute(minutes);
  std::uint64_t tools_count = 0;
  for (const Child& c : children) {
    if (c.role.rfind("station", 0) != 0 || c.status != 0) continue;
    const StationData d = read_station(s.work, c.role);
    // Each tool's answers come in its own partition (docs/dds.md, "Per-tool
    // delivery"): a station receives none of another station's.
    check(c.role + " received no other station's answers", d.meta["foreign_feedback"] == 0,
          std::to_string(d.meta["foreign_feedback"].get<std::uint64_t>()) +
              " answers of other stations' tools");
    stations_json.push_back({{"role", c.role},
                             {"foreign_feedback", d.meta["foreign_feedback"]},
                             {"dropped_late_feedback", d.meta["dropped_late_feedback"]},
                             {"other_session_feedback", d.meta["other_session_feedback"]}});
    for (std::size_t k = 0; k < d.tools.size(); ++k) {
      const auto& [id, ticks] = d.tools[k];
      ++tools_count;
      const ToolSummary t = summarize(id, ticks, budget_us);
      json tj = to_json(t, s.seconds);
      tj["events"] = d.meta["tools"][k]["events"];
      load_tools.push_back(tj);
      tool_summaries.push_back(t);
      check("tool " + id + " answered", t.in_time + t.late > 0,
            std::to_string(t.in_time + t.late) + " of " + std::to_string(t.ticks) + " poses");
      check("tool " + id + " touched the organ", t.states[1] + t.states[2] > 0,
            std::to_string(t.states[1] + t.states[2]) + " answers touching or grasping");
      if (const auto b = baseline_by_tool.find(id); b != baseline_by_tool.end()) {
        auto ratio = [](double load, double alone) { return alone > 0 ? load / alone : 0.0; };
        ratios.push_back({{"tool", id},
                          {"p50", ratio(t.rtt.p50, b->second.rtt.p50)},
                          {"p99", ratio(t.rtt.p99, b->second.rtt.p99)},
                          {"p999", ratio(t.rtt.p999, b->second.rtt.p999)}});
      }
      for (std::size_t i = 0; i < ticks.size(); ++i) {
        const std::size_t minute = std::min(
            minutes - 1, static_cast<std::size_t>(static_cast<double>(i) / s.rate_hz / 60));
        ++ticks_by_minute[minute];
        if (ticks[i].outcome != 0) rtt_by_minute[minute].push_back(ticks[i].rtt_us);
      }
      all_ticks.insert(all_ticks.end(), ticks.begin(), ticks.end());
    }
  }
  summary["settings"]["tools"] = tools_count;
  const ToolSummary all = summarize("all", all_ticks, budget_us);
  all_ticks = {};

  json requests = nullptr;
  if (s.request_hz > 0) {
    if (const fs::path f = fs::path(s.work) / "requests.json"; fs::exists(f)) {
      requests = json::parse(read_text(f));
      check("no lost reply", requests["lost"] == 0 && requests["sent"].get<std::uint64_t>() > 0,
            fmt_lost(requests));
      check("no error reply", requests["errors"] == 0,
            std::to_string(requests["errors"].get<std::uint64_t>()) + " errors" +
                (requests["errors"] == 0 ? "" : ": " + requests["first_error"].get<std::string>()));
    } else {
      check("no lost reply", false, "the requester wrote no result");
    }
  }

  json viewers = json::array();
  std::uint64_t refused = 0;
  for (int v = 1; v <= s.viewers; ++v) {
    const fs::path f = fs::path(s.work) / ("viewer" + std::to_string(v) + ".json");
    if (!fs::exists(f)) {
      check("viewer" + std::to_string(v) + " received the stream", false, "no result");
      continue;
    }
    json vj = json::parse(read_text(f));
    int models_seen = 0;
    std::uint64_t fewest = std::numeric_limits<std::uint64_t>::max();
    const std::vector<std::string> models = model_ids(s);
    for (const std::string& id : models) {
      const auto it = vj["models"].find(id);
      const std::uint64_t n = it == vj["models"].end() ? 0 : (*it)["samples"].get<std::uint64_t>();
      models_seen += n > 0 ? 1 : 0;
      fewest = std::min(fewest, n);
    }
    check(vj["role"].get<std::string>() + " received every model's surface",
          models_seen == static_cast<int>(models.size()),
          std::to_string(models_seen) + " of " + std::to_string(models.size()) +
              " models, fewest samples " + std::to_string(fewest));
    check(vj["role"].get<std::string>() + " received heartbeats", vj["heartbeats"] > 0,
          std::to_string(vj["heartbeats"].get<std::uint64_t>()) + " heartbeats");
    refused = std::max(refused, vj["last_status"]["tool_poses_refused"].get<std::uint64_t>());
    viewers.push_back(vj);
  }
  if (s.viewers > 0)
    check("no pose refused by palpated", refused == 0,
          std::to_string(refused) + " refused (status heartbeat, tool_poses_refused)");

  // palpated's memory and CPU.
  json daemon_json;
  daemon_json["alive_at_end"] = alive_at_end;
  daemon_json["died_at_s"] = died_at_s;
  daemon_json["exit_status"] = daemon_exit;
  daemon_json["log_warnings"] = count("level=warning");
  daemon_json["log_errors"] = count("level=error") + count("level=critical");
  check("palpated alive at the end of the load", alive_at_end,
        daemon_died ? "exited with " + std::to_string(daemon.exit_status()) + " at " +
                          std::to_string(died_at_s) + " s"
                    : "alive");
  check("palpated exited 0 on SIGTERM", daemon_exit == 0,
        "exit status " + std::to_string(daemon_exit));
  json timeline = json::array();
  if (!samples.empty()) {
    const auto warm = std::find_if(samples.begin(), samples.end(),
                                   [&](const ProcSample& p) { return p.t_s >= s.warmup_s; });
    const ProcSample& first = warm == samples.end() ? samples.back() : *warm;
    const ProcSample& last = samples.back();
    double max_rss = 0, max_cpu = 0, max_hwm = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      max_rss = std::max(max_rss, samples[i].rss_mb);
      max_hwm = std::max(max_hwm, samples[i].hwm_mb);
      if (i > 0)
        max_cpu = std::max(max_cpu, (samples[i].cpu_s - samples[i - 1].cpu_s) /
                                        (samples[i].t_s - samples[i - 1].t_s));
    }
    // Least-squares slope of RSS over the samples after the warm-up, MB/min.
    double n = 0, st = 0, sr = 0, stt = 0, str = 0;
    for (auto it = warm; it != samples.end(); ++it) {
      const double t = it->t_s / 60;
      n += 1;
      st += t;
      sr += it->rss_mb;
      stt += t * t;
      str += t * it->rss_mb;
    }
    const double slope =
        n > 1 && n * stt - st * st > 0 ? (n * str - st * sr) / (n * stt - st * st) : 0;
    const double span = last.t_s - samples.front().t_s;
    daemon_json["rss_mb"] = {{"at_start", samples.front().rss_mb},
                             {"after_warmup", first.rss_mb},
                             {"after_warmup_at_s", first.t_s},
                             {"end", last.rss_mb},
                             {"max", max_rss},
                             {"growth_after_warmup", last.rss_mb - first.rss_mb},
                             {"slope_mb_per_min", slope}};
    daemon_json["hwm_mb"] = max_hwm;
    daemon_json["cpu_percent_of_one_core"] = {
        {"mean", span > 0 ? 100 * (last.cpu_s - samples.front().cpu_s) / span : 0},
        {"max_1s", 100 * max_cpu}};
    const double total = last.machine_total_s - samples.front().machine_total_s;
    daemon_json["machine_busy_percent"] =
        total > 0 ? 100 * (last.machine_busy_s - samples.front().machine_busy_s) / total : 0;
    check("palpated's RSS flat after the warm-up", last.rss_mb - first.rss_mb <= s.rss_tolerance_mb,
          fmt_rss(first, last, s.rss_tolerance_mb));
    for (std::size_t m = 0; m < minutes; ++m) {
      const Distribution d = distribution(std::move(rtt_by_minute[m]), budget_us);
      auto sample_at = [&](double t_s) -> const ProcSample& {
        const auto at = std::find_if(samples.begin(), samples.end(),
                                     [&](const ProcSample& p) { return p.t_s >= t_s - 0.5; });
        return at == samples.end() ? samples.back() : *at;
      };
      const ProcSample& from = sample_at(60.0 * static_cast<double>(m));
      const ProcSample& to = sample_at(std::min(60.0 * static_cast<double>(m + 1), s.seconds));
      const double machine = to.machine_total_s - from.machine_total_s;
      const double elapsed = to.t_s - from.t_s;
      timeline.push_back(
          {{"minute", m + 1},
           {"answered_share", share(d.n, ticks_by_minute[m])},
           {"round_trip", to_json(d)},
           {"rss_mb", to.rss_mb},
           {"palpated_cpu_percent", elapsed > 0 ? 100 * (to.cpu_s - from.cpu_s) / elapsed : 0},
           {"machine_busy_percent",
            machine > 0 ? 100 * (to.machine_busy_s - from.machine_busy_s) / machine : 0}});
    }
  } else {
    check("palpated's RSS flat after the warm-up", false, "no sample of /proc");
  }
  daemon_json["samples"] = json::array();
  // Per second: time (s), VmRSS (MB), palpated's CPU time (s), the
  // machine's busy and total CPU time (s, all CPUs).
  for (const ProcSample& p : samples)
    daemon_json["samples"].push_back(
        {p.t_s, p.rss_mb, p.cpu_s, p.machine_busy_s, p.machine_total_s});

  summary["daemon"] = daemon_json;
  summary["baseline"] = {{"tools", baseline_tools}};
  summary["load"] = {{"tools", load_tools},       {"all_tools", to_json(all, s.seconds)},
                     {"stations", stations_json}, {"requests", requests},
                     {"viewers", viewers},        {"timeline", timeline}};
  json clients_cpu = {{"stations", 0.0}, {"viewers", 0.0}, {"requests", 0.0}};
  for (const Child& c : children) {
    const std::string kind = c.role.rfind("station", 0) == 0  ? "stations"
                             : c.role.rfind("viewer", 0) == 0 ? "viewers"
                                                              : "requests";
    clients_cpu[kind] = clients_cpu[kind].get<double>() + 100 * c.cpu_s / s.seconds;
  }
  summary["load"]["clients_cpu_percent_of_one_core"] = clients_cpu;
  summary["ratios_to_baseline"] = ratios;
  summary["checks"] = checks;
  summary["passed"] = passed;
  if (!s.json.empty()) write_json(s.json, summary);
  print_table(summary);
  return passed ? 0 : kChecksFailed;
}

}  // namespace

}  // namespace palpate::load

int main(int argc, char** argv) {
  try {
    return palpate::load::run(argc, argv);
  } catch (...) {
    return palpate::report_current_exception("palpate_load_generator");
  }
}
