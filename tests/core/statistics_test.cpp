// Nearest-rank percentiles (core/statistics.hpp): what the heartbeat and the
// clients report.
#include "palpate/core/statistics.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace palpate {
namespace {

TEST(Statistics, NearestRankOfSortedValues) {
  std::vector<double> v;
  for (int i = 1; i <= 101; ++i) v.push_back(i);  // 1 .. 101
  // rank round(q (n − 1)): q = 0.5 → element 50 (value 51), 0.99 → 99 (100).
  EXPECT_EQ(sorted_percentile(v, 0.0), 1);
  EXPECT_EQ(sorted_percentile(v, 0.5), 51);
  EXPECT_EQ(sorted_percentile(v, 0.99), 100);
  EXPECT_EQ(sorted_percentile(v, 1.0), 101);
}

TEST(Statistics, EmptyIsZeroAndOneValueIsItself) {
  EXPECT_EQ(sorted_percentile({}, 0.5), 0);
  const std::vector<double> one{7.5};
  EXPECT_EQ(sorted_percentile(one, 0.999), 7.5);
}

}  // namespace
}  // namespace palpate
