#pragma once
// Private to palpate_load_generator: what its parent process and its
// children (stations, viewers, the requester) share: the settings, the
// start rendezvous, the tick records the stations write, the distributions
// they report.

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/core/statistics.hpp"

namespace palpate::load {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

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
inline std::vector<std::string> model_ids(const Settings& s) {
  if (s.shared_organ) return {"organ"};
  std::vector<std::string> ids;
  for (int k = 1; k <= s.stations; ++k) ids.push_back("station" + std::to_string(k));
  return ids;
}
inline std::string station_model(const Settings& s, int station) {
  return s.shared_organ ? "organ" : "station" + std::to_string(station);
}
inline std::string station_tool(int station, const std::string& gesture_tool) {
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

inline Clock::time_point steady_time(std::int64_t ns) {
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

inline void write_ticks(const fs::path& file, const std::vector<TickRecord>& ticks) {
  std::ofstream out(file, std::ios::binary);
  out.write(reinterpret_cast<const char*>(ticks.data()),
            static_cast<std::streamsize>(ticks.size() * sizeof(TickRecord)));
  if (!out) throw palpate::SystemError(file.string() + ": write failed");
}

inline std::vector<TickRecord> read_ticks(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw palpate::SystemError(file.string() + ": missing (did the station finish?)");
  std::vector<TickRecord> ticks(fs::file_size(file) / sizeof(TickRecord));
  in.read(reinterpret_cast<char*>(ticks.data()),
          static_cast<std::streamsize>(ticks.size() * sizeof(TickRecord)));
  return ticks;
}

inline void write_json(const fs::path& file, const json& j) {
  std::ofstream out(file);
  out << j.dump(2) << "\n";
  if (!out) throw palpate::SystemError(file.string() + ": write failed");
}

struct Distribution {
  std::size_t n = 0;
  double p50 = 0, p90 = 0, p99 = 0, p999 = 0, max = 0, over_budget = 0;
};
inline Distribution distribution(std::vector<double> v, double budget = 1000) {
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
inline json to_json(const Distribution& d) {
  return {{"n", d.n},
          {"p50_us", d.p50},
          {"p90_us", d.p90},
          {"p99_us", d.p99},
          {"p999_us", d.p999},
          {"max_us", d.max},
          {"over_1ms_share", d.over_budget}};
}

// ---- the children (load_children.cpp) ---------------------------------------------

/// A station: the gesture's tools on its model, at the haptic rate, from
/// the start time for @p seconds.
int station_child(const Settings& s, int station, const std::string& role, double seconds,
                  const Rendezvous& rendezvous);
/// A viewer: every model's surface stream and the status heartbeat, with
/// palpate's QoS, counted from the start for @p seconds.
int viewer_child(const Settings& s, const std::string& role, double seconds,
                 const Rendezvous& rendezvous);
/// The requester: reliable constraint requests at a steady rate, one in
/// flight, each waited for up to --request-timeout.
int requester_child(const Settings& s, const std::string& role, double seconds,
                    const Rendezvous& rendezvous);

}  // namespace palpate::load
