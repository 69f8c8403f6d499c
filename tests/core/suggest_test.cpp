// "Did you mean": the near-miss flags users type, and what must not be suggested.

#include "palpate/core/suggest.hpp"

#include <gtest/gtest.h>

namespace palpate {
namespace {

const std::vector<std::string> kFlags{"job",           "mesh",    "mesh-unit", "young-modulus",
                                      "poisson-ratio", "nu",      "fix-box",   "output",
                                      "displacement",  "surface", "model"};

TEST(Suggest, AShortenedFlagGetsTheFlagItBegins) {
  EXPECT_EQ(closest_flag("--poisson", kFlags), "--poisson-ratio");
  EXPECT_EQ(closest_flag("--young", kFlags), "--young-modulus");
}

TEST(Suggest, ATypoGetsTheNearestFlag) {
  EXPECT_EQ(closest_flag("--displacment", kFlags), "--displacement");
  EXPECT_EQ(closest_flag("--ouptut", kFlags), "--output");
  EXPECT_EQ(closest_flag("--mesh-units", kFlags), "--mesh-unit");
}

TEST(Suggest, NothingCloseGetsNothing) {
  EXPECT_EQ(closest_flag("--compliance", kFlags), "");
  EXPECT_EQ(closest_flag("--x", kFlags), "");
  EXPECT_EQ(closest_flag("--model", kFlags), "") << "a known flag needs no suggestion";
}

TEST(Suggest, TheLineNamesEachSuggestionOnceAndIgnoresValues) {
  const std::vector<std::string> args{"--job",         "a.toml",        "--poisson", "0.45",
                                      "--poisson=0.4", "--displacment", "1:0,0,0"};
  EXPECT_EQ(flag_suggestions(args, kFlags), " (did you mean --poisson-ratio or --displacement?)");
  EXPECT_EQ(flag_suggestions(std::vector<std::string>{"--job", "0.45"}, kFlags), "");
}

}  // namespace
}  // namespace palpate
