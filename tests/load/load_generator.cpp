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
// every tool answered and touching the organ at some point; no pose refused;
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
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "palpate.h"
#include "palpate/transport/client.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/core/error.hpp"
#include "palpate/runtime/gesture.hpp"
#include "palpate/core/statistics.hpp"
#include "palpate/transport/tool_client.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;
using palpate::ToolEventKind;
using palpate::ToolState;

constexpr float kMissing = std::numeric_limits<float>::quiet_NaN();
constexpr int kChecksFailed = 1;
constexpr int kNoStart = 3;

struct Settings {
  std::string palpated, config, model_file, gesture_file, work = "load-work", json;
  int stations = 4, viewers = 4;
  bool shared_organ = false;  ///< every station on one model ("organ") instead of its own
  double seconds = 600, baseline_s = 30, warmup_s = 30, rate_hz = 1000, request_hz = 100;
  double request_timeout_s = 2, rss_tolerance_mb = 8, start_timeout_s = 60;
};

/// The models palpated serves: one per station, or the shared organ.
std::vector<std::string> model_ids(const Settings& s) {
  if (s.shared_organ) return {"organ"};
  std::vector<std::string> ids;
  for (int k = 1; k <= s.stations; ++k) ids.push_back("station" + std::to_string(k));
  return ids;
}
std::string station_model(const Settings& s, int station) {
  return s.shared_organ ? "organ" : "station" + std::to_string(station);
}
std::string station_tool(int station, const std::string& gesture_tool) {
  return "s" + std::to_string(station) + "-" + gesture_tool;
}

// ------------------------------------------------------------------ children

/// The child's side of the start: "ready" up the first pipe, then the
/// common start time (steady clock, ns) down the second.
class Rendezvous {
 public:
  Rendezvous(int ready_fd, int start_fd) : ready_fd_(ready_fd), start_fd_(start_fd) {}
  std::int64_t ready_then_wait_start() const {
    const char r = 'R';
    if (write(ready_fd_, &r, 1) != 1) throw palpate::SystemError("telling the parent: ready");
    std::int64_t start_ns = 0;
    if (read(start_fd_, &start_ns, sizeof start_ns) != static_cast<ssize_t>(sizeof start_ns))
      throw palpate::SystemError("the parent went away before the start");
    return start_ns;
  }

 private:
  int ready_fd_, start_fd_;
};

Clock::time_point steady_time(std::int64_t ns) {
  return Clock::time_point(
      std::chrono::duration_cast<Clock::duration>(std::chrono::nanoseconds(ns)));
}

/// One tick of one tool, as a station records it; written raw to
/// <work>/<role>-<tool>.ticks (the parent is the same binary).
struct TickRecord {
  float rtt_us = kMissing;  ///< own feedback's round trip (NaN: none came)
  float compute_us = kMissing;
  float lag_us = 0;          ///< pose sent − tick scheduled
  std::uint8_t outcome = 0;  ///< 0 missing, 1 in the tick, 2 late
  std::uint8_t state = 0;    ///< ToolState of the answer
  std::uint8_t contacts = 0;
  std::uint8_t newer = 0;  ///< the wait got the feedback of a newer pose
};
static_assert(sizeof(TickRecord) == 16);

void write_ticks(const fs::path& file, const std::vector<TickRecord>& ticks) {
  std::ofstream out(file, std::ios::binary);
  out.write(reinterpret_cast<const char*>(ticks.data()),
            static_cast<std::streamsize>(ticks.size() * sizeof(TickRecord)));
  if (!out) throw palpate::SystemError(file.string() + ": write failed");
}

std::vector<TickRecord> read_ticks(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw palpate::SystemError(file.string() + ": missing (did the station finish?)");
  std::vector<TickRecord> ticks(fs::file_size(file) / sizeof(TickRecord));
  in.read(reinterpret_cast<char*>(ticks.data()),
          static_cast<std::streamsize>(ticks.size() * sizeof(TickRecord)));
  return ticks;
}

void write_json(const fs::path& file, const json& j) {
  std::ofstream out(file);
  out << j.dump(2) << "\n";
  if (!out) throw palpate::SystemError(file.string() + ": write failed");
}

/// Where station @p station's gesture is anchored on a shared organ: the
/// "auto" anchor for station 1 (the compliance vertex farthest from the
/// attachment), then each next station at the compliance vertex farthest
/// from the anchors before it among those at least half as far from the
/// attachment as the first: spread over the free part of the organ.
std::uint32_t shared_anchor(const palpate::DrawnSurface& surface, int station) {
  const int n = surface.compliance_vertex_count;
  const auto drawn = static_cast<int>(surface.vertex_ids.size());
  auto at = [&](int j) {
    return Eigen::Vector3d(&surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
  };
  std::vector<double> from_fixed(static_cast<std::size_t>(n), 1e9);
  for (int j = 0; j < n; ++j)
    for (int f = n; f < drawn; ++f)
      from_fixed[static_cast<std::size_t>(j)] =
          std::min(from_fixed[static_cast<std::size_t>(j)], (at(j) - at(f)).norm());
  std::vector<int> anchors{palpate::auto_anchor(surface).drawn_index};
  const double reach = from_fixed[static_cast<std::size_t>(anchors[0])];
  while (static_cast<int>(anchors.size()) < station) {
    int best = anchors[0];
    double best_distance = -1;
    for (int j = 0; j < n; ++j) {
      if (from_fixed[static_cast<std::size_t>(j)] < reach / 2) continue;
      double nearest = 1e9;
      for (const int a : anchors) nearest = std::min(nearest, (at(j) - at(a)).norm());
      if (nearest > best_distance) {
        best_distance = nearest;
        best = j;
      }
    }
    anchors.push_back(best);
  }
  return surface.vertex_ids[static_cast<std::size_t>(anchors.back())];
}

/// A station: the gesture's tools on its model, at the haptic rate, from
/// the start time for @p seconds.
int station_child(const Settings& s, int station, const std::string& role, double seconds,
                  const Rendezvous& rendezvous) {
  palpate::Gesture gesture = palpate::read_gesture_file(s.gesture_file);
  for (auto& t : gesture.tools) t.id = station_tool(station, t.id);
  const std::string model_id = station_model(s, station);
  palpate::ToolClient client(palpate::ToolClientOptions{});
  const auto timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(s.start_timeout_s * 1e3));
  const auto model = client.wait_for_model(model_id, timeout);
  if (!model) throw palpate::SystemError("no description of model " + model_id);
  const palpate::DrawnSurface& surface = model->surface;
  if (s.shared_organ) gesture.anchor_vertex_id = shared_anchor(surface, station);
  const palpate::GesturePlayer player(gesture, palpate::place_gesture(gesture, surface));
  if (!client.wait_for_daemon(timeout)) throw palpate::SystemError("palpated reads no tool poses");

  const int tools = player.tool_count();
  const double period_s = 1.0 / s.rate_hz;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s));
  const auto ticks_per_play =
      static_cast<std::size_t>(std::floor(player.duration_s() * s.rate_hz + 1e-9)) + 1;
  const auto total = static_cast<std::size_t>(std::llround(seconds * s.rate_hz));
  // Not in step: station k ticks (k − 1)/N of a period after station 1 and
  // plays its gesture from (k − 1)/N of its length.
  const double fraction = static_cast<double>(station - 1) / s.stations;
  const auto phase_ticks = static_cast<std::size_t>(fraction * static_cast<double>(ticks_per_play));
  std::vector<std::vector<TickRecord>> records(static_cast<std::size_t>(tools),
                                               std::vector<TickRecord>(total));
  std::vector<std::array<std::uint64_t, 6>> events(static_cast<std::size_t>(tools));
  std::array<palpate::ToolFeedbackSample, 64> late{};
  std::uint64_t other_sessions = 0;

  const std::int64_t start_ns = rendezvous.ready_then_wait_start();
  const auto start =
      steady_time(start_ns) + std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(fraction * period_s));
  // Sequences from the steady clock in µs, as palpate-pliers: above those of
  // any earlier run of the same tools (the baseline's).
  const auto first_sequence = static_cast<std::uint64_t>(palpate::ToolClient::now_ns() / 1000);
  auto fill = [](TickRecord& r, const palpate::ToolFeedbackSample& f) {
    r.rtt_us = static_cast<float>(static_cast<double>(f.round_trip_ns()) * 1e-3);
    r.compute_us = static_cast<float>(static_cast<double>(f.compute_ns) * 1e-3);
    r.state = static_cast<std::uint8_t>(f.state);
    r.contacts = static_cast<std::uint8_t>(std::min<std::uint32_t>(f.contacts, 255));
  };
  auto collect_late = [&](int tool, std::size_t now_tick) {
    const std::string& id = player.tool_id(tool);
    for (;;) {
      const std::size_t n = client.take_late_feedback(id, late);
      for (std::size_t k = 0; k < n; ++k) {
        const auto& f = late[k];
        if (f.sequence < first_sequence || f.sequence > first_sequence + now_tick) {
          ++other_sessions;
          continue;
        }
        TickRecord& r = records[static_cast<std::size_t>(tool)][f.sequence - first_sequence];
        if (r.outcome != 0) continue;
        r.outcome = 2;
        fill(r, f);
      }
      if (n < late.size()) return;
    }
  };
  std::size_t played = 0;
  for (std::size_t i = 0; i < total; ++i, ++played) {
    const auto scheduled = start + i * period;
    std::this_thread::sleep_until(scheduled);
    const double t = static_cast<double>((i + phase_ticks) % ticks_per_play) * period_s;
    const std::uint64_t sequence = first_sequence + i;
    for (int k = 0; k < tools; ++k) {
      const palpate::GesturePose pose = player.sample(k, t);
      const auto& q = pose.orientation;
      const std::int64_t sent =
          client.send_pose(player.tool_id(k), model_id, sequence,
                           {pose.hinge_m.x(), pose.hinge_m.y(), pose.hinge_m.z()},
                           {q.w(), q.x(), q.y(), q.z()}, pose.jaw_angle_rad);
      records[static_cast<std::size_t>(k)][i].lag_us = static_cast<float>(
          static_cast<double>(sent - start_ns) * 1e-3 -
          std::chrono::duration<double, std::micro>(scheduled - steady_time(start_ns)).count());
    }
    const auto deadline = scheduled + period;
    for (int k = 0; k < tools; ++k) {
      TickRecord& r = records[static_cast<std::size_t>(k)][i];
      if (const auto f = client.wait_feedback(player.tool_id(k), sequence, deadline)) {
        if (f->sequence == sequence) {
          r.outcome = 1;
          fill(r, *f);
        } else {
          r.newer = 1;
        }
      }
      collect_late(k, i);
    }
    for (const auto& e : client.take_events()) {
      if (e.model_id != model_id || e.pose_sequence < first_sequence) continue;
      for (int k = 0; k < tools; ++k)
        if (player.tool_id(k) == e.tool_id && static_cast<std::size_t>(e.kind) < 6)
          ++events[static_cast<std::size_t>(k)][static_cast<std::size_t>(e.kind)];
    }
  }
  const auto drain_until = Clock::now() + std::chrono::milliseconds(20);
  for (int k = 0; k < tools && played > 0; ++k) {
    client.wait_feedback(player.tool_id(k), first_sequence + played, drain_until);
    collect_late(k, played - 1);
  }

  json tools_json = json::array();
  for (int k = 0; k < tools; ++k) {
    const std::string& id = player.tool_id(k);
    const fs::path file = fs::path(s.work) / (role + "-" + id + ".ticks");
    write_ticks(file, records[static_cast<std::size_t>(k)]);
    json ev = json::object();
    for (std::size_t kind = 0; kind < 6; ++kind)
      ev[palpate::tool_event_name(static_cast<ToolEventKind>(kind))] =
          events[static_cast<std::size_t>(k)][kind];
    tools_json.push_back({{"id", id},
                          {"model", model_id},
                          {"anchor_vertex", player.anchor(k).vertex_id},
                          {"ticks_file", file.filename().string()},
                          {"events", ev}});
  }
  write_json(fs::path(s.work) / (role + ".json"),
             {{"role", role},
              {"tools", tools_json},
              {"ticks", played},
              {"foreign_feedback", client.foreign_feedback()},
              {"dropped_late_feedback", client.dropped_late_feedback()},
              {"other_session_feedback", other_sessions}});
  return 0;
}

/// Nearest-rank percentiles of a sample, and the share above a budget.
struct Distribution {
  std::size_t n = 0;
  double p50 = 0, p90 = 0, p99 = 0, p999 = 0, max = 0, over_budget = 0;
};
Distribution distribution(std::vector<double> v, double budget = 1000) {
  std::sort(v.begin(), v.end());
  Distribution d;
  d.n = v.size();
  d.p50 = palpate::sorted_percentile(v, 0.5);
  d.p90 = palpate::sorted_percentile(v, 0.9);
  d.p99 = palpate::sorted_percentile(v, 0.99);
  d.p999 = palpate::sorted_percentile(v, 0.999);
  d.max = v.empty() ? 0 : v.back();
  const auto over = std::upper_bound(v.begin(), v.end(), budget);
  d.over_budget =
      v.empty() ? 0 : static_cast<double>(v.end() - over) / static_cast<double>(v.size());
  return d;
}
json to_json(const Distribution& d) {
  return {{"n", d.n},
          {"p50_us", d.p50},
          {"p90_us", d.p90},
          {"p99_us", d.p99},
          {"p999_us", d.p999},
          {"max_us", d.max},
          {"over_1ms_share", d.over_budget}};
}

/// A viewer: every model's surface stream and the status heartbeat, with
/// palpate's QoS, counted from the start for @p seconds.
int viewer_child(const Settings& s, const std::string& role, double seconds,
                 const Rendezvous& rendezvous) {
  namespace dds = palpate::dds;
  const dds::Participant participant = dds::join_domain(0, "");
  const dds_entity_t p = participant.get();
  const dds_entity_t surface_reader = dds::check(
      dds_create_reader(p, dds::topic(p, &palpate_SurfaceDisplacement_desc, dds::kSurfaceTopic),
                        dds::surface_qos().get(), nullptr),
      "creating the surface reader");
  const dds_entity_t status_reader =
      dds::check(dds_create_reader(p, dds::topic(p, &palpate_DaemonStatus_desc, dds::kStatusTopic),
                                   dds::status_qos().get(), nullptr),
                 "creating the status reader");
  const dds::Entity waitset(dds::check(dds_create_waitset(p), "creating the waitset"));
  for (const dds_entity_t reader : {surface_reader, status_reader})
    dds::check(dds_waitset_attach(waitset.get(),
                                  dds::check(dds_create_readcondition(reader, DDS_ANY_STATE),
                                             "creating a read condition"),
                                  0),
               "attaching a read condition");
  const auto give_up =
      Clock::now() + std::chrono::milliseconds(static_cast<std::int64_t>(s.start_timeout_s * 1e3));
  for (;;) {
    dds_subscription_matched_status_t surface{}, status{};
    dds_get_subscription_matched_status(surface_reader, &surface);
    dds_get_subscription_matched_status(status_reader, &status);
    if (surface.current_count > 0 && status.current_count > 0) break;
    if (Clock::now() > give_up) throw palpate::SystemError("no surface or status writer");
    dds_sleepfor(DDS_MSECS(10));
  }

  struct PerModel {
    std::uint64_t samples = 0, gaps = 0, out_of_order = 0, last = 0, first = 0;
  };
  std::map<std::string, PerModel> models;
  std::vector<double> latency_us;  // source timestamp → taken, both UTC clocks of this host
  std::uint64_t heartbeats = 0;
  palpate_DaemonStatus last_status{};
  bool counting = false;
  auto take_all = [&] {
    constexpr int kBatch = 16;
    void* samples[kBatch] = {};
    dds_sample_info_t infos[kBatch];
    for (;;) {
      const dds_return_t n = dds_take(surface_reader, samples, infos, kBatch, kBatch);
      if (n < 0)
        throw palpate::SystemError(std::string("taking surface samples: ") + dds_strretcode(n));
      const dds_time_t now = dds_time();
      for (int i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        const auto& d = *static_cast<const palpate_SurfaceDisplacement*>(samples[i]);
        PerModel& m = models[std::string(d.model_id, strnlen(d.model_id, sizeof d.model_id))];
        // Before the start: only where each stream stands.
        if (counting) {
          if (m.last != 0 && d.sequence_number > m.last + 1)
            m.gaps += d.sequence_number - m.last - 1;
          if (m.last != 0 && d.sequence_number <= m.last) ++m.out_of_order;
          if (m.samples++ == 0) m.first = d.sequence_number;
          latency_us.push_back(static_cast<double>(now - infos[i].source_timestamp) * 1e-3);
        }
        m.last = std::max(m.last, d.sequence_number);
      }
      if (n > 0) dds_return_loan(surface_reader, samples, n);
      if (n < kBatch) break;
    }
    for (;;) {
      void* sample = nullptr;
      dds_sample_info_t info;
      const dds_return_t n = dds_take(status_reader, &sample, &info, 1, 1);
      if (n <= 0) break;
      if (info.valid_data && counting) {
        ++heartbeats;
        std::memcpy(&last_status, sample, sizeof last_status);
      }
      dds_return_loan(status_reader, &sample, n);
    }
  };
  take_all();
  const std::int64_t start_ns = rendezvous.ready_then_wait_start();
  std::this_thread::sleep_until(steady_time(start_ns));
  take_all();
  for (auto& [id, m] : models) m.samples = 0;
  counting = true;
  const auto end = steady_time(start_ns) + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(seconds));
  while (Clock::now() < end) {
    dds_attach_t triggered;
    dds_waitset_wait(
        waitset.get(), &triggered, 1,
        std::chrono::duration_cast<std::chrono::nanoseconds>(end - Clock::now()).count());
    take_all();
  }
  json per_model = json::object();
  for (const auto& [id, m] : models)
    per_model[id] = {
        {"samples", m.samples},      {"rate_hz", static_cast<double>(m.samples) / seconds},
        {"sequence_gaps", m.gaps},   {"out_of_order", m.out_of_order},
        {"first_sequence", m.first}, {"last_sequence", m.last}};
  write_json(fs::path(s.work) / (role + ".json"),
             {{"role", role},
              {"models", per_model},
              {"latency", to_json(distribution(std::move(latency_us)))},
              {"heartbeats", heartbeats},
              {"last_status",
               {{"requests_served", last_status.requests_served},
                {"error_replies", last_status.error_replies},
                {"tool_poses", last_status.tool_poses},
                {"tool_poses_refused", last_status.tool_poses_refused},
                {"clients", last_status.clients},
                {"surface_rate_hz", last_status.surface_rate_hz},
                {"request_rate_hz", last_status.request_rate_hz}}}});
  return 0;
}

/// The requester: reliable constraint requests at a steady rate, one in
/// flight, each waited for up to --request-timeout.
int requester_child(const Settings& s, const std::string& role, double seconds,
                    const Rendezvous& rendezvous) {
  palpate::ClientOptions options;
  options.client_id = "load-requests";
  palpate::Client client(options);
  const auto timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(s.start_timeout_s * 1e3));
  // Per model: 12 patches of k = 1, 3, 5, 10 compliance vertices around
  // seeds spread over the surface, pushed 1.5 mm in along the outward normal.
  constexpr int kPatches = 12;
  constexpr std::array<int, 4> kSizes{1, 3, 5, 10};
  std::vector<std::vector<std::vector<palpate::ConstraintSpec>>> patches;
  const std::vector<std::string> models = model_ids(s);
  for (const std::string& model_id : models) {
    const auto model = client.wait_for_model(model_id, timeout);
    if (!model) throw palpate::SystemError("no description of model " + model_id);
    const palpate::DrawnSurface& surface = model->surface;
    const int n = model->surface.compliance_vertex_count;
    auto rest = [&](int j) {
      return Eigen::Vector3d(&model->surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
    };
    auto& mine = patches.emplace_back();
    for (int p = 0; p < kPatches; ++p) {
      const int seed = static_cast<int>(static_cast<long>(p) * n / kPatches);
      std::vector<int> order(static_cast<std::size_t>(n));
      for (int j = 0; j < n; ++j) order[static_cast<std::size_t>(j)] = j;
      const int k = std::min(n, kSizes[static_cast<std::size_t>(p) % kSizes.size()]);
      std::partial_sort(order.begin(), order.begin() + k, order.end(), [&](int a, int b) {
        return (rest(a) - rest(seed)).squaredNorm() < (rest(b) - rest(seed)).squaredNorm();
      });
      auto& patch = mine.emplace_back();
      for (int c = 0; c < k; ++c) {
        const int j = order[static_cast<std::size_t>(c)];
        const Eigen::Vector3d normal = palpate::outward_normal(surface, j);
        patch.push_back(palpate::ConstraintSpec::normal_displacement(
            model->surface.vertex_ids[static_cast<std::size_t>(j)], {normal.x(), normal.y(), normal.z()},
            -0.0015));
      }
    }
  }
  if (!client.wait_for_service(timeout)) throw palpate::SystemError("palpated reads no requests");

  const std::int64_t start_ns = rendezvous.ready_then_wait_start();
  const auto start = steady_time(start_ns);
  const auto end =
      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / s.request_hz));
  const auto reply_timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(s.request_timeout_s * 1e3));
  std::vector<double> rtt_us;
  std::uint64_t sent = 0, ok = 0, errors = 0, lost = 0, behind = 0;
  std::string first_error;
  std::vector<std::uint64_t> lost_ids;
  auto next = start;
  for (std::uint64_t i = 0;; ++i) {
    std::this_thread::sleep_until(next);
    const auto sent_at = Clock::now();
    if (sent_at >= end) break;
    const auto& patch = patches[i % patches.size()][(i / patches.size()) % kPatches];
    const bool want_surface = i % 10 == 9;
    const std::uint64_t id =
        client.send(models[i % models.size()], patch, want_surface, /*update_state=*/false);
    ++sent;
    const auto reply = client.wait_reply(id, reply_timeout);
    if (!reply) {
      ++lost;
      if (lost_ids.size() < 20) lost_ids.push_back(id);
    } else {
      rtt_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - sent_at).count());
      const bool good = reply->status == palpate::RequestStatus::kOk &&
                        reply->results.size() == patch.size() &&
                        (!want_surface || !reply->surface_displacement_m.empty());
      if (good) {
        ++ok;
      } else {
        if (errors++ == 0)
          first_error = reply->message.empty() ? "wrong result count" : reply->message;
      }
    }
    // Steady: the next at its time, or now if this one ran late (no burst).
    next += period;
    if (next < Clock::now()) {
      ++behind;
      next = Clock::now();
    }
  }
  write_json(fs::path(s.work) / (role + ".json"),
             {{"role", role},
              {"sent", sent},
              {"ok", ok},
              {"errors", errors},
              {"first_error", first_error},
              {"lost", lost},
              {"lost_ids", lost_ids},
              {"sent_late", behind},
              {"rate_hz", static_cast<double>(sent) / seconds},
              {"timeout_s", s.request_timeout_s},
              {"foreign_replies", client.foreign_replies()},
              {"round_trip", to_json(distribution(std::move(rtt_us)))}});
  return 0;
}

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
  const pid_t pid = fork();
  if (pid < 0) throw palpate::SystemError("fork: " + std::string(std::strerror(errno)));
  if (pid == 0) {
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

int decode(int status) { return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status); }

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
        c.status = decode(status);
      } else if (Clock::now() > deadline) {
        kill(c.pid, SIGKILL);
        wait4(c.pid, &status, 0, &usage);
        c.exited = true;
        c.status = decode(status);
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

/// palpated as a child process, its stdout and stderr in a file.
class Daemon {
 public:
  Daemon(const std::string& program, const std::vector<std::string>& args, const fs::path& log) {
    std::fflush(nullptr);
    pid_ = fork();
    if (pid_ < 0) throw palpate::SystemError("fork: " + std::string(std::strerror(errno)));
    if (pid_ == 0) {
      const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(fd, 1);
      dup2(fd, 2);
      std::vector<char*> argv{const_cast<char*>(program.c_str())};
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(program.c_str(), argv.data());
      _exit(127);
    }
  }
  ~Daemon() {
    if (alive()) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  pid_t pid() const { return pid_; }
  /// False once it has exited (its status is then in exit_status()).
  bool alive() {
    if (exited_) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      status_ = decode(status);
    }
    return !exited_;
  }
  /// SIGTERM, then its exit status (−1: still there after 20 s, killed).
  int stop() {
    if (!alive()) return status_;
    kill(pid_, SIGTERM);
    for (int i = 0; i < 2000 && alive(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (alive()) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
      exited_ = true;
      status_ = -1;
    }
    return status_;
  }
  int exit_status() const { return status_; }

 private:
  pid_t pid_ = -1;
  bool exited_ = false;
  int status_ = -1;
};

/// One second's look at palpated and the machine.
struct ProcSample {
  double t_s = 0;                                  ///< since the load's start
  double rss_mb = 0, hwm_mb = 0;                   ///< VmRSS, VmHWM (MB = 2^20 bytes)
  double cpu_s = 0;                                ///< palpated's utime + stime
  double machine_busy_s = 0, machine_total_s = 0;  ///< /proc/stat, all CPUs
};

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

/// What one tool's ticks amount to.
struct ToolSummary {
  std::string id;
  std::size_t ticks = 0, in_time = 0, late = 0, missing = 0, newer = 0, within_1ms = 0;
  std::array<std::size_t, 3> states{};
  Distribution rtt, compute, lag;
};

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

/// A station's ticks, read back: per tool, with the station's JSON.
struct StationData {
  json meta;
  std::vector<std::pair<std::string, std::vector<TickRecord>>> tools;
};
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
    std::fprintf(stderr, "palpate_load_generator: error: %s (see --help)\n", e.what());
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
  Daemon daemon(s.palpated, daemon_args, fs::path(s.work) / "palpated.log");
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
    if (!daemon.alive()) {
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
  const bool alive_at_end = !daemon_died && daemon.alive();
  const int daemon_exit = daemon.stop();
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

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (...) {
    return palpate::report_current_exception("palpate_load_generator");
  }
}
