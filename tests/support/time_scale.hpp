#pragma once
// How much slower than normal the test programs run: PALPATE_TEST_TIME_SCALE
// (scripts/sanitize.sh sets 3 under ASan, 5 under TSan; docs/sanitizers.md),
// 1 when unset or not a number >= 1. Tests stretch bounded waits and paced
// rates by it rather than skip under the sanitizers.

#include <cstdlib>

namespace palpate::testing {

inline double time_scale() {
  const char* text = std::getenv("PALPATE_TEST_TIME_SCALE");
  if (text == nullptr) return 1.0;
  char* end = nullptr;
  const double scale = std::strtod(text, &end);
  return end != text && *end == '\0' && scale >= 1.0 ? scale : 1.0;
}

}  // namespace palpate::testing
