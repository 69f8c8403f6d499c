#pragma once
/// @file
/// Wall time since a start, for the phase timings the offline steps report
/// (internal to the libraries).

#include <chrono>

namespace palpate::detail {

/// Seconds of steady-clock time from @p t0 to now.
inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace palpate::detail
