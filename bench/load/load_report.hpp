#pragma once
// Private to palpate_load_generator: what the parent measures of palpated
// and the machine, the summary of the stations' ticks, and the table it
// prints (load_report.cpp).

#include <sys/types.h>

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "load_common.hpp"

namespace palpate::load {

// One second's look at palpated and the machine.
struct ProcSample {
  double t_s = 0;                                  ///< since the load's start
  double rss_mb = 0, hwm_mb = 0;                   ///< VmRSS, VmHWM (MB = 2^20 bytes)
  double cpu_s = 0;                                ///< palpated's utime + stime
  double machine_busy_s = 0, machine_total_s = 0;  ///< /proc/stat, all CPUs
};

/// What one tool's ticks amount to.
struct ToolSummary {
  std::string id;
  std::size_t ticks = 0, in_time = 0, late = 0, missing = 0, newer = 0, within_1ms = 0;
  std::array<std::size_t, 3> states{};
  Distribution rtt, compute, lag;
};

/// A station's ticks, read back: per tool, with the station's JSON.
struct StationData {
  json meta;
  std::vector<std::pair<std::string, std::vector<TickRecord>>> tools;
};

/// palpated's memory and CPU, and the machine's CPU, now; none once it exited.
std::optional<ProcSample> sample_process(pid_t pid);
/// The whole text of @p file ("" when it cannot be read).
std::string read_text(const fs::path& file);
/// The summary of one tool's ticks, against a round-trip budget (µs).
ToolSummary summarize(const std::string& id, const std::vector<TickRecord>& ticks,
                      double budget_us);
/// The load average of the machine, as JSON.
json load_average();
/// The CPU model of the machine.
std::string machine_model();
/// @p part / @p whole, 0 for no whole.
double share(std::size_t part, std::size_t whole);
json to_json(const ToolSummary& s, double seconds);
/// What station @p role wrote in @p work.
StationData read_station(const fs::path& work, const std::string& role);
std::string fmt_lost(const json& r);
std::string fmt_rss(const ProcSample& first, const ProcSample& last, double tolerance_mb);
/// The summary as a table on stdout.
void print_table(const json& s);
/// "2026-11-23T19:51:00Z".
std::string utc_now();

}  // namespace palpate::load
