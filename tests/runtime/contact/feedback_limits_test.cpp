// The device's force and slew limits on a tool's feedback (FeedbackLimits,
// docs/tools.md "One tick", step 5) on cases computed by hand.

#include "palpate/runtime/contact/feedback_limits.hpp"

#include <gtest/gtest.h>

namespace palpate::detail {
namespace {

using Eigen::Vector3d;

// Every expected value below is exact in decimal and a few roundings away
// from the inputs (a norm, a division, a product), so it is met to a few
// ulps: 1e-12 N (N·m) is thousands of ulps at these magnitudes (≤ 10).
constexpr double kLimitsTolerance = 1e-12;

void expect_vector_near(const Vector3d& actual, const Vector3d& expected) {
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(actual[i], expected[i], kLimitsTolerance) << "component " << i;
}

FeedbackLimits::Last sent(const Vector3d& force_n, double since_s) {
  return {true, force_n, since_s};
}

TEST(FeedbackLimits, AForceOverTheLimitIsClampedAndScalesTorqueAndGrip) {
  // 8 N limit, a slew limit that does not bite (1e6 N/s × 1 ms = 1000 N).
  const FeedbackLimits limits(8, 1e6);
  const auto out = limits.limit(Vector3d(0, 0, 10), Vector3d(0.1, 0, -0.05), 2.0,
                                sent(Vector3d(0, 0, 9), 0.001));
  expect_vector_near(out.force_n, Vector3d(0, 0, 8));           // 10 N × 8/10
  expect_vector_near(out.torque_nm, Vector3d(0.08, 0, -0.04));  // × |F| / |F_raw| = 0.8
  EXPECT_NEAR(out.grip_n, 1.6, kLimitsTolerance);
  EXPECT_TRUE(out.limited);
}

TEST(FeedbackLimits, AForceThatJumpsMovesAtTheSlewRate) {
  // 500 N/s × 2 ms = 1 N from the last 1 N towards 4 N (under the limit).
  const FeedbackLimits limits(8, 500);
  const auto out =
      limits.limit(Vector3d(0, 0, 4), Vector3d(0, 0.2, 0), 1.0, sent(Vector3d(0, 0, 1), 0.002));
  expect_vector_near(out.force_n, Vector3d(0, 0, 2));
  expect_vector_near(out.torque_nm, Vector3d(0, 0.1, 0));  // 2 N of 4: × 0.5
  EXPECT_NEAR(out.grip_n, 0.5, kLimitsTolerance);
  EXPECT_TRUE(out.limited);
}

TEST(FeedbackLimits, ClampThenSlewFromTheLastForce) {
  // |(0, 6, 8)| = 10 N → clamped to (0, 4.8, 6.4); from zero at
  // 500 N/s × 4 ms = 2 N along it: (0, 1.2, 1.6), 2 N of the raw 10.
  const FeedbackLimits limits(8, 500);
  const auto out =
      limits.limit(Vector3d(0, 6, 8), Vector3d(1, 2, 3), 5.0, sent(Vector3d::Zero(), 0.004));
  expect_vector_near(out.force_n, Vector3d(0, 1.2, 1.6));
  expect_vector_near(out.torque_nm, Vector3d(0.2, 0.4, 0.6));  // × 0.2
  EXPECT_NEAR(out.grip_n, 1.0, kLimitsTolerance);
  EXPECT_TRUE(out.limited);
}

TEST(FeedbackLimits, WithinBothLimitsTheWrenchPassesUnchanged) {
  // |(1, 2, 2)| = 3 N; the change from (1, 2, 2.5) is 0.5 N, exactly the
  // 500 N/s × 1 ms allowed: not limited.
  const FeedbackLimits limits(8, 500);
  const auto out = limits.limit(Vector3d(1, 2, 2), Vector3d(0.3, -0.1, 0), 0.7,
                                sent(Vector3d(1, 2, 2.5), 0.001));
  expect_vector_near(out.force_n, Vector3d(1, 2, 2));
  expect_vector_near(out.torque_nm, Vector3d(0.3, -0.1, 0));
  EXPECT_NEAR(out.grip_n, 0.7, kLimitsTolerance);
  EXPECT_FALSE(out.limited);
}

TEST(FeedbackLimits, TheIntervalIsClampedToTenMillisecondsAndNotBelowZero) {
  const FeedbackLimits limits(8, 100);
  // 1 s of silence grants 100 N/s × 10 ms = 1 N, not 100 N.
  expect_vector_near(
      limits.limit(Vector3d(0, 0, 5), Vector3d::Zero(), 0, sent(Vector3d::Zero(), 1.0)).force_n,
      Vector3d(0, 0, 1));
  // A clock that went back grants nothing: the last force is sent again.
  const auto back =
      limits.limit(Vector3d(0, 0, 5), Vector3d::Zero(), 0, sent(Vector3d(0, 0, 3), -0.5));
  expect_vector_near(back.force_n, Vector3d(0, 0, 3));
  EXPECT_TRUE(back.limited);
}

TEST(FeedbackLimits, AFirstOutputMovesFromZeroForOneMillisecond) {
  const FeedbackLimits limits(8, 500);  // 500 N/s × 1 ms = 0.5 N
  const auto out = limits.limit(Vector3d(3, 0, 4), Vector3d(0, 0, 1), 2.0, {});
  expect_vector_near(out.force_n, Vector3d(0.3, 0, 0.4));  // 0.5 N of 5: × 0.1
  expect_vector_near(out.torque_nm, Vector3d(0, 0, 0.1));
  EXPECT_NEAR(out.grip_n, 0.2, kLimitsTolerance);
  EXPECT_TRUE(out.limited);
}

TEST(FeedbackLimits, ATorqueWithoutForceIsNotSent) {
  const FeedbackLimits limits(8, 500);
  const auto out =
      limits.limit(Vector3d::Zero(), Vector3d(0.1, 0.2, 0.3), 1.0, sent(Vector3d::Zero(), 0.001));
  expect_vector_near(out.force_n, Vector3d::Zero());
  expect_vector_near(out.torque_nm, Vector3d::Zero());
  EXPECT_EQ(out.grip_n, 0.0);
  EXPECT_FALSE(out.limited);
}

TEST(FeedbackLimits, AToolNotFeltIsSentNothingAndNotLimited) {
  const FeedbackLimits limits(8, 500);
  const auto out = limits.limit(Vector3d(0, 0, 20), Vector3d(1, 0, 0), 3.0,
                                sent(Vector3d(0, 0, 5), 0.001), /*felt=*/false);
  expect_vector_near(out.force_n, Vector3d::Zero());
  expect_vector_near(out.torque_nm, Vector3d::Zero());
  EXPECT_EQ(out.grip_n, 0.0);
  EXPECT_FALSE(out.limited);
}

}  // namespace
}  // namespace palpate::detail
