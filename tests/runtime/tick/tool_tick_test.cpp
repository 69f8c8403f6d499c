// The tool tick whole (ToolTick): what the device is sent on a model with a
// cut region goes through the device's slew limit, the session file records
// exactly what was sent, and on a model without a region the tick is the
// contact engine's update.

#include "palpate/runtime/tool_tick.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "palpate/runtime/session_recorder.hpp"
#include "runtime/hybrid_organ.hpp"
#include "support/box_model_suite.hpp"
#include "support/h5_reader.hpp"
#include "support/sphere_tool.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;
using testing::kLz;

constexpr double kRateNPerS = 10;  // a slow slew limit: 10 mN per 1 ms tick
constexpr double kTickS = 1e-3;

/// A 6 mm sphere with a slow slew limit, no friction.
ToolGeometry slow_probe() {
  ToolGeometry g = testing::sphere_tool("probe", 0.006);
  g.max_force_rate_n_per_s = kRateNPerS;
  g.force_limit_n = 3;
  return g;
}

/// A pose of the probe, tip down, its centre at @p centre.
ToolPoseInput pose_at(const Vector3d& centre, std::uint64_t sequence) {
  ToolPoseInput pose;
  pose.sequence = sequence;
  pose.position_m = centre;
  pose.orientation = Eigen::Quaterniond(0, 1, 0, 0);
  return pose;
}

/// The probe pressed 3 mm into the region's top at once (one tick from
/// outside to inside) and held for @p ticks: per tick, what the tool was
/// sent and the region's push on its tip, and every record made.
struct RegionPress {
  std::vector<Vector3d> sent, push;
};
RegionPress press_the_region(ToolTick& tick, int ticks, SessionRecorder* recorder) {
  RegionPress p;
  const Vector3d above(0.080, 0.032, kLz + 0.010);
  const Vector3d in(0.080, 0.032, kLz + 0.006 - 0.003);
  for (int k = 1; k <= ticks; ++k) {
    ToolPoseInput pose = pose_at(k <= 2 ? above : in, static_cast<std::uint64_t>(k));
    EXPECT_EQ(tick.engine().check(0, pose), PoseProblem::kNone);
    const double now_s = kTickS * k;
    EXPECT_EQ(tick.update(0, pose, now_s), RequestStatus::kOk);
    EXPECT_TRUE(tick.region_stepped());
    p.sent.push_back(tick.output(0).force_n);
    p.push.push_back(tick.region()->tip_force_n(0));
    if (recorder != nullptr) tick.record(0, now_s, 1000, *recorder);
  }
  return p;
}

// The region's push on the tip arrives in one tick; the force sent may
// change by at most max_force_rate_n_per_s × Δt per tick whatever it comes
// from (before ToolTick, the daemon added the push after the slew limit:
// the force stepped by the whole push, 0.53 N, in one tick, against the
// 10 mN allowed).
TEST(ToolTick, TheRegionsPushIsSlewLimitedLikeTheContacts) {
  const testing::Organ o;
  HybridRegion region(o.model);
  ToolTick tick(o.model, {slow_probe()}, {}, {}, nullptr, &region);
  const RegionPress p = press_the_region(tick, 400, nullptr);
  const double allowed = kRateNPerS * kTickS;
  double largest_sent = 0, largest_push = 0;
  for (std::size_t k = 1; k < p.sent.size(); ++k) {
    largest_sent = std::max(largest_sent, (p.sent[k] - p.sent[k - 1]).norm());
    largest_push = std::max(largest_push, (p.push[k] - p.push[k - 1]).norm());
  }
  std::printf("largest step per tick: push %.4g N, sent %.4g N (allowed %.4g N)\n", largest_push,
              largest_sent, allowed);
  // The test means something: the push alone steps far faster than allowed.
  EXPECT_GT(largest_push, 10 * allowed);
  EXPECT_LE(largest_sent, allowed * (1 + 1e-9));
  // And the force reaches the push once the limit lets it: the region's
  // push is all the probe feels there (the rest's triangles under the
  // region are hidden), to round-off once settled.
  EXPECT_EQ(tick.engine().output(0).contacts, 0);
  EXPECT_GT(p.push.back().norm(), 0.05);
  EXPECT_LE((p.sent.back() - p.push.back()).norm(), 1e-9 * p.push.back().norm());
}

// The session file's force is the force sent, tick by tick, on a model whose
// region pushes the tool (before ToolTick, the daemon recorded the contacts'
// force without the push).
TEST(ToolTick, TheRecordedForceIsTheForceSent) {
  const testing::Organ o;
  HybridRegion region(o.model);
  ToolTick tick(o.model, {slow_probe()}, {}, {}, nullptr, &region);
  testing::TempDir dir;
  const std::filesystem::path file = dir.path() / "session.h5";
  SessionInfo info;
  info.model_id = "organ";
  info.tools = {slow_probe()};
  RegionPress p;
  {
    SessionRecorder recorder(file, info);
    p = press_the_region(tick, 200, &recorder);
    recorder.close();
  }
  const testing::H5Reader h5(file);
  const std::vector<double> force = h5.read<double>("/tools/probe/force", 3);
  ASSERT_EQ(force.size(), 3 * p.sent.size());
  int pushed = 0;
  for (std::size_t k = 0; k < p.sent.size(); ++k) {
    pushed += p.push[k].norm() > 0 ? 1 : 0;
    for (int d = 0; d < 3; ++d)
      ASSERT_EQ(force[3 * k + static_cast<std::size_t>(d)], p.sent[k][d]) << "tick " << k;
  }
  EXPECT_GT(pushed, 100) << "the region pushed the tool on most ticks";
}

// Without a region, a tick is the engine's update: the same output, bit for
// bit, as a bare engine given the same poses (a press with friction, then a
// slow slide).
using ToolTickOnTheBox = testing::BoxModelSuite<>;
TEST_F(ToolTickOnTheBox, WithoutARegionTheTickIsTheEnginesUpdate) {
  const ToolGeometry g = testing::sphere_tool("probe", 0.004, 0.3);
  ToolTick tick(model(), {g}, {}, {});
  ToolContactEngine bare(model(), {g}, {}, {});
  EXPECT_EQ(tick.region(), nullptr);
  const Vector3d top(0.050, 0.025, 0.040);
  for (int k = 1; k <= 60; ++k) {
    const double depth = 0.0002 * std::min(k, 30);
    ToolPoseInput a = pose_at(top + Vector3d(1e-5 * k, 0, 0.004 - depth), k), b = a;
    ASSERT_EQ(tick.engine().check(0, a), PoseProblem::kNone);
    ASSERT_EQ(bare.check(0, b), PoseProblem::kNone);
    ASSERT_EQ(tick.update(0, a, kTickS * k), bare.update(0, b, kTickS * k));
    EXPECT_EQ(tick.output(0).force_n, bare.output(0).force_n) << "tick " << k;
    EXPECT_EQ(tick.output(0).contacts, bare.output(0).contacts) << "tick " << k;
  }
  EXPECT_GT(tick.output(0).force_n.norm(), 0.01);
}

}  // namespace
}  // namespace palpate
