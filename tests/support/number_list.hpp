#pragma once
// "1.5,2,-3": the comma-separated numbers of a command-line option, for the
// small test programs (palpate_sphere_press, palpate_lift), which each say
// how to use them when a list is not one.

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

namespace palpate::testing {

/// The finite numbers of @p text, separated by commas; nothing when an item
/// is empty, not a number or not finite.
inline std::optional<std::vector<double>> number_list(const std::string& text) {
  std::vector<double> out;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = std::min(text.find(',', start), text.size());
    const std::string item = text.substr(start, end - start);
    char* stop = nullptr;
    const double v = std::strtod(item.c_str(), &stop);
    if (item.empty() || *stop != '\0' || !std::isfinite(v)) return std::nullopt;
    out.push_back(v);
    start = end + 1;
  }
  return out;
}

}  // namespace palpate::testing
