#pragma once
// palpate-pliers' records of a run and what it reports of them: one record
// per tick and tool, each tool's summary (round trip, compute, lag
// percentiles; forces, states, events; what the device rendered), its lines
// and JSON, the per-tick CSV (docs/pliers.md, "Output").

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/device.h"
#include "palpate/runtime/tool_state.hpp"
#include "palpate/transport/presence.hpp"

namespace palpate::pliers {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

enum class Outcome : std::uint8_t {
  kMissing,  ///< no feedback for this pose (yet)
  kInTime,   ///< its feedback was taken before the next tick
  kLate,     ///< its feedback came during a later tick
};
inline const char* outcome_name(Outcome o) {
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
  /// What palpate_device_force() rendered at the tick's last device step
  /// (N, model frame; zero while palpated is lost), the largest |force| over
  /// the tick's device steps, the passivity controller's largest damping
  /// (N·s/m) and the observer's energy at the last step (J).
  double rendered_n = 0;
  std::array<double, 3> rendered_force_n{};
  double rendered_max_n = 0, damping_n_s_per_m = 0, energy_j = 0;
  palpate::DaemonState daemon = palpate::DaemonState::kUnknown;  ///< at that time
};

/// Closes a palpate_device handle (ending its session if it is live).
struct DeviceCloser {
  void operator()(palpate_device* d) const { palpate_device_close(d); }
};
using Device = std::unique_ptr<palpate_device, DeviceCloser>;

struct ToolRun {
  std::string id;
  int gesture_index = 0;
  Device device;  ///< this tool on the model (palpate/device.h)
  std::vector<TickRecord> ticks;
  std::array<std::uint64_t, 7> events{};  // by ToolEventKind
  std::uint64_t notices = 0;              // poses palpated said it refused (rate limited)
  std::string first_refusal;              // the first reason palpated gave
};

/// The percentiles of a latency sample, µs.
struct Percentiles {
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};
Percentiles percentiles(std::vector<double> v);
nlohmann::json to_json(const Percentiles& p);

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
  // At the device's rate: the largest |force| of any step, the passivity
  // controller's largest damping and the ticks it damped.
  double max_rendered_step_n = 0, max_damping = 0;
  std::size_t damped_ticks = 0;
};

/// The summary of @p run's ticks from @p first_counted on; @p budget_us is
/// one tick (a round trip within it is "in time").
ToolSummary summarize(const ToolRun& run, std::size_t first_counted, double budget_us);

const char* daemon_state_name(DaemonState state);
/// part / whole in per cent (0 when whole is 0).
double share(std::size_t part, std::size_t whole);

/// Prints one tool's lines of the summary and returns its JSON.
nlohmann::json print_tool(const ToolRun& run, const ToolSummary& s, int anchor_vertex,
                          double budget_us, double device_rate_hz);

/// The per-tick CSV (--csv): one line per tick and tool, tick order.
void write_csv(const std::string& path, const std::vector<ToolRun>& runs, std::size_t first_counted,
               std::int64_t start_ns);

}  // namespace palpate::pliers
