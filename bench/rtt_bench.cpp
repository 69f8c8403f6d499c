// Request→reply round trip through palpated over Cyclone DDS, as a haptic
// loop sees it: one client sends a constraint request at a fixed rate
// (default 1 kHz), waits for its reply, and measures the time between the
// two on the steady clock. Each request imposes a few mm along the inward
// normal on the k compliance vertices nearest a fixed seed (bench/patch.hpp),
// force only (no surface field), the same set every time (the daemon reuses
// its factorization), depth varied a little per request.
//
// What the number contains: serialization and loopback transport both ways,
// the daemon's wake-up, validation and solve, and this client's wake-up. It
// is the figure to compare with Cyclone's own ping-pong (bench/dds_roundtrip.sh
// runs both; ddsperf's round trip has no solve in it).
//
// Usage: palpate_rtt_bench [--model-id ID] [-k K] [--rate-hz R] [--seconds S]
//                          [--warmup-seconds W] [--update-state] [--domain D] [--json]
//                          [--busy-wait] [--rt-priority P] [--cpus LIST] [--lock-memory]
// Run it next to palpated inside a private network namespace (see
// bench/dds_roundtrip.sh); it uses palpate's loopback DDS configuration.

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/realtime.hpp"
#include "patch.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

/// Nearest-rank percentile of sorted @p v (q in [0, 1]).
double percentile(const std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, rank == 0 ? 0 : rank - 1)];
}

struct Summary {
  double p50 = 0, p99 = 0, p999 = 0, max = 0, mean = 0;
};

Summary summarize(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  Summary s;
  s.p50 = percentile(v, 0.50);
  s.p99 = percentile(v, 0.99);
  s.p999 = percentile(v, 0.999);
  s.max = v.empty() ? 0 : v.back();
  double sum = 0;
  for (double x : v) sum += x;
  s.mean = v.empty() ? 0 : sum / static_cast<double>(v.size());
  return s;
}

nlohmann::json to_json(const Summary& s) {
  return {{"p50_us", s.p50},
          {"p99_us", s.p99},
          {"p999_us", s.p999},
          {"max_us", s.max},
          {"mean_us", s.mean}};
}

/// Approximate serialized sizes (XCDR2, bytes) of ConstraintRequest and
/// ConstraintReply for k constraints and these ids (idl/palpate.idl):
/// encapsulation 4 + DHEADER 4 + strings (4 + length + 1, padded) + fixed
/// fields + k × 56 (Constraint) or k × 56 (ConstraintResult, padded to 8).
/// Used to give ddsperf a comparable payload.
std::size_t padded_string(const std::string& s) { return (4 + s.size() + 1 + 7) / 8 * 8; }
std::size_t request_bytes(std::size_t k, const std::string& client, const std::string& model) {
  return 8 + padded_string(client) + 8 + padded_string(model) + 8 + 4 + k * 56;
}
std::size_t reply_bytes(std::size_t k, const std::string& client, const std::string& model) {
  return 8 + padded_string(client) + 8 + padded_string(model) + 4 + 8 + 8 + 24 + 8 + 4 + k * 56 + 4;
}

}  // namespace

int main(int argc, char** argv) try {
  palpate::ensure_optimized_blas(argv);
  CLI::App app{"palpate_rtt_bench: request→reply round trip through palpated at a fixed rate"};
  std::string model_id = "liver";
  int k = 1;
  double rate_hz = 1000, seconds = 10, warmup_seconds = 2;
  bool update_state = false, json = false;
  std::uint32_t domain = 0;
  app.add_option("--model-id", model_id, "model id palpated serves");
  app.add_option("-k", k, "constrained vertices per request")->check(CLI::Range(1, 64));
  app.add_option("--rate-hz", rate_hz, "requests per second")->check(CLI::PositiveNumber);
  app.add_option("--seconds", seconds, "measured duration")->check(CLI::PositiveNumber);
  app.add_option("--warmup-seconds", warmup_seconds, "unmeasured requests first")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--update-state", update_state,
               "requests change the model's shown state (the stream then runs)");
  app.add_option("--domain", domain, "DDS domain id");
  bool busy_wait = false;
  app.add_flag("--busy-wait", busy_wait,
               "poll for the reply instead of sleeping on a waitset (ClientOptions::busy_wait)");
  palpate::RealtimeOptions realtime;
  std::string cpus;
  app.add_option("--rt-priority", realtime.priority,
                 "SCHED_FIFO priority of the requesting thread and Cyclone's receive thread");
  app.add_option("--cpus", cpus, "their CPUs, as taskset -c");
  app.add_flag("--lock-memory", realtime.lock_memory, "mlockall once connected");
  app.add_flag("--json", json, "print one JSON object instead of text");
  CLI11_PARSE(app, argc, argv);

  palpate::ClientOptions options;
  options.client_id = "rtt-bench-" + std::to_string(getpid());
  options.domain_id = domain;
  options.busy_wait = busy_wait;
  if (!cpus.empty()) realtime.cpus = palpate::realtime::parse_cpu_list(cpus, "--cpus");
  palpate::realtime::validate(realtime, palpate::realtime::kFlagNames);
  options.realtime = realtime;
  palpate::Client client(options);
  palpate::realtime::apply_to_this_thread(realtime, palpate::realtime::kFlagNames);
  const auto model = client.wait_for_model(model_id, 20s);
  if (!model)
    throw palpate::SystemError("no description of model '" + model_id +
                               "' within 20 s: is palpated up?");
  if (!client.wait_for_service(20s))
    throw palpate::SystemError("palpated did not match this client within 20 s");

  const palpate::DrawnSurface& surface = model->surface;
  const auto patch = palpate::bench::nearest_patch(surface, palpate::bench::main_seed(surface), k);
  std::vector<palpate::ConstraintSpec> constraints(patch.vertex_ids.size());

  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate_hz));
  const auto warmup_count = static_cast<std::uint64_t>(warmup_seconds * rate_hz);
  const auto total_count = warmup_count + static_cast<std::uint64_t>(seconds * rate_hz);
  std::vector<double> rtt_us, solve_us;
  rtt_us.reserve(total_count);
  solve_us.reserve(total_count);
  std::uint64_t timeouts = 0, errors = 0, measured_timeouts = 0;
  auto next = Clock::now();
  for (std::uint64_t i = 0; i < total_count; ++i) {
    const double depth = palpate::bench::press_depth_m(i);
    for (std::size_t j = 0; j < constraints.size(); ++j)
      constraints[j] = palpate::ConstraintSpec::displacement(
          patch.vertex_ids[j], {depth * patch.inward_normal[0], depth * patch.inward_normal[1],
                                depth * patch.inward_normal[2]});
    // A fixed schedule; a late reply delays the next request, it does not
    // cause a burst.
    std::this_thread::sleep_until(next);
    next = std::max(next + period, Clock::now());
    const auto sent = Clock::now();
    const auto id = client.send(model_id, constraints, /*want_surface=*/false, update_state);
    const auto reply = client.wait_reply(id, 1s);
    const auto received = Clock::now();
    if (!reply) {
      ++timeouts;
      if (i >= warmup_count) ++measured_timeouts;
      continue;
    }
    if (reply->status != palpate::RequestStatus::kOk) {
      if (errors++ == 0)
        std::fprintf(stderr, "palpate_rtt_bench: request refused: %s: %s\n",
                     palpate::status_name(reply->status), reply->message.c_str());
      continue;
    }
    if (i < warmup_count) continue;
    rtt_us.push_back(std::chrono::duration<double, std::micro>(received - sent).count());
    solve_us.push_back(static_cast<double>(reply->solve_ns) * 1e-3);
  }

  const Summary rtt = summarize(rtt_us), solve = summarize(solve_us);
  // Requests answered within a haptic tick (1 ms) among those sent in the
  // measured part (a timeout is not answered in time).
  const auto in_time =
      std::count_if(rtt_us.begin(), rtt_us.end(), [](double us) { return us <= 1000; });
  const double within_1ms_share =
      static_cast<double>(in_time) /
      static_cast<double>(std::max<std::size_t>(1, rtt_us.size() + measured_timeouts));
  const auto req_bytes = request_bytes(patch.vertex_ids.size(), options.client_id, model_id);
  const auto rep_bytes = reply_bytes(patch.vertex_ids.size(), options.client_id, model_id);
  if (json) {
    nlohmann::json out = {{"k", patch.vertex_ids.size()},
                          {"rate_hz", rate_hz},
                          {"seconds", seconds},
                          {"samples", rtt_us.size()},
                          {"timeouts", timeouts},
                          {"errors", errors},
                          {"update_state", update_state},
                          {"busy_wait", busy_wait},
                          {"rt_priority", realtime.priority},
                          {"cpus", palpate::realtime::format_cpu_list(realtime.cpus)},
                          {"lock_memory", realtime.lock_memory},
                          {"within_1ms_share", within_1ms_share},
                          {"request_bytes", req_bytes},
                          {"reply_bytes", rep_bytes},
                          {"round_trip", to_json(rtt)},
                          {"daemon_solve", to_json(solve)}};
    std::printf("%s\n", out.dump().c_str());
  } else {
    std::printf(
        "k=%zu at %.0f Hz for %.0f s: %zu round trips, %llu timeouts, %llu errors (request ≈ %zu "
        "B, reply ≈ %zu B)\n",
        patch.vertex_ids.size(), rate_hz, seconds, rtt_us.size(),
        static_cast<unsigned long long>(timeouts), static_cast<unsigned long long>(errors),
        req_bytes, rep_bytes);
    std::printf(
        "  round trip   p50 %8.1f µs  p99 %8.1f µs  p99.9 %8.1f µs  max %8.1f µs; within 1 ms "
        "%.2f %%\n",
        rtt.p50, rtt.p99, rtt.p999, rtt.max, 100 * within_1ms_share);
    std::printf("  daemon solve p50 %8.1f µs  p99 %8.1f µs  p99.9 %8.1f µs  max %8.1f µs\n",
                solve.p50, solve.p99, solve.p999, solve.max);
  }
  return timeouts + errors == 0 ? 0 : 1;
} catch (const std::exception& e) {
  std::fprintf(stderr, "palpate_rtt_bench: error: %s\n", e.what());
  return 1;
}
