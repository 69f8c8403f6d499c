#include "palpate/transport/presence.hpp"

#include <fmt/format.h>

namespace palpate {

std::optional<std::string> describe_presence_change(const DaemonPresence& before,
                                                    const DaemonPresence& now) {
  if (now.state == DaemonState::kLost && before.state != DaemonState::kLost)
    return fmt::format("palpated lost: no status heartbeat for {:.1f} s", now.silent_s);
  const bool restarted = now.restarts > before.restarts;
  if (now.state == DaemonState::kPresent && before.state == DaemonState::kLost)
    return fmt::format("palpated is back (up {:.1f} s{})", now.uptime_s,
                       restarted ? "; restarted" : "");
  if (now.state == DaemonState::kPresent && restarted)
    return fmt::format("palpated restarted (up {:.1f} s)", now.uptime_s);
  return std::nullopt;
}

}  // namespace palpate
