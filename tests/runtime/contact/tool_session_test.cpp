// A tool's session with the contact engine (docs/tools.md): the device's
// force and rate limits, the watchdog that ramps a silent tool out, a
// client's end, the poses refused with their reason, and a tick that
// allocates nothing.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "runtime/contact/tool_contact_fixture.hpp"
#include "support/allocation_counter.hpp"

namespace palpate::tool_contact_testing {
namespace {

using ::testing::HasSubstr;

TEST_F(ToolContactTest, TheForceNeverExceedsTheDeviceLimitNorJumpsFasterThanTheRate) {
  ToolGeometry g;
  g.id = "grasper";
  g.force_limit_n = 1.0;
  g.max_force_rate_n_per_s = 200;  // 0.2 N per tick
  ToolContactEngine engine(model(), {g}, {}, {});
  Driver driver(engine, 1);
  const Vector3d surface = rest(top_vertex(75, 25));
  const Vector3d above = surface + Vector3d(0, 0, g.tip_length_m + g.tip_radius_m + 0.001);
  start(driver, 0, above);
  driver.move(0, above - Vector3d(0, 0, 0.010), 0, 0.0005);  // fast: 0.5 mm per tick
  driver.hold(20);
  driver.move(0, above, 0, 0.002);  // and out faster still
  driver.hold(10);
  bool limited = false;
  Vector3d previous = Vector3d::Zero();
  for (const auto& out : driver.log) {
    EXPECT_LE(out.force_n.norm(), g.force_limit_n * (1 + 1e-12));
    EXPECT_LE((out.force_n - previous).norm(), g.max_force_rate_n_per_s * kTick * (1 + 1e-9));
    limited |= out.force_limited;
    previous = out.force_n;
  }
  EXPECT_TRUE(limited);
  EXPECT_NEAR(driver.log[driver.log.size() - 5].force_n.norm(), 0.0, 1e-12)
      << "withdrawn: back to zero at the rate limit";
}

TEST_F(ToolContactTest, TheWatchdogRampsAToolOutWhenItsPosesStop) {
  ToolGeometry g;
  g.id = "grasper";
  g.force_limit_n = 100;
  ContactSettings settings;
  settings.watchdog_timeout_s = 0.05;
  settings.watchdog_ramp_s = 0.2;
  ToolContactEngine engine(model(), {g}, settings, {});
  Driver driver(engine, 1);
  const Vector3d surface = rest(top_vertex(75, 25));
  const Vector3d above = surface + Vector3d(0, 0, g.tip_length_m + g.tip_radius_m + 0.001);
  start(driver, 0, above);
  driver.move(0, above - Vector3d(0, 0, 0.005), 0);
  driver.hold(10);
  const double pressed = driver.last(0).force_n.norm();
  ASSERT_GT(pressed, 0.1);

  const double silent_from = driver.now - kTick;
  EXPECT_EQ(engine.watchdog(silent_from + 0.049), 0u) << "within the timeout: nothing";
  double previous = pressed;
  bool saw_watchdog = false;
  for (double t = silent_from + 0.050; t < silent_from + 0.30; t += kTick) {
    if (engine.watchdog(t) & 1) {
      const ToolOutput& out = engine.output(0);
      for (int e = 0; e < out.event_count; ++e)
        saw_watchdog |= out.events[static_cast<std::size_t>(e)] == ToolEventKind::kWatchdog;
      EXPECT_TRUE(out.watchdog || out.state == ToolState::kFree);
      EXPECT_LE(out.force_n.norm(), previous * (1 + 1e-9) + 1e-12);
      previous = out.force_n.norm();
    }
  }
  EXPECT_TRUE(saw_watchdog);
  EXPECT_EQ(previous, 0.0);
  EXPECT_TRUE(engine.contact_indices().empty());
  EXPECT_EQ(engine.watchdog(silent_from + 1.0), 0u) << "a tool ramped out is forgotten";

  driver.now = silent_from + 1.0;
  driver.tick_all();
  EXPECT_TRUE(driver.saw(0, ToolEventKind::kResumed));
  EXPECT_GT(driver.last(0).contacts, 0) << "back where it was, pressing again";
}

TEST_F(ToolContactTest, AClientsEndLetsGoAtOnceAndTheNextSessionStartsAfresh) {
  ToolGeometry g;
  g.id = "grasper";
  g.force_limit_n = 100;
  ToolContactEngine engine(model(), {g, probe("other", kSticks)}, {}, {});
  Driver driver(engine, 1);
  EXPECT_FALSE(engine.end(0, 0)) << "no session yet: nothing to end";
  const Vector3d surface = rest(top_vertex(75, 25));
  const Vector3d above = surface + Vector3d(0, 0, g.tip_length_m + g.tip_radius_m + 0.001);
  start(driver, 0, above);
  driver.move(0, above - Vector3d(0, 0, 0.005), 0);
  ASSERT_GT(driver.last(0).force_n.norm(), 0.1);
  ASSERT_FALSE(engine.contact_indices().empty());

  ASSERT_TRUE(engine.end(0, driver.now));
  const ToolOutput& out = engine.output(0);
  EXPECT_EQ(out.force_n.norm(), 0.0) << "let go at once, no ramp";
  EXPECT_EQ(out.contacts, 0);
  EXPECT_FALSE(out.watchdog);
  ASSERT_GE(out.event_count, 1);
  EXPECT_EQ(out.events[static_cast<std::size_t>(out.event_count - 1)], ToolEventKind::kEnded);
  EXPECT_TRUE(engine.contact_indices().empty()) << "the organ is back at rest";
  EXPECT_EQ(engine.watchdog(driver.now + 1.0), 0u) << "nothing left for the watchdog";
  EXPECT_FALSE(engine.end(0, driver.now)) << "ended twice: the second changes nothing";

  // A new client counts its sequences from 1 again: not stale, not resumed.
  driver.log.clear();
  driver.log_tool.clear();
  driver.poses[0].sequence = 0;
  driver.now += 1.0;
  driver.tick_all();
  EXPECT_FALSE(driver.saw(0, ToolEventKind::kResumed));
  EXPECT_GT(driver.last(0).contacts, 0) << "pressing again where it was";
}

TEST_F(ToolContactTest, AbsurdPosesAreRefusedWithTheirReason) {
  ToolContactEngine engine(model(), {ToolGeometry{.id = "grasper"}}, {}, {});
  const Vector3d above = rest(top_vertex(75, 25)) + Vector3d(0, 0, 0.05);
  auto check = [&](ToolPoseInput p) { return engine.check(0, p); };
  ToolPoseInput good = pose_at(above);
  good.sequence = 1;
  EXPECT_EQ(check(good), PoseProblem::kNone);

  ToolPoseInput p = good;
  p.position_m.x() = std::nan("");
  EXPECT_EQ(check(p), PoseProblem::kNonFinite);
  p = good;
  p.jaw_angle_rad = INFINITY;
  EXPECT_EQ(check(p), PoseProblem::kNonFinite);
  p = good;
  p.orientation = Eigen::Quaterniond(2, 0, 0, 0);
  EXPECT_EQ(check(p), PoseProblem::kBadQuaternion);
  p = good;
  p.orientation = Eigen::Quaterniond(0, 1.05, 0, 0);
  EXPECT_EQ(engine.check(0, p), PoseProblem::kNone);
  EXPECT_NEAR(p.orientation.norm(), 1.0, 1e-15) << "a nearly unit quaternion is normalized";
  p = good;
  p.jaw_angle_rad = -0.01;
  EXPECT_EQ(check(p), PoseProblem::kBadJawAngle);
  EXPECT_THAT(engine.problem_message(), HasSubstr("under its limit"));
  p.jaw_angle_rad = degrees(90);
  EXPECT_EQ(check(p), PoseProblem::kBadJawAngle);
  // The client is told what it sent and what is accepted, in degrees.
  EXPECT_STREQ(engine.problem_message(),
               "jaw angle 90° of tool 'grasper' is over its limit; accepted: 0° to 75°");
  p = good;
  p.position_m.z() += 2.0;
  EXPECT_EQ(check(p), PoseProblem::kOutOfWorkspace);
  EXPECT_THAT(engine.problem_message(), HasSubstr("outside the organ's box"));

  ASSERT_EQ(engine.update(0, good, 0), RequestStatus::kOk);
  EXPECT_EQ(check(good), PoseProblem::kStale) << "the same sequence again";
  EXPECT_THAT(engine.problem_message(), HasSubstr("is not newer than pose 1"));
  good.sequence = 2;
  EXPECT_EQ(check(good), PoseProblem::kNone);
}

TEST_F(ToolContactTest, ATickAllocatesNothing) {
  ToolGeometry g;
  g.id = "left";
  ToolGeometry h = g;
  h.id = "right";
  ToolContactEngine engine(model(), {g, h}, {}, {});
  Driver driver(engine, 2);
  const Vector3d a = rest(top_vertex(75, 12.5)), b = rest(top_vertex(75, 37.5));
  const double reach = g.tip_length_m + g.tip_radius_m;
  start(driver, 0, a + Vector3d(0, 0, reach + 0.001));
  start(driver, 1, b + Vector3d(0, 0, reach + 0.001));
  driver.log.reserve(1000);
  driver.log_tool.reserve(1000);
  const auto before = testing::allocations_here();
  for (int i = 0; i < 200; ++i) {  // both 3 mm deep
    driver.poses[0].position_m.z() -= 2e-5;
    driver.poses[1].position_m.z() -= 2e-5;
    driver.tick_all();
  }
  engine.watchdog(driver.now + 0.1);
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  EXPECT_GT(driver.last(0).contacts, 0);
  EXPECT_GT(driver.last(1).contacts, 0);
}

}  // namespace
}  // namespace palpate::tool_contact_testing
