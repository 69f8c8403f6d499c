#pragma once
/// @file
/// The latency percentiles palpated's heartbeat and palpate-client report.

#include <cstddef>
#include <span>

namespace palpate {

/// The q-quantile (q in [0, 1]) of @p sorted values: the element at rank
/// round(q · (n − 1)). 0 for no values.
inline double sorted_percentile(std::span<const double> sorted, double q) {
  if (sorted.empty()) return 0;
  return sorted[static_cast<std::size_t>(q * static_cast<double>(sorted.size() - 1) + 0.5)];
}

}  // namespace palpate
