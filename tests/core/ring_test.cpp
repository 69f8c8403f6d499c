// The fixed-capacity FIFO of palpate/core/ring.hpp: order, and the oldest
// element dropped (and said so) when full.

#include "palpate/core/ring.hpp"

#include <gtest/gtest.h>

namespace palpate {
namespace {

TEST(Ring, KeepsOrderAndDropsTheOldestWhenFull) {
  Ring<int, 3> ring;
  EXPECT_TRUE(ring.empty());
  EXPECT_TRUE(ring.push(1));
  EXPECT_TRUE(ring.push(2));
  EXPECT_TRUE(ring.push(3));
  EXPECT_EQ(ring.size(), 3u);
  EXPECT_FALSE(ring.push(4));  // full: 1 is dropped
  EXPECT_EQ(ring.size(), 3u);
  for (int expected : {2, 3, 4}) {
    ASSERT_FALSE(ring.empty());
    EXPECT_EQ(ring.front(), expected);
    ring.pop();
  }
  EXPECT_TRUE(ring.empty());
}

TEST(Ring, WrapsAroundManyTimes) {
  Ring<int, 4> ring;
  int next_out = 0;
  for (int in = 0; in < 1000; ++in) {
    ring.push(in);
    if (in % 3 == 2) {  // three in, three out: the head walks round the 4 slots
      for (int k = 0; k < 3; ++k) {
        ASSERT_EQ(ring.front(), next_out++);
        ring.pop();
      }
    }
  }
  EXPECT_TRUE(ring.empty() || ring.size() == 1u);
  EXPECT_EQ(next_out, 999);
}

}  // namespace
}  // namespace palpate
