// The C API for haptic devices (palpate/device.h, docs/devices.md): bad
// arguments give their status and message and never crash; then, against
// the real palpated on a box model over real Cyclone DDS (CTest runs this in
// a private network namespace), a whole session from the servo loop's side
// (open, poses at 4 kHz sent at 1 kHz, the local model rendered, events,
// the end), and the C example of a simulated device (examples/devices/
// simulated_device.c) as a child process: what its hand felt.

#include "palpate/device.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <numbers>
#include <span>
#include <sstream>
#include <string>
#include <thread>

#include "support/allocation_counter.hpp"
#include "support/box_job.hpp"
#include "support/child_process.hpp"
#include "support/daemon_process.hpp"
#include "support/test_meshes.hpp"

namespace palpate::testing {
namespace {

using namespace std::chrono_literals;

constexpr std::size_t kErrorSize = 512;

/// A tool of 1 to 63 characters among A-Z a-z 0-9 _ - . (docs/dds.md).
const char* const kLongId = "a123456789b123456789c123456789d123456789e123456789f123456789g1234";

palpate_device_options options_for(const char* model, const char* tool) {
  palpate_device_options o;
  palpate_device_options_init(&o);
  o.model_id = model;
  o.tool_id = tool;
  return o;
}

// ---------------------------------------------------------------------------
// Without palpated: arguments.

TEST(DeviceApi, VersionAndStatusNames) {
  int major = -1, minor = -1, patch = -1;
  palpate_device_version(&major, &minor, &patch);
  EXPECT_EQ(major, PALPATE_DEVICE_VERSION_MAJOR);
  EXPECT_EQ(minor, PALPATE_DEVICE_VERSION_MINOR);
  EXPECT_EQ(patch, PALPATE_DEVICE_VERSION_PATCH);
  palpate_device_version(nullptr, nullptr, nullptr);
  EXPECT_STREQ(palpate_device_status_name(PALPATE_DEVICE_OK), "ok");
  EXPECT_STREQ(palpate_device_status_name(PALPATE_DEVICE_NONE), "none");
  EXPECT_STREQ(palpate_device_status_name(PALPATE_DEVICE_E_ARGUMENT), "argument");
  EXPECT_STREQ(palpate_device_status_name(PALPATE_DEVICE_E_NO_PALPATED), "no palpated");
  EXPECT_STREQ(palpate_device_status_name(PALPATE_DEVICE_E_INTERNAL), "internal");
  EXPECT_STREQ(palpate_device_status_name(12345), "unknown status");
}

TEST(DeviceApi, OptionsHaveTheirDefaults) {
  palpate_device_options o;
  std::memset(&o, 0xff, sizeof o);
  palpate_device_options_init(&o);
  EXPECT_EQ(o.struct_size, sizeof o);
  EXPECT_EQ(o.model_id, nullptr);
  EXPECT_EQ(o.tool_id, nullptr);
  EXPECT_EQ(o.dds_config, nullptr);
  EXPECT_EQ(o.domain_id, 0u);
  EXPECT_EQ(o.pose_rate_hz, 1000);
  EXPECT_EQ(o.local_model, 1);
  EXPECT_EQ(o.passivity, 1);
  EXPECT_EQ(o.max_damping_n_s_per_m, 50);
  EXPECT_EQ(o.hold_s, 0.05);
  EXPECT_EQ(o.ramp_s, 0.25);
  EXPECT_EQ(o.frame.scale, 1);
  EXPECT_EQ(o.frame.force_scale, 1);
  EXPECT_EQ(o.frame.rotation_wxyz[0], 1);
  EXPECT_EQ(o.frame.rotation_wxyz[3], 0);
  EXPECT_EQ(o.frame.handle_to_tool_wxyz[0], 1);
  EXPECT_EQ(o.frame.offset_m[2], 0);
  palpate_device_options_init(nullptr);  // no crash
}

/// open() with @p o: its status, and the message it wrote.
std::pair<int, std::string> open_with(const palpate_device_options* o) {
  char error[kErrorSize] = "unchanged";
  palpate_device* tool = reinterpret_cast<palpate_device*>(0x1);  // must become NULL
  const int status = palpate_device_open(o, &tool, error, sizeof error);
  EXPECT_EQ(tool, status == PALPATE_DEVICE_OK ? tool : nullptr);
  if (status == PALPATE_DEVICE_OK) palpate_device_close(tool);
  return {status, error};
}

TEST(DeviceApi, OpenRefusesBadOptionsWithTheirMessage) {
  char error[kErrorSize];
  EXPECT_EQ(palpate_device_open(nullptr, nullptr, error, sizeof error), PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_STREQ(error, "palpate_device_open: tool is NULL");
  EXPECT_EQ(open_with(nullptr),
            std::make_pair(int{PALPATE_DEVICE_E_ARGUMENT},
                           std::string("palpate_device_open: options is NULL")));

  palpate_device_options o = options_for("box", "left");
  o.struct_size = 8;  // an options struct not filled by palpate_device_options_init()
  auto [status, message] = open_with(&o);
  EXPECT_EQ(status, PALPATE_DEVICE_E_VERSION);
  EXPECT_NE(message.find("options->struct_size 8: expected at least"), std::string::npos)
      << message;

  struct Case {
    void (*change)(palpate_device_options&);
    const char* expected;
  };
  const Case cases[] = {
      {[](palpate_device_options& x) { x.model_id = nullptr; }, "options->model_id is NULL"},
      {[](palpate_device_options& x) { x.tool_id = nullptr; }, "options->tool_id is NULL"},
      {[](palpate_device_options& x) { x.tool_id = "left hand"; },
       "tool id 'left hand': expected 1 to 63 characters among A-Z a-z 0-9 _ - ."},
      {[](palpate_device_options& x) { x.tool_id = ""; }, "tool id '': expected 1 to 63"},
      {[](palpate_device_options& x) { x.model_id = kLongId; }, "model id 'a123456789b"},
      {[](palpate_device_options& x) { x.pose_rate_hz = 0; },
       "options->pose_rate_hz = 0: expected 1 to 20000"},
      {[](palpate_device_options& x) { x.pose_rate_hz = std::nan(""); },
       "options->pose_rate_hz = nan"},
      {[](palpate_device_options& x) { x.timeout_s = -1; }, "options->timeout_s = -1"},
      {[](palpate_device_options& x) { x.max_damping_n_s_per_m = -5; },
       "options->max_damping_n_s_per_m = -5"},
      {[](palpate_device_options& x) { x.frame.scale = 0; }, "options->frame.scale = 0"},
      {[](palpate_device_options& x) { x.frame.force_scale = INFINITY; },
       "options->frame.force_scale = inf"},
      {[](palpate_device_options& x) { x.frame.rotation_wxyz[0] = 0; },
       "options->frame.rotation_wxyz is not a rotation"},
      {[](palpate_device_options& x) { x.frame.handle_to_tool_wxyz[2] = std::nan(""); },
       "options->frame.handle_to_tool_wxyz is not a rotation"},
      {[](palpate_device_options& x) { x.frame.offset_m[1] = INFINITY; },
       "options->frame.offset_m is not finite"},
  };
  for (const Case& c : cases) {
    palpate_device_options bad = options_for("box", "left");
    c.change(bad);
    const auto [s, m] = open_with(&bad);
    EXPECT_EQ(s, PALPATE_DEVICE_E_ARGUMENT) << m;
    EXPECT_NE(m.find(c.expected), std::string::npos) << m;
  }
}

TEST(DeviceApi, EveryCallRefusesANullHandle) {
  char error[kErrorSize];
  const double p[3] = {0, 0, 0}, q[4] = {1, 0, 0, 0};
  double f[3], t[3];
  std::uint64_t sent = 7;
  EXPECT_EQ(palpate_device_set_pose(nullptr, 0, p, q, 0, &sent, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_STREQ(error, "palpate_device_set_pose: tool is NULL");
  EXPECT_EQ(sent, 0u);
  EXPECT_EQ(palpate_device_force(nullptr, 0, f, t, error, sizeof error), PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_STREQ(error, "palpate_device_force: tool is NULL");
  palpate_device_state state;
  state.struct_size = sizeof state;
  EXPECT_EQ(palpate_device_get_state(nullptr, &state, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  palpate_device_event event;
  event.struct_size = sizeof event;
  EXPECT_EQ(palpate_device_next_event(nullptr, &event, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  palpate_device_answer answer;
  answer.struct_size = sizeof answer;
  EXPECT_EQ(palpate_device_next_answer(nullptr, &answer, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_EQ(palpate_device_wait(nullptr, 0, error, sizeof error), PALPATE_DEVICE_E_ARGUMENT);
  palpate_device_model model;
  model.struct_size = sizeof model;
  EXPECT_EQ(palpate_device_get_model(nullptr, &model, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_EQ(palpate_device_end_session(nullptr, 1, error, sizeof error), PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_STREQ(error, "palpate_device_end_session: tool is NULL");
  palpate_device_close(nullptr);  // no crash
  // No buffer, or a short one: the status still says it; the message is cut
  // and NUL-terminated.
  EXPECT_EQ(palpate_device_force(nullptr, 0, f, t, nullptr, 0), PALPATE_DEVICE_E_ARGUMENT);
  char tiny[8];
  std::memset(tiny, 'x', sizeof tiny);
  EXPECT_EQ(palpate_device_force(nullptr, 0, f, t, tiny, sizeof tiny), PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_STREQ(tiny, "palpate");
}

TEST(DeviceApi, NoPalpatedIsSaidAsSuch) {
  palpate_device_options o = options_for("box", "left");
  o.domain_id = 17;  // no palpated there
  o.timeout_s = 0.3;
  const auto [status, message] = open_with(&o);
  EXPECT_EQ(status, PALPATE_DEVICE_E_NO_PALPATED) << message;
  EXPECT_NE(message.find("no palpated within 0.3 s: no model description on DDS domain 17"),
            std::string::npos)
      << message;
  o.dds_config = "/nonexistent/cyclonedds.xml";
  const auto [config_status, config_message] = open_with(&o);
  EXPECT_EQ(config_status, PALPATE_DEVICE_E_CONFIG) << config_message;
  EXPECT_NE(config_message.find("'/nonexistent/cyclonedds.xml' cannot be read"), std::string::npos)
      << config_message;
}

// ---------------------------------------------------------------------------
// With palpated: the box model, its default tools (left and right graspers).

class DeviceSession : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    box_ = write_box_compliance(dir_->path(), "box", 8, 85e3);
    std::ofstream(dir_->path() / "palpated.toml")
        << "[daemon]\nid = \"device-daemon\"\nlog_level = \"info\"\n"
           "[[model]]\nid = \"box\"\nfile = \"box.h5\"\n";
    daemon_ = new Daemon({"--config", (dir_->path() / "palpated.toml").string()},
                         dir_->path() / "palpated.log");
  }
  static void TearDownTestSuite() {
    EXPECT_EQ(daemon_->stop(SIGTERM), 0) << daemon_->log();
    if (::testing::Test::HasFailure()) std::fprintf(stderr, "%s", daemon_->log().c_str());
    delete daemon_;
    delete dir_;
  }

  /// Opens @p tool on the box, or fails the test.
  static palpate_device* open(const char* tool) {
    palpate_device_options o = options_for("box", tool);
    char error[kErrorSize];
    palpate_device* handle = nullptr;
    EXPECT_EQ(palpate_device_open(&o, &handle, error, sizeof error), PALPATE_DEVICE_OK)
        << error << daemon_->log();
    return handle;
  }

  /// Waits up to @p timeout for an event of @p kind; counts the others seen.
  static bool wait_event(palpate_device* tool, int kind, std::chrono::milliseconds timeout,
                         palpate_device_event* got = nullptr) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < until) {
      palpate_device_event e;
      e.struct_size = sizeof e;
      const int status = palpate_device_next_event(tool, &e, nullptr, 0);
      if (status == PALPATE_DEVICE_OK && e.kind == kind) {
        if (got) *got = e;
        return true;
      }
      if (status == PALPATE_DEVICE_NONE) std::this_thread::sleep_for(2ms);
    }
    return false;
  }

  inline static TempDir* dir_ = nullptr;
  inline static std::filesystem::path box_;
  inline static Daemon* daemon_ = nullptr;
};

TEST_F(DeviceSession, AModelPalpatedDoesNotServeIsNamedWithThoseItDoes) {
  palpate_device_options o = options_for("liver", "left");
  const auto [status, message] = open_with(&o);
  EXPECT_EQ(status, PALPATE_DEVICE_E_NO_MODEL) << message;
  EXPECT_NE(message.find("model 'liver' is not served by palpated; served: box"), std::string::npos)
      << message;
}

TEST_F(DeviceSession, OpenPosesRenderEventsAndEnd) {
  palpate_device* tool = open("left");
  ASSERT_NE(tool, nullptr);
  char error[kErrorSize];

  palpate_device_model model;
  model.struct_size = sizeof model;
  ASSERT_EQ(palpate_device_get_model(tool, &model, error, sizeof error), PALPATE_DEVICE_OK);
  EXPECT_STREQ(model.model_id, "box");
  EXPECT_STREQ(model.mechanics, "linear");
  ASSERT_GT(model.compliance_vertex_count, 0u);
  ASSERT_GT(model.vertex_count, model.compliance_vertex_count);  // the clamp's vertices
  ASSERT_GT(model.triangle_count, 0u);
  const std::span<const double> rest(model.rest_positions_m, 3 * std::size_t{model.vertex_count});
  const int vertex = box_top_vertex(rest, static_cast<int>(model.compliance_vertex_count), 75, 25);
  ASSERT_GE(vertex, 0);
  const Eigen::Vector3d top(&model.rest_positions_m[3 * vertex]);

  // A bad pose never reaches palpated: its status and message.
  const double nan_position[3] = {0, std::nan(""), 0}, zero_q[4] = {0, 0, 0, 0};
  const double q[4] = {0, 1, 0, 0};  // tool +z along the model's -z: pointing down
  EXPECT_EQ(palpate_device_set_pose(tool, 0, nan_position, q, 0, nullptr, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_NE(std::string(error).find("is not finite"), std::string::npos) << error;
  EXPECT_EQ(palpate_device_set_pose(tool, 0, top.data(), zero_q, 0, nullptr, error, sizeof error),
            PALPATE_DEVICE_E_ARGUMENT);
  EXPECT_NE(std::string(error).find("is not a rotation"), std::string::npos) << error;
  double f[3] = {9, 9, 9}, t[3] = {9, 9, 9};
  EXPECT_EQ(palpate_device_force(tool, 0, f, t, error, sizeof error), PALPATE_DEVICE_OK);
  EXPECT_EQ(Eigen::Vector3d(f).norm(), 0.0) << "no pose yet, nothing rendered";

  // The servo loop: 4 kHz on the device's own (scheduled) clock; the hinge
  // comes down from 25 mm above the top face to 3 mm into it (the capsule's
  // end is 19 mm below the hinge), holds, and goes back up.
  constexpr int kRate = 4000;
  constexpr std::int64_t kStepNs = 1'000'000'000 / kRate;
  const double reach = 0.019;
  auto hinge_at = [&](double depth_m) -> Eigen::Vector3d {
    return top + Eigen::Vector3d(0, 0, reach - depth_m);
  };
  std::int64_t now = palpate_device_now_ns() + 2'000'000;
  std::int64_t free_since = -1;  // since when palpated's answers say the tool is free
  int steps = 0, sent_poses = 0, free_steps = 0;
  double free_max = 0, held_z = 0, held_answer_z = 0, max_z = 0;
  double free_damping = 0;
  Eigen::Vector3d posed = hinge_at(-0.006);  // the pose given at the step before
  std::uint64_t first = 0, last = 0;
  std::uint64_t allocations_in_loop = 0;
  auto step = [&](double depth_m) {
    std::this_thread::sleep_until(
        std::chrono::steady_clock::time_point(std::chrono::nanoseconds(now)));
    const Eigen::Vector3d h = hinge_at(depth_m);
    std::uint64_t sent = 0;
    const std::uint64_t before = allocations();
    ASSERT_EQ(palpate_device_set_pose(tool, now, h.data(), q, 0, &sent, error, sizeof error),
              PALPATE_DEVICE_OK)
        << error;
    ASSERT_EQ(palpate_device_force(tool, now, f, t, error, sizeof error), PALPATE_DEVICE_OK)
        << error;
    allocations_in_loop += allocations() - before;
    if (sent != 0) {
      ++sent_poses;
      if (first == 0) first = sent;
      EXPECT_EQ(sent, last == 0 ? first : last + 1) << "sequences increase by one";
      last = sent;
    }
    max_z = std::max(max_z, f[2]);
    // Free: 5 mm above the surface, and answered free for 20 ms (a touch's
    // force, slew limited at 500 N/s, is gone by then): nothing rendered,
    // however late the answers, but the passivity controller's damping
    // −α v (v of the poses given) that pays back a debt the touch left.
    palpate_device_state s;
    s.struct_size = sizeof s;
    ASSERT_EQ(palpate_device_get_state(tool, &s, error, sizeof error), PALPATE_DEVICE_OK);
    const Eigen::Vector3d velocity = (h - posed) / (kStepNs * 1e-9);
    posed = h;
    if (!s.has_answer || s.tool_state != PALPATE_DEVICE_FREE)
      free_since = -1;
    else if (free_since < 0)
      free_since = now;
    if (depth_m <= -0.005 && free_since >= 0 && now - free_since >= 20'000'000) {
      const Eigen::Vector3d damping = -s.damping_n_s_per_m * velocity;
      ++free_steps;
      free_max = std::max(free_max, (Eigen::Vector3d(f) - damping).norm());
      free_damping = std::max(free_damping, damping.norm());
    }
    now += kStepNs;
    ++steps;
  };
  for (int i = 0; i < kRate / 10; ++i) step(-0.006);  // 0.1 s free, 6 mm above
  for (int i = 1; i <= kRate / 5; ++i) step(-0.006 + 0.009 * i / (kRate / 5));  // down in 0.2 s
  for (int i = 0; i < kRate / 5; ++i) step(0.003);                              // hold 0.2 s
  palpate_device_state state;
  state.struct_size = sizeof state;
  ASSERT_EQ(palpate_device_get_state(tool, &state, error, sizeof error), PALPATE_DEVICE_OK);
  held_z = f[2];
  held_answer_z = state.answer_force_n[2];
  EXPECT_EQ(state.tool_state, PALPATE_DEVICE_TOUCHING);
  EXPECT_GT(state.contacts, 0u);
  EXPECT_NE(state.daemon, PALPATE_DEVICE_DAEMON_LOST) << "its heartbeat comes at 1 Hz";
  EXPECT_GT(state.round_trip_s, 0.0);
  EXPECT_EQ(state.rendered_force_n[2], f[2]);
  EXPECT_GE(state.energy_j, 0.0) << "passive";
  for (int i = 1; i <= kRate / 5; ++i) step(0.003 - 0.009 * i / (kRate / 5));  // up in 0.2 s
  for (int i = 0; i < kRate / 10; ++i) step(-0.006);                           // away 0.1 s

  // Poses at 1 kHz of a 4 kHz loop, on its own clock: one every four steps.
  EXPECT_EQ(sent_poses, (steps + 3) / 4);
  EXPECT_EQ(allocations_in_loop, 0u) << "set_pose and force allocate nothing";
  // Free: nothing. Pressed 3 mm into the top face: the organ pushes the tool
  // up, and the local model at the held pose renders palpated's own answer
  // (the pose has not moved since it was answered; 1 mN + 1 % for the
  // answer of a pose a step older).
  EXPECT_GT(free_steps, 0);
  // (The damping's velocity is the renderer's to round-off of the clock's
  // seconds: 1e-5 of it.)
  EXPECT_LE(free_max, 1e-9 + 1e-5 * free_damping) << "free, before the touch and after the leave";
  EXPECT_GT(held_z, 0.05) << "3 mm into an 85 kPa box";
  EXPECT_LT(max_z, 8.0 + 1e-9) << "the default tool's force limit";
  EXPECT_NEAR(held_z, held_answer_z, 1e-3 + 0.01 * std::abs(held_answer_z));

  // Every answer the handle took, in the log: sequences it sent. The log
  // keeps the last 256; answers still coming in while it is read join it.
  ASSERT_EQ(palpate_device_get_state(tool, &state, error, sizeof error), PALPATE_DEVICE_OK);
  const std::uint64_t taken_before = state.answers_taken;
  int answers = 0;
  palpate_device_answer a;
  a.struct_size = sizeof a;
  while (palpate_device_next_answer(tool, &a, error, sizeof error) == PALPATE_DEVICE_OK) {
    ++answers;
    EXPECT_GE(a.sequence, first);
    EXPECT_LE(a.sequence, last);
    EXPECT_GE(a.receive_time_ns, a.send_time_ns);
  }
  EXPECT_GT(answers, 0);
  ASSERT_EQ(palpate_device_get_state(tool, &state, error, sizeof error), PALPATE_DEVICE_OK);
  EXPECT_LE(static_cast<std::uint64_t>(answers), 256 + (state.answers_taken - taken_before))
      << "the log keeps the last 256";
  EXPECT_EQ(state.poses_sent, static_cast<std::uint64_t>(sent_poses));
  EXPECT_EQ(state.first_sequence, first);
  EXPECT_EQ(state.last_sequence, last);
  EXPECT_GE(state.answers_taken, static_cast<std::uint64_t>(answers));

  // The events of the press (reliable): a touch, then a leave.
  palpate_device_event e;
  ASSERT_TRUE(wait_event(tool, PALPATE_DEVICE_EVENT_TOUCH, 3s, &e)) << daemon_->log();
  EXPECT_STREQ(e.message, "touch");
  EXPECT_GE(e.pose_sequence, first);
  EXPECT_TRUE(wait_event(tool, PALPATE_DEVICE_EVENT_LEAVE, 3s)) << daemon_->log();

  // The end: acknowledged, and an ENDED event.
  EXPECT_EQ(palpate_device_end_session(tool, 2.0, error, sizeof error), PALPATE_DEVICE_OK) << error;
  EXPECT_TRUE(wait_event(tool, PALPATE_DEVICE_EVENT_ENDED, 3s, &e)) << daemon_->log();
  EXPECT_GE(e.pose_sequence, first);
  EXPECT_LE(e.pose_sequence, last);
  EXPECT_EQ(palpate_device_end_session(tool, 2.0, error, sizeof error), PALPATE_DEVICE_OK)
      << "nothing to end twice";

  // A pose palpated refuses (jaws beyond the tool's 75°): the reason, as an event.
  const Eigen::Vector3d above = hinge_at(-0.01);
  std::uint64_t refused = 0;
  ASSERT_EQ(palpate_device_set_pose(tool, 0, above.data(), q, std::numbers::pi / 2, &refused, error,
                                    sizeof error),
            PALPATE_DEVICE_OK);
  EXPECT_EQ(refused, last + 1);
  ASSERT_TRUE(wait_event(tool, PALPATE_DEVICE_EVENT_REFUSED, 3s, &e)) << daemon_->log();
  EXPECT_EQ(e.pose_sequence, refused);
  EXPECT_NE(std::string(e.message).find("jaw angle 90° of tool 'left' is over its limit"),
            std::string::npos)
      << e.message;
  palpate_device_close(tool);
}

TEST_F(DeviceSession, WaitReturnsWhenTheNewestPoseIsAnswered) {
  palpate_device* tool = open("right");
  ASSERT_NE(tool, nullptr);
  char error[kErrorSize];
  // Before any pose: nothing to wait for, until the deadline.
  EXPECT_EQ(palpate_device_wait(tool, palpate_device_now_ns() + 1'000'000, error, sizeof error),
            PALPATE_DEVICE_NONE);
  const double p[3] = {0.05, 0.025, 0.08}, q[4] = {0, 1, 0, 0};  // above the box
  int answered = 0;
  for (int i = 0; i < 20; ++i) {
    std::uint64_t sent = 0;
    ASSERT_EQ(palpate_device_set_pose(tool, 0, p, q, 0, &sent, error, sizeof error),
              PALPATE_DEVICE_OK);
    if (palpate_device_wait(tool, palpate_device_now_ns() + 1'000'000'000, error, sizeof error) ==
        PALPATE_DEVICE_OK) {
      ++answered;
      palpate_device_state s;
      s.struct_size = sizeof s;
      ASSERT_EQ(palpate_device_get_state(tool, &s, error, sizeof error), PALPATE_DEVICE_OK);
      EXPECT_GE(s.answer_sequence, sent) << "OK means the newest pose is answered";
    }
    std::this_thread::sleep_for(1ms);  // at most the pose rate
  }
  // Best effort: a pose may be lost, but not most of them on loopback.
  EXPECT_GT(answered, 10);
  palpate_device_close(tool);
}

// ---------------------------------------------------------------------------
// The C example: a simulated device's hand pressing the box at 4 kHz.

std::map<std::string, double> result_of(const std::string& output) {
  std::map<std::string, double> values;
  const auto at = output.rfind("\nresult ");
  if (at == std::string::npos) return values;
  std::istringstream line(output.substr(at + 8, output.find('\n', at + 1) - at - 8));
  for (std::string pair; line >> pair;)
    if (const auto eq = pair.find('='); eq != std::string::npos)
      values[pair.substr(0, eq)] = std::stod(pair.substr(eq + 1));
  return values;
}

TEST_F(DeviceSession, TheSimulatedDeviceFeelsThePress) {
  // Press the middle of the top face, not a corner (the example's own
  // anchor, the freest vertex, is a corner of the free end on a box).
  palpate_device* tool = open("right");
  ASSERT_NE(tool, nullptr);
  palpate_device_model model;
  model.struct_size = sizeof model;
  ASSERT_EQ(palpate_device_get_model(tool, &model, nullptr, 0), PALPATE_DEVICE_OK);
  const int vertex = box_top_vertex(
      std::span<const double>(model.rest_positions_m, 3 * std::size_t{model.vertex_count}),
      static_cast<int>(model.compliance_vertex_count), 75, 25);
  ASSERT_GE(vertex, 0);
  const std::uint32_t mesh_vertex = model.vertex_ids[vertex];
  palpate_device_close(tool);

  ChildProcess device(SIMULATED_DEVICE_PATH,
                      {"box", "left", "--vertex", std::to_string(mesh_vertex)},
                      dir_->path() / "simulated_device.out");
  const int code = device.wait(60s);
  const std::string out = device.output();
  ASSERT_EQ(code, 0) << out << daemon_->log();
  std::printf("%s", out.c_str());  // what the device felt, in the test's log
  const auto r = result_of(out);
  ASSERT_FALSE(r.empty()) << out;
  // 2.4 s of script at 4 kHz, poses at 1 kHz on its own clock.
  EXPECT_EQ(r.at("steps"), 9600) << out;
  EXPECT_EQ(r.at("poses"), 2400) << out;
  EXPECT_GT(r.at("answers"), 0) << out;
  // Free, the tip 5 mm or more outside the surface and answered so for
  // 20 ms: nothing at all.
  EXPECT_GT(r.at("free_steps"), 0) << out;
  // Nothing but the passivity controller's damping (1e-5 of it: the
  // example's velocity is the renderer's to round-off of the clock).
  EXPECT_LE(r.at("free_max_n"), 2e-9 + 1e-5 * r.at("free_damping_max_n")) << out;
  // Held 6 mm deep by the hand's 300 N/m spring: the organ pushes the
  // handle back out, by some tenths of a newton, within the tool's limit.
  EXPECT_GT(r.at("hold_force_n"), 0.1) << out;
  EXPECT_LT(r.at("max_force_n"), 8.0 + 1e-9) << out;
  // Settled (a 0.1 kg handle on 300 N/m and the organ, damped: settled in
  // well under the 0.4 s averaged), the device's force is the hand's push
  // (5 % + 10 mN) and palpated's answer at that pose (5 % + 10 mN: the hand
  // still creeps as the organ creeps under its step of the hold).
  EXPECT_NEAR(r.at("hold_force_n"), r.at("hold_spring_n"), 0.01 + 0.05 * r.at("hold_spring_n"))
      << out;
  EXPECT_NEAR(r.at("hold_force_n"), r.at("hold_answer_n"), 0.01 + 0.05 * r.at("hold_answer_n"))
      << out;
  // A touch, a leave, and the end it asked for.
  EXPECT_GE(r.at("touch"), 1) << out;
  EXPECT_GE(r.at("leave"), 1) << out;
  EXPECT_EQ(r.at("ended"), 1) << out;
  EXPECT_EQ(r.at("refused"), 0) << out;
}

}  // namespace
}  // namespace palpate::testing
