#pragma once
/// @file
/// Whether palpated is there, as a client knows it from the status
/// heartbeat (docs/faults.md): what Client and ToolClient report.

#include <cstdint>
#include <optional>
#include <string>

namespace palpate {

/// What a client knows of palpated from its status heartbeat (palpate_status,
/// docs/dds.md): whether it is there, and whether it was restarted.
enum class DaemonState : std::uint8_t {
  kUnknown,  ///< no heartbeat yet
  kPresent,  ///< a heartbeat within the timeout
  kLost,     ///< silent for longer than the timeout: killed, hung, or unreachable
};

struct DaemonPresence {
  DaemonState state = DaemonState::kUnknown;
  std::uint64_t losses = 0;       ///< times it went from present to lost
  std::uint64_t restarts = 0;     ///< heartbeats whose uptime went back: a new palpated process
  double silent_s = 0;            ///< since the last heartbeat (0 before the first)
  double uptime_s = 0;            ///< palpated's uptime in the last heartbeat
  double heartbeat_period_s = 0;  ///< measured (0 until two heartbeats came)
  double timeout_s = 0;           ///< the silence that means lost, now
};

/// One line saying what changed from @p before to @p now ("palpated lost: no
/// status heartbeat for 3.6 s", "palpated is back (up 0.4 s; restarted)",
/// "palpated restarted (up 0.2 s)"), or std::nullopt if nothing did. For
/// clients to report the daemon going and coming back.
std::optional<std::string> describe_presence_change(const DaemonPresence& before,
                                                    const DaemonPresence& now);

}  // namespace palpate
