#pragma once
// Private to palpate_daemon: the daemon's clock, its latency log and the
// rate limiter of its repeated warnings.

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <span>
#include <vector>

#include "palpate/core/statistics.hpp"
#include "palpate/transport/messages.hpp"
#include "pi_mutex.hpp"

namespace palpate::daemon {

using Clock = std::chrono::steady_clock;

/// When palpated started: the origin of its tools' clock and session
/// recordings, and of the status heartbeat's uptime.
struct DaemonClock {
  Clock::time_point started = Clock::now();
  double seconds() const { return std::chrono::duration<double>(Clock::now() - started).count(); }
  std::uint64_t uptime_ns() const {
    return static_cast<std::uint64_t>(
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - started).count());
  }
};

/// Latencies of a serving thread, handed to the status publisher once per
/// heartbeat. Fixed capacity: samples beyond it in one interval are dropped
/// from the percentiles (not from the counts).
class LatencyLog {
 public:
  static constexpr std::size_t kCapacity = 1 << 17;
  LatencyLog() : first_us_(kCapacity), second_us_(kCapacity) {}

  /// Records one served sample: two latencies in µs (for requests: the
  /// solve, and request to reply).
  void record(double first_us, double second_us) {
    const std::lock_guard lock(mutex_);
    if (count_ == kCapacity) return;
    first_us_[count_] = first_us;
    second_us_[count_] = second_us;
    ++count_;
  }
  /// Swaps the interval's samples into @p first_us, @p second_us (each of
  /// kCapacity); returns their count.
  std::size_t drain(std::vector<double>& first_us, std::vector<double>& second_us) {
    const std::lock_guard lock(mutex_);
    first_us.swap(first_us_);
    second_us.swap(second_us_);
    return std::exchange(count_, 0);
  }

 private:
  PiMutex mutex_;
  std::vector<double> first_us_, second_us_;
  std::size_t count_ = 0;
};

/// What a serving thread counts, for the status heartbeat: samples served,
/// those refused or answered with an error, and their latencies.
class ServerStats {
 public:
  void count_served() { served_.fetch_add(1, std::memory_order_relaxed); }
  void count_error() { errors_.fetch_add(1, std::memory_order_relaxed); }
  std::uint64_t served() const { return served_.load(std::memory_order_relaxed); }
  std::uint64_t errors() const { return errors_.load(std::memory_order_relaxed); }
  LatencyLog& latencies() { return latencies_; }

 private:
  std::atomic<std::uint64_t> served_{0}, errors_{0};
  LatencyLog latencies_;
};

/// Nearest-rank percentiles of the first @p count of @p values_us (sorted here).
inline LatencySummary percentiles(std::vector<double>& values_us, std::size_t count) {
  LatencySummary latency;
  if (count == 0) return latency;
  std::sort(values_us.begin(), values_us.begin() + static_cast<std::ptrdiff_t>(count));
  const std::span<const double> sorted(values_us.data(), count);
  latency.p50_us = sorted_percentile(sorted, 0.50);
  latency.p99_us = sorted_percentile(sorted, 0.99);
  latency.p999_us = sorted_percentile(sorted, 0.999);
  latency.max_us = sorted.back();
  return latency;
}

/// Logs a repeated warning at most once per second per reason, with the
/// number of occurrences folded into it.
class WarningLimiter {
 public:
  template <typename... Args>
  void warn(int reason, fmt::format_string<Args...> format, Args&&... args) {
    const auto now = Clock::now();
    Slot& slot = slots_[static_cast<std::size_t>(reason) % slots_.size()];
    ++slot.count;
    if (slot.logged && now - slot.last < std::chrono::seconds(1)) return;
    spdlog::warn("{} occurrences={}", fmt::format(format, std::forward<Args>(args)...), slot.count);
    slot.count = 0;
    slot.logged = true;
    slot.last = now;
  }

 private:
  struct Slot {
    std::uint64_t count = 0;
    bool logged = false;
    Clock::time_point last{};
  };
  std::array<Slot, 16> slots_{};
};

}  // namespace palpate::daemon
