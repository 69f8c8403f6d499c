// Faults end to end (docs/faults.md): the real palpated, palpate-pliers and
// palpate-client as processes, killed with SIGKILL, over real Cyclone DDS on
// loopback (CTest runs this binary in a private network namespace).
//
// Times asserted here are liveness bounds, far above what is expected (a
// heartbeat silence of 1.3 s is expected to be noticed within about 1.5 s;
// the bound is 10 s): they say "it happens", not "it happens fast".

#include <gtest/gtest.h>
#include <hdf5.h>

#include <Eigen/Dense>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "palpate/file/compliance_file.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/tool_client.hpp"
#include "support/box_job.hpp"
#include "support/child_process.hpp"
#include "support/daemon_process.hpp"
#include "support/test_meshes.hpp"
#include "support/time_scale.hpp"

namespace palpate {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using Eigen::Vector3d;
using testing::ChildProcess;
using testing::Daemon;
using testing::TempDir;

// Poses at 1 kHz; slower under a sanitizer (1 kHz / PALPATE_TEST_TIME_SCALE),
// where two instrumented tools at 1 kHz saturate two cores and what the
// tests then measure is the machine's throughput (docs/sanitizers.md).
const Clock::duration kPosePeriod =
    std::chrono::duration_cast<Clock::duration>(1ms * testing::time_scale());
const std::string kPliersRate = std::to_string(1000.0 / testing::time_scale());
constexpr auto kLiveness = 10s;  // bound for "it happens" (expected: about a second)
const std::array<double, 4> kPointingDown{0, 1, 0, 0};  // tool +z along the model's −z
constexpr double kReach = 0.019;  // default tool: hinge to the capsule's distal end, m

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

/// The box model's geometry as a client sees it.
struct Box {
  ModelInfo info;
  std::map<std::uint32_t, Vector3d> rest;  // by mesh vertex id
  int drawn(double x_mm, double y_mm) const {
    return testing::box_top_vertex(info.surface.rest_positions_m,
                                   info.surface.compliance_vertex_count, x_mm, y_mm);
  }
  std::uint32_t id(int drawn_index) const {
    return info.surface.vertex_ids[static_cast<std::size_t>(drawn_index)];
  }
  Vector3d at(int drawn_index) const { return rest.at(id(drawn_index)); }
};

Box describe(Client& client, const std::string& model) {
  auto info = client.wait_for_model(model, kLiveness);
  if (!info) throw std::runtime_error("no model description");
  Box box{*info, {}};
  for (std::size_t i = 0; i < info->surface.vertex_ids.size(); ++i)
    box.rest[info->surface.vertex_ids[i]] = Vector3d(&info->surface.rest_positions_m[3 * i]);
  return box;
}

/// A gesture file that brings the left tool down at @p anchor @p depth_mm
/// under the rest surface in 0.3 s and holds it there for two minutes.
std::filesystem::path write_hold_gesture(const TempDir& dir, std::uint32_t anchor,
                                         double depth_mm = 4) {
  const auto path = dir / "hold.toml";
  std::ofstream(path) << "name = \"hold\"\nanchor = " << anchor
                      << "\n[[tool]]\nid = \"left\"\n"
                         "[[tool.keyframe]]\nt = 0.0\nposition = [0, 0, 10]\n"
                         "[[tool.keyframe]]\nt = 0.3\nposition = [0, 0, "
                      << -depth_mm
                      << "]\n"
                         "[[tool.keyframe]]\nt = 120.0\n";
  return path;
}

/// A tool driven at 1 kHz on its own thread by an in-process ToolClient:
/// down to 4 mm under the rest surface at @p where, then held; every
/// feedback and event kept with its arrival time.
class Hand {
 public:
  struct Feedback {
    Clock::time_point at;
    Vector3d force;
    ToolState state;
    bool watchdog;
  };

  /// Drives @p tool; also reads the events of the tools in @p watched (a
  /// station sees its own tools' events only, unless it opens others').
  Hand(std::string tool, std::string model, const Vector3d& where,
       std::vector<std::string> watched = {})
      : tool_(std::move(tool)),
        model_(std::move(model)),
        where_(where),
        watched_(std::move(watched)) {
    thread_ = std::thread([this] { run(); });
  }
  ~Hand() { stop(); }
  void stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }

  std::vector<Feedback> feedback() const {
    const std::lock_guard lock(mutex_);
    return feedback_;
  }
  std::vector<ToolEventSample> events() const {
    const std::lock_guard lock(mutex_);
    return events_;
  }
  std::uint64_t poses() const { return poses_; }
  /// Mean force of the @p count feedback samples that arrived first at or
  /// after @p from (fewer if fewer came): a window of samples, not of time,
  /// so that a slow build (ASan) that answers a few poses a second still
  /// has one.
  Vector3d mean_force_after(Clock::time_point from, int count) const {
    Vector3d sum = Vector3d::Zero();
    int n = 0;
    for (const auto& f : feedback())
      if (f.at >= from && n < count) {
        sum += f.force;
        ++n;
      }
    return n > 0 ? Vector3d(sum / n) : Vector3d::Constant(std::nan(""));
  }
  /// Mean force of the last @p count feedback samples.
  Vector3d mean_force_last(int count) const {
    const auto all = feedback();
    Vector3d sum = Vector3d::Zero();
    int n = 0;
    for (auto it = all.rbegin(); it != all.rend() && n < count; ++it, ++n) sum += it->force;
    return n > 0 ? Vector3d(sum / n) : Vector3d::Constant(std::nan(""));
  }
  bool touching_since(Clock::duration d) const {
    const auto all = feedback();
    if (all.empty() || Clock::now() - all.front().at < d) return false;
    for (auto it = all.rbegin(); it != all.rend() && Clock::now() - it->at < d; ++it)
      if (it->state != ToolState::kTouching) return false;
    return all.back().state == ToolState::kTouching;
  }

 private:
  void run() {
    ToolClient client(ToolClientOptions{});
    client.open_tool(tool_);
    for (const auto& other : watched_) client.open_tool(other);
    if (!client.wait_for_model(model_, kLiveness) || !client.wait_for_daemon(kLiveness)) return;
    std::uint64_t sequence = static_cast<std::uint64_t>(ToolClient::now_ns() / 1000);
    const auto start = Clock::now();
    auto tick = start;
    while (running_) {
      // 10 mm above to 4 mm deep in 0.3 s, then held.
      const double s = std::min(1.0, seconds(Clock::now() - start) / 0.3);
      const Vector3d hinge = where_ + Vector3d(0, 0, kReach + 0.010 - s * 0.014);
      client.send_pose(tool_, model_, ++sequence, {hinge.x(), hinge.y(), hinge.z()}, kPointingDown,
                       0);
      ++poses_;
      tick += kPosePeriod;
      const auto f = client.wait_feedback(tool_, sequence, tick);
      auto events = client.take_events();
      {
        const std::lock_guard lock(mutex_);
        if (f)
          feedback_.push_back({Clock::now(), Vector3d(f->force_n.data()), f->state, f->watchdog});
        for (auto& e : events) events_.push_back(std::move(e));
      }
      std::this_thread::sleep_until(tick);
    }
  }

  std::string tool_, model_;
  Vector3d where_;
  std::vector<std::string> watched_;
  std::atomic<bool> running_{true};
  std::atomic<std::uint64_t> poses_{0};
  mutable std::mutex mutex_;
  std::vector<Feedback> feedback_;
  std::vector<ToolEventSample> events_;
  std::thread thread_;
};

/// Every surface sample of a model, with its arrival time, on its own thread.
class SurfaceWatch {
 public:
  struct Sample {
    Clock::time_point at;
    std::vector<std::uint32_t> vertices;
    std::vector<double> forces;
  };
  explicit SurfaceWatch(std::string model) : model_(std::move(model)) {
    thread_ = std::thread([this] {
      Client client(ClientOptions{"faults-surface-watch", 0, "", true, false});
      std::uint64_t next = 0;
      while (running_) {
        if (const auto s = client.wait_surface(model_, next, 0, 50ms)) {
          next = s->sequence_number + 1;
          const std::lock_guard lock(mutex_);
          samples_.push_back({Clock::now(), s->constrained_vertices, s->constrained_forces_n});
        }
      }
    });
  }
  ~SurfaceWatch() {
    running_ = false;
    thread_.join();
  }
  std::vector<Sample> samples() const {
    const std::lock_guard lock(mutex_);
    return samples_;
  }

 private:
  std::string model_;
  std::atomic<bool> running_{true};
  mutable std::mutex mutex_;
  std::vector<Sample> samples_;
  std::thread thread_;
};

/// The force on the vertices of a surface sample nearer to @p a than to @p b.
Vector3d force_near(const SurfaceWatch::Sample& s, const Box& box, const Vector3d& a,
                    const Vector3d& b, int* count = nullptr) {
  Vector3d sum = Vector3d::Zero();
  int n = 0;
  for (std::size_t c = 0; c < s.vertices.size(); ++c) {
    const Vector3d x = box.rest.at(s.vertices[c]);
    if ((x - a).norm() < (x - b).norm()) {
      sum += Vector3d(&s.forces[3 * c]);
      ++n;
    }
  }
  if (count) *count = n;
  return sum;
}

void write_config(const std::filesystem::path& file, const std::string& extra = "") {
  std::ofstream(file) << "[daemon]\nid = \"faults\"\nlog_level = \"info\"\n"
                         "[rates]\nstatus_hz = 10\nsurface_hz = 60\n"
                         "[[model]]\nid = \"box\"\nfile = \"box.h5\"\n"
                         "[contact]\nwatchdog_timeout_ms = 50\nwatchdog_ramp_ms = 300\n"
                      << extra;
}

// ---------------------------------------------------------------------------
// A client killed mid-session: its tool's contacts go after the watchdog
// (timeout, then the ramp), the other tool is served all along.

TEST(Faults, AClientKilledMidSessionLetsGoOfItsToolAfterTheWatchdogAndTheOtherToolGoesOn) {
  TempDir dir;
  testing::write_box_compliance(dir.path(), "box", 8, 85e3);
  // Frictionless tools: the right tool's force then depends on where it is,
  // not on how its contacts stuck while the left one pressed (with friction
  // its normal force after the release differed by up to 7 %).
  write_config(dir / "palpated.toml",
               "[[tools]]\nid = \"left\"\nfriction = 0\n[[tools]]\nid = \"right\"\nfriction = 0\n");
  Daemon daemon({"--config", (dir / "palpated.toml").string()}, dir / "palpated.log");
  SurfaceWatch surface("box");
  Client viewer(ClientOptions{"faults-viewer", 0, "", false, false});
  const Box box = describe(viewer, "box");
  // The box is clamped at x = 0: the right tool presses near the clamp, so
  // that the free end, where the left one presses deeper, does not sink away
  // from it (a cantilever's end moves more than where it is pushed).
  const int left_vertex = box.drawn(75, 25), right_vertex = box.drawn(25, 25);
  const Vector3d left_at = box.at(left_vertex), right_at = box.at(right_vertex);

  // The right hand alone, then the left one (palpate-pliers) too.
  Hand right("right", "box", right_at, {"left"});  // watches the left tool's events
  for (const auto until = Clock::now() + kLiveness; !right.touching_since(500ms);) {
    ASSERT_LT(Clock::now(), until) << daemon.log();
    std::this_thread::sleep_for(20ms);
  }
  const Vector3d alone = right.mean_force_last(20);
  ASSERT_GT(alone.z(), 0.1) << "the organ pushes the right tool up";

  ChildProcess pliers(PLIERS_PATH,
                      {write_hold_gesture(dir, box.id(left_vertex), 8).string(), "--model", "box",
                       "--timeout", "20", "--rate", kPliersRate},
                      dir / "pliers.out");
  if (!pliers.wait_for_output("left   touch", Clock::now() + kLiveness)) {
    pliers.signal(SIGINT);
    pliers.wait(kLiveness);
    FAIL() << pliers.output() << daemon.log();
  }
  std::this_thread::sleep_for(700ms);  // down to 4 mm at 0.3 s, then held
  const auto before = surface.samples();
  ASSERT_FALSE(before.empty());
  int left_contacts = 0;
  const Vector3d left_force = force_near(before.back(), box, left_at, right_at, &left_contacts);
  ASSERT_GT(left_contacts, 0) << "the stream shows the left tool's contacts: " << before.size()
                              << " samples, the last " << seconds(Clock::now() - before.back().at)
                              << " s ago with " << before.back().vertices.size() << " vertices";
  ASSERT_GT(left_force.norm(), 0.1);

  pliers.signal(SIGKILL);
  const auto killed = Clock::now();
  ASSERT_EQ(pliers.wait(kLiveness), 128 + SIGKILL);

  // Its contacts are released: a surface sample without any near the left tool.
  // Watchdog timeout + ramp + margin; stretched under a sanitizer, where
  // two tools at 1 kHz keep palpated's cores busy (docs/sanitizers.md).
  const auto bound =
      std::chrono::duration_cast<Clock::duration>((50ms + 300ms + 3s) * testing::time_scale());
  Clock::time_point released{};
  while (released == Clock::time_point{} && Clock::now() < killed + bound) {
    for (const auto& s : surface.samples()) {
      int n = 0;
      force_near(s, box, left_at, right_at, &n);
      if (s.at > killed && n == 0) {
        released = s.at;
        break;
      }
    }
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_NE(released, Clock::time_point{})
      << "the left tool's contacts were not released within " << seconds(bound) << " s\n"
      << daemon.log();
  std::this_thread::sleep_for(500ms);
  right.stop();
  std::printf("contacts released %.3f s after the kill (watchdog 0.05 s + ramp 0.3 s)\n",
              seconds(released - killed));

  // Released by the watchdog's ramp, not dropped: some sample between the
  // kill and the release shows the left contacts' force on its way down.
  bool ramping = false;
  for (const auto& s : surface.samples())
    if (s.at > killed && s.at < released) {
      const double f = force_near(s, box, left_at, right_at).norm();
      ramping = ramping || (f > 0 && f < 0.9 * left_force.norm());
    }
  EXPECT_TRUE(ramping) << "the force of the left contacts ramps down";
  const auto events = right.events();
  EXPECT_TRUE(std::any_of(events.begin(), events.end(), [](const ToolEventSample& e) {
    return e.tool_id == "left" && e.kind == ToolEventKind::kWatchdog;
  })) << "a watchdog event for the killed client's tool";

  // The right tool was served all along: no silence, always touching, never
  // in the watchdog, and once alone again it feels what it felt alone.
  const auto feedback = right.feedback();
  Clock::time_point previous{};
  double largest_gap_s = 0;
  int in_window = 0;
  for (const auto& f : feedback) {
    if (f.at < killed - 200ms || f.at > released + 400ms) continue;
    if (previous != Clock::time_point{})
      largest_gap_s = std::max(largest_gap_s, seconds(f.at - previous));
    previous = f.at;
    ++in_window;
    EXPECT_EQ(f.state, ToolState::kTouching);
    EXPECT_FALSE(f.watchdog);
    EXPECT_TRUE(f.force.allFinite());
  }
  EXPECT_LT(largest_gap_s, 0.5) << "the right tool's feedback never stopped";
  // How many poses were answered in the window depends on the machine's
  // speed (under ASan, next to other tests: 0 to 467 of 1 kHz), so it is not
  // asserted: the gap bound above says it was served all along.
  EXPECT_GT(in_window, 0) << "its poses were answered";
  // Alone again, it is pushed back as hard as when it was alone (the normal
  // force).
  const Vector3d after = right.mean_force_after(released + 200ms, 20);
  std::printf("right tool's normal force: %.4f N alone, %.4f N alone again\n", alone.z(),
              after.z());
  EXPECT_NEAR(after.z(), alone.z(), 0.01 * alone.z())
      << "after " << after.transpose() << ", alone " << alone.transpose();
  EXPECT_EQ(daemon.stop(SIGTERM), 0) << daemon.log();
}

// ---------------------------------------------------------------------------
// palpated killed and restarted while clients run: they see it go and come
// back, and resume in the same processes.

TEST(Faults, ClientsSeeTheDaemonGoAndComeBackAndResumeWithoutRestarting) {
  TempDir dir;
  testing::write_box_compliance(dir.path(), "box", 8, 85e3);
  write_config(dir / "palpated.toml");
  const std::vector<std::string> args{"--config", (dir / "palpated.toml").string()};
  auto daemon = std::make_unique<Daemon>(args, dir / "palpated-1.log");

  // The request client in this process, asking the same question at 100 Hz.
  Client client(ClientOptions{"faults-requests", 0, "", false, false});
  const Box box = describe(client, "box");
  ASSERT_TRUE(client.wait_for_service(kLiveness)) << daemon->log();
  const std::vector<ConstraintSpec> press{
      ConstraintSpec::displacement(box.id(box.drawn(37.5, 25)), {0, 0, -0.002})};
  const Reply first = client.request("box", press);
  ASSERT_EQ(first.status, RequestStatus::kOk);
  struct Answer {
    Clock::time_point at;
    Reply reply;
  };
  std::mutex answers_mutex;
  std::vector<Answer> answers;
  std::vector<std::pair<Clock::time_point, DaemonState>> states;
  std::atomic<bool> asking{true};
  std::thread asker([&] {
    while (asking) {
      const auto reply = client.wait_reply(client.send("box", press), 300ms);
      const DaemonState state = client.daemon_presence().state;
      const std::lock_guard lock(answers_mutex);
      if (reply) answers.push_back({Clock::now(), *reply});
      if (states.empty() || states.back().second != state) states.emplace_back(Clock::now(), state);
      std::this_thread::sleep_for(10ms);
    }
  });
  auto answered_after = [&](Clock::time_point t) {
    const std::lock_guard lock(answers_mutex);
    return std::count_if(answers.begin(), answers.end(), [&](const Answer& a) { return a.at > t; });
  };
  auto state_after = [&](Clock::time_point t, DaemonState wanted) {
    const std::lock_guard lock(answers_mutex);
    return std::any_of(states.begin(), states.end(),
                       [&](const auto& s) { return s.first > t && s.second == wanted; });
  };

  // The other clients, as processes: a tool loop, a palpation demo and a watcher.
  ChildProcess pliers(PLIERS_PATH,
                      {write_hold_gesture(dir, box.id(box.drawn(75, 25))).string(), "--model",
                       "box", "--timeout", "20", "--rate", kPliersRate, "--csv",
                       (dir / "pliers.csv").string(), "--json", (dir / "pliers.json").string()},
                      dir / "pliers.out");
  ChildProcess demo(CLIENT_PATH, {"demo", "--model", "box", "--rate", "100", "--repeat", "1000"},
                    dir / "demo.out");
  ChildProcess watch(CLIENT_PATH, {"watch"}, dir / "watch.out");
  ASSERT_TRUE(pliers.wait_for_output("left   touch", Clock::now() + kLiveness)) << pliers.output();
  ASSERT_TRUE(watch.wait_for_output("palpated present", Clock::now() + kLiveness))
      << watch.output();
  ASSERT_TRUE(demo.wait_for_output("depth", Clock::now() + kLiveness)) << demo.output();
  std::this_thread::sleep_for(300ms);
  ASSERT_GT(answered_after(Clock::now() - 300ms), 5);

  ASSERT_EQ(daemon->stop(SIGKILL), 128 + SIGKILL);
  const auto killed = Clock::now();
  // Each client notices (heartbeat silent for 3 × 0.1 s + 1 s).
  const auto noticed_by = killed + kLiveness;
  // Sequential waits: each time is an upper bound of when that client said it.
  double noticed_s[4] = {};
  EXPECT_TRUE(pliers.wait_for_output("palpated lost: no status heartbeat", noticed_by))
      << pliers.output();
  noticed_s[0] = seconds(Clock::now() - killed);
  EXPECT_TRUE(watch.wait_for_output("palpated lost: no status heartbeat", noticed_by))
      << watch.output();
  noticed_s[1] = seconds(Clock::now() - killed);
  while (!state_after(killed, DaemonState::kLost) && Clock::now() < noticed_by)
    std::this_thread::sleep_for(10ms);
  EXPECT_TRUE(state_after(killed, DaemonState::kLost));
  noticed_s[2] = seconds(Clock::now() - killed);
  EXPECT_TRUE(demo.wait_for_output("palpated lost: no status heartbeat", noticed_by))
      << demo.output();
  noticed_s[3] = seconds(Clock::now() - killed);
  std::printf(
      "loss reported after the kill by: pliers %.2f s, watch %.2f s, in-process client "
      "%.2f s, demo %.2f s (at most)\n",
      noticed_s[0], noticed_s[1], noticed_s[2], noticed_s[3]);

  // A new palpated, same configuration: the same client processes resume.
  daemon = std::make_unique<Daemon>(args, dir / "palpated-2.log");
  const auto restarted = Clock::now();
  const auto resumed_by = restarted + 2 * kLiveness;
  double back_s[4] = {};
  EXPECT_TRUE(pliers.wait_for_output("palpated is back", resumed_by)) << pliers.output();
  back_s[0] = seconds(Clock::now() - restarted);
  EXPECT_TRUE(watch.wait_for_output("palpated is back", resumed_by)) << watch.output();
  back_s[1] = seconds(Clock::now() - restarted);
  while (answered_after(restarted) == 0 && Clock::now() < resumed_by)
    std::this_thread::sleep_for(10ms);
  ASSERT_GT(answered_after(restarted), 0) << "the request client got replies again\n"
                                          << daemon->log();
  back_s[2] = seconds(Clock::now() - restarted);
  EXPECT_TRUE(demo.wait_for_output("palpated is back", resumed_by)) << demo.output();
  back_s[3] = seconds(Clock::now() - restarted);
  std::printf(
      "back after the restart (palpated's start included) for: pliers %.2f s, watch "
      "%.2f s, in-process client's first reply %.2f s, demo %.2f s (at most)\n",
      back_s[0], back_s[1], back_s[2], back_s[3]);
  std::this_thread::sleep_for(700ms);  // feedback flows for a while
  asking = false;
  asker.join();
  // The restarted daemon answers as the first one did, bit for bit.
  {
    const std::lock_guard lock(answers_mutex);
    const Reply& again = answers.back().reply;
    EXPECT_EQ(again.status, RequestStatus::kOk);
    EXPECT_EQ(again.total_force_n, first.total_force_n);
    EXPECT_GT(answers.back().at, restarted);
  }
  // It made a reply writer for each client it found (they did not restart).
  const std::string log = daemon->log();
  EXPECT_NE(log.find("event=client_added client=faults-requests"), std::string::npos) << log;

  pliers.signal(SIGINT);
  EXPECT_EQ(pliers.wait(kLiveness), 130) << pliers.output();
  watch.signal(SIGTERM);
  EXPECT_EQ(watch.wait(kLiveness), 0) << watch.output();
  demo.signal(SIGTERM);
  demo.wait(kLiveness);
  EXPECT_EQ(ChildProcess::count(watch.output(), "palpated lost"), 1) << watch.output();
  EXPECT_EQ(ChildProcess::count(watch.output(), "palpated is back (up"), 1) << watch.output();
  EXPECT_NE(pliers.output().find("palpated lost 1 time(s), restarted 1 time(s); now present"),
            std::string::npos)
      << pliers.output();

  // The pliers' ticks: while palpated was lost the device rendered no force;
  // after it came back, feedback came in the tick again.
  std::ifstream csv(dir / "pliers.csv");
  std::string line;
  std::getline(csv, line);
  ASSERT_NE(line.find(",rendered_n,daemon"), std::string::npos) << line;
  int lost = 0, pliers_answered = 0, last_lost_tick = -1;
  std::vector<std::pair<int, std::string>> outcomes;
  while (std::getline(csv, line)) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    // 26 columns, then what was rendered at the device's rate (docs/pliers.md).
    ASSERT_EQ(cells.size(), 32u) << line;
    const int tick = std::stoi(cells[0]);
    if (cells[25] == "lost") {
      ++lost;
      last_lost_tick = tick;
      EXPECT_EQ(std::stod(cells[24]), 0.0) << "tick " << tick << ": force rendered while lost";
      EXPECT_EQ(std::stod(cells[29]), 0.0)
          << "tick " << tick << ": force rendered at a device step while lost";
    }
    outcomes.emplace_back(tick, cells[7]);
  }
  // Answered at all, in its tick or late: how many came in time depends on
  // the machine's speed (under ASan on two cores, none), which a test does
  // not assert.
  for (const auto& [tick, outcome] : outcomes)
    pliers_answered += tick > last_lost_tick && outcome != "missing" ? 1 : 0;
  EXPECT_GT(lost, 100)
      << "ticks while palpated was lost (from 1.3 s after the kill to the restart)";
  EXPECT_GT(pliers_answered, 100) << "the pliers' poses answered after palpated came back";
  EXPECT_EQ(daemon->stop(SIGTERM), 0) << daemon->log();
}

// ---------------------------------------------------------------------------
// Compliance files: a truncated, a corrupted and a wrong-version file are
// refused at start-up with one line and exit 2; a file replaced while the
// daemon runs does not change what it serves.

/// Runs palpated on @p file until it exits (it should not start serving).
std::pair<int, std::string> start_on(const std::filesystem::path& file, const TempDir& dir) {
  Daemon daemon({"--model", "box=" + file.string(), "--domain", "7"}, dir / "refused.log");
  const int code = daemon.stop(0);
  return {code, daemon.log()};
}

/// The one error line palpated printed.
std::string error_line(const std::string& log) {
  const auto at = log.find("palpated: error: ");
  if (at == std::string::npos) return {};
  return log.substr(at, log.find('\n', at) - at);
}

void flip_byte(const std::filesystem::path& file, std::uint64_t offset) {
  std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(static_cast<std::streamoff>(offset));
  char c = 0;
  f.get(c);
  f.seekp(static_cast<std::streamoff>(offset));
  f.put(static_cast<char>(c ^ 0x10));
}

TEST(Faults, DamagedAndWrongVersionComplianceFilesAreRefusedAtStartUp) {
  TempDir dir;
  const auto good = testing::write_box_compliance(dir.path(), "box", 4, 85e3);
  const auto size = std::filesystem::file_size(good);
  struct Case {
    std::string name;
    std::vector<std::string> fragments;
  };
  // Truncated: the end of the file is missing.
  std::filesystem::copy_file(good, dir / "truncated.h5");
  std::filesystem::resize_file(dir / "truncated.h5", size * 2 / 3);
  // Corrupted: one bit flipped in the middle of G's data.
  std::filesystem::copy_file(good, dir / "corrupted.h5");
  {
    const hid_t file = H5Fopen(good.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t set = H5Dopen2(file, "/compliance/G", H5P_DEFAULT);
    const haddr_t offset = H5Dget_offset(set);
    const hsize_t bytes = H5Dget_storage_size(set);
    H5Dclose(set);
    H5Fclose(file);
    ASSERT_NE(offset, HADDR_UNDEF);
    flip_byte(dir / "corrupted.h5", offset + bytes / 2 + 3);
  }
  // Wrong version: a major version this palpate does not read.
  std::filesystem::copy_file(good, dir / "version.h5");
  {
    const hid_t file = H5Fopen((dir / "version.h5").c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t attr = H5Aopen(file, "format_version_major", H5P_DEFAULT);
    const int two = 2;
    H5Awrite(attr, H5T_NATIVE_INT, &two);
    H5Aclose(attr);
    H5Fclose(file);
  }
  // Mixed: the first half of this file, the rest of another of the same mesh
  // (E × 2): what a reader would see of a file overwritten in place while it
  // reads, or of a copy interrupted over an older one.
  {
    TempDir other;
    const auto stiff = testing::write_box_compliance(other.path(), "box", 4, 170e3);
    std::ifstream a(good, std::ios::binary), b(stiff, std::ios::binary);
    const std::string first(std::istreambuf_iterator<char>(a), {}),
        second(std::istreambuf_iterator<char>(b), {});
    ASSERT_EQ(first.size(), second.size());
    std::ofstream(dir / "mixed.h5", std::ios::binary)
        << first.substr(0, first.size() / 2) << second.substr(first.size() / 2);
  }
  const std::vector<Case> cases{
      {"truncated.h5", {"truncated: ", "bytes of the", "copy it again"}},
      {"mixed.h5", {"content_sha256", "the file is corrupt"}},
      {"corrupted.h5", {"content_sha256", "the file is corrupt"}},
      {"version.h5", {"format_version_major: is 2; this palpate reads version 1.x"}},
  };
  for (const auto& c : cases) {
    const auto [code, log] = start_on(dir / c.name, dir);
    EXPECT_EQ(code, 2) << c.name << "\n" << log;
    const std::string line = error_line(log);
    EXPECT_NE(line.find((dir / c.name).string()), std::string::npos) << line;
    for (const auto& fragment : c.fragments)
      EXPECT_NE(line.find(fragment), std::string::npos) << c.name << ": " << line;
    EXPECT_EQ(ChildProcess::count(log, "palpated: error: "), 1) << log;
    EXPECT_EQ(log.find("event=serving"), std::string::npos) << log;
  }
  // The intact file starts.
  Daemon daemon({"--model", "box=" + good.string(), "--domain", "7"}, dir / "good.log");
  Client client(ClientOptions{"faults-good", 7, "", false, false});
  EXPECT_TRUE(client.wait_for_model("box", kLiveness)) << daemon.log();
  EXPECT_EQ(daemon.stop(SIGTERM), 0);
}

/// One request's answer from whatever palpated serves "box" on @p domain,
/// sent again until one comes (a daemon just started may not route it yet).
std::optional<Reply> ask(Client& client, const std::vector<ConstraintSpec>& press) {
  for (int attempt = 0; attempt < 20; ++attempt)
    if (auto reply = client.wait_reply(client.send("box", press, false, false), 500ms))
      return reply;
  return std::nullopt;
}

TEST(Faults, AFileReplacedWhileTheDaemonServesChangesNothingItServes) {
  TempDir dir;
  const auto served = testing::write_box_compliance(dir.path(), "box", 4, 85e3);
  TempDir other;
  const auto stiff = testing::write_box_compliance(other.path(), "box", 4, 170e3);  // E × 2
  Daemon daemon({"--model", "box=" + served.string(), "--domain", "8"}, dir / "palpated.log");
  Client client(ClientOptions{"faults-replaced", 8, "", false, false});
  const Box box = describe(client, "box");
  const std::vector<ConstraintSpec> press{
      ConstraintSpec::displacement(box.info.surface.vertex_ids[3], {0, 0, -0.001})};
  const auto original = ask(client, press);
  ASSERT_TRUE(original) << daemon.log();
  ASSERT_EQ(original->status, RequestStatus::kOk);

  // Replaced by rename (how palpate-precompute writes), then overwritten in place.
  std::filesystem::copy_file(stiff, dir / ".box.h5.new");
  std::filesystem::rename(dir / ".box.h5.new", served);
  const auto after_rename = ask(client, press);
  ASSERT_TRUE(after_rename);
  EXPECT_EQ(after_rename->total_force_n, original->total_force_n);
  EXPECT_EQ(after_rename->results[0].force_n, original->results[0].force_n);
  {
    std::ifstream in(stiff, std::ios::binary);
    std::ofstream out(served, std::ios::binary | std::ios::in | std::ios::out);
    out << in.rdbuf();
  }
  const auto after_overwrite = ask(client, press);
  ASSERT_TRUE(after_overwrite);
  EXPECT_EQ(after_overwrite->total_force_n, original->total_force_n);
  EXPECT_EQ(daemon.stop(SIGTERM), 0) << daemon.log();

  // A daemon started now serves the new file: twice the force (E doubled),
  // which the answers above would have shown had the model changed.
  Daemon again({"--model", "box=" + served.string(), "--domain", "8"}, dir / "again.log");
  const auto fresh = ask(client, press);
  ASSERT_TRUE(fresh) << again.log();
  EXPECT_LT(
      (Vector3d(fresh->total_force_n.data()) - 2 * Vector3d(original->total_force_n.data())).norm(),
      1e-9 * Vector3d(fresh->total_force_n.data()).norm());
  EXPECT_EQ(again.stop(SIGTERM), 0);
}

TEST(Faults, AFileOverwrittenWhileTheDaemonLoadsItIsServedWholeOrRefused) {
  // A writer overwrites the file in place, again and again, alternately with
  // two models (E and 2E), in 16 kB pieces 1 ms apart (some 40 ms per file),
  // and rests 60 ms between two files; palpated is started on it repeatedly meanwhile. Each
  // start must serve model A exactly, or model B exactly, or stop with one
  // clear line (exit 2): never a mix of the two.
  TempDir dir, sources;
  const auto a = testing::write_box_compliance(sources.path(), "a", 4, 85e3);
  std::filesystem::create_directory(sources / "b");
  const auto b = testing::write_box_compliance(sources.path() / "b", "a", 4, 170e3);
  auto bytes = [](const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string content[2] = {bytes(a), bytes(b)};
  const auto file = dir / "box.h5";
  std::filesystem::copy_file(a, file);

  // The answers of each model alone (same daemon code, so bit for bit).
  Client client(ClientOptions{"faults-loading", 9, "", false, false});
  Reply expected[2];
  std::vector<ConstraintSpec> press;
  for (int m = 0; m < 2; ++m) {
    Daemon clean({"--model", "box=" + (m == 0 ? a : b).string(), "--domain", "9"},
                 dir / "clean.log");
    if (press.empty()) {
      const Box box = describe(client, "box");
      press = {ConstraintSpec::displacement(box.info.surface.vertex_ids[3], {0, 0, -0.001})};
    }
    const auto reply = ask(client, press);
    ASSERT_TRUE(reply) << clean.log();
    expected[m] = *reply;
    ASSERT_EQ(clean.stop(SIGTERM), 0);
  }
  ASSERT_NE(expected[0].total_force_n, expected[1].total_force_n);

  std::atomic<bool> writing{true};
  std::atomic<int> writes{0};
  std::thread writer([&] {
    for (int m = 1; writing; m ^= 1) {
      {
        std::fstream out(file, std::ios::in | std::ios::out | std::ios::binary);  // no truncation
        for (std::size_t at = 0; at < content[m].size() && writing; at += 16384) {
          out.write(content[m].data() + at, static_cast<std::streamsize>(std::min<std::size_t>(
                                                16384, content[m].size() - at)));
          out.flush();
          std::this_thread::sleep_for(1ms);
        }
      }
      ++writes;
      std::this_thread::sleep_for(60ms);
    }
  });
  int served[2] = {0, 0}, refused = 0;
  constexpr int kStarts = 10;
  for (int start = 0; start < kStarts; ++start) {
    Daemon daemon({"--model", "box=" + file.string(), "--domain", "9"},
                  dir / ("start-" + std::to_string(start) + ".log"));
    // Its log says which: serving, or one error line before it exits.
    std::string log;
    for (const auto until = Clock::now() + kLiveness;
         Clock::now() < until && log.find("event=serving") == std::string::npos &&
         log.find("palpated: error") == std::string::npos;
         std::this_thread::sleep_for(5ms))
      log = daemon.log();
    if (log.find("event=serving") != std::string::npos) {
      const auto reply = ask(client, press);
      ASSERT_TRUE(reply) << daemon.log();
      const int m = reply->total_force_n == expected[0].total_force_n   ? 0
                    : reply->total_force_n == expected[1].total_force_n ? 1
                                                                        : -1;
      EXPECT_NE(m, -1) << "start " << start << " serves neither file";
      if (m >= 0) ++served[m];
      EXPECT_EQ(daemon.stop(SIGTERM), 0);
    } else {
      EXPECT_EQ(daemon.stop(0), 2) << daemon.log();
      const std::string line = error_line(daemon.log());
      EXPECT_NE(line.find(file.string() + ": "), std::string::npos) << daemon.log();
      ++refused;
    }
  }
  writing = false;
  writer.join();
  std::printf("%d starts during %d overwrites: served A %d, served B %d, refused %d\n", kStarts,
              writes.load(), served[0], served[1], refused);
  EXPECT_GT(writes.load(), 0);
}

}  // namespace
}  // namespace palpate
