// The id rule every name on palpate's topics follows (core/ids.hpp), and
// the unit conversions at the edges (core/units.hpp).
#include "palpate/core/ids.hpp"

#include <gtest/gtest.h>

#include <numbers>
#include <string>

#include "palpate/core/units.hpp"

namespace palpate {
namespace {

TEST(Ids, AcceptOneTo63LettersDigitsAndUnderscoreDashDot) {
  EXPECT_TRUE(is_valid_id("liver"));
  EXPECT_TRUE(is_valid_id("s1-left_2.tool"));
  EXPECT_TRUE(is_valid_id("A"));
  EXPECT_TRUE(is_valid_id(std::string(63, 'x')));
}

TEST(Ids, RefuseEmptyTooLongAndEverythingElse) {
  EXPECT_FALSE(is_valid_id(""));
  EXPECT_FALSE(is_valid_id(std::string(64, 'x')));
  // Partition wildcards, separators, spaces, non-ASCII letters.
  for (const char* bad : {"a*", "a?", "a[1]", "a\\b", "a/b", "a b", "a:b", "organ\n", "é"})
    EXPECT_FALSE(is_valid_id(bad)) << bad;
  EXPECT_FALSE(is_valid_id(std::string("a\0b", 3)));
}

TEST(Units, MillimetresAndDegreesToSi) {
  EXPECT_DOUBLE_EQ(millimetres(15), 0.015);
  EXPECT_DOUBLE_EQ(degrees(180), std::numbers::pi);
  // Exact at compile time: usable in defaults.
  static_assert(millimetres(1000) == 1.0);
}

}  // namespace
}  // namespace palpate
