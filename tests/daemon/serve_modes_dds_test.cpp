// palpated's serve modes end to end (docs/realtime.md): the real daemon
// serving requests and tool poses in Cyclone's listener (the default), on
// its own serving thread woken by a waitset, and on that thread polling;
// then on a real-time serving thread (SCHED_FIFO, bound to a CPU, memory
// locked) when this process may ask for one, or refused with its message
// when it may not. Each mode must give the listener's answers. CTest runs
// this binary in a private network namespace; no timing is asserted.

#include <gtest/gtest.h>
#include <signal.h>

#include <Eigen/Dense>
#include <atomic>
#include <chrono>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "../../lib/daemon/src/serving_thread.hpp"
#include "palpate.h"
#include "palpate/core/error.hpp"
#include "palpate/core/sanitizers.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/realtime.hpp"
#include "palpate/transport/tool_client.hpp"
#ifdef PALPATE_COUNTS_ALLOCATIONS
#include "support/allocation_counter.hpp"
#endif
#include "support/box_job.hpp"
#include "support/daemon_process.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace std::chrono_literals;
using testing::Daemon;
using testing::TempDir;

constexpr auto kServeTimeout = 10s;
// A domain of its own: the other suites' daemons are on domain 0.
constexpr std::uint32_t kDomain = 17;
constexpr std::array<double, 4> kToolPointingDown{0, 1, 0, 0};  // tool +z along the model's −z

/// What one palpated answered: the replies to a fixed list of requests,
/// and the feedback of a probe pressed in fixed steps, one pose at a time.
struct Answers {
  std::vector<Reply> replies;
  std::vector<Eigen::Vector3d> press_forces;
};

class ServeModes : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    testing::write_box_compliance(dir_->path(), "box", 4, 85e3);
    // The probe's force follows its pose alone: no slew limit, sticking
    // friction, and one pose answered before the next is sent.
    std::ofstream(dir_->path() / "palpated.toml")
        << "[daemon]\nid = \"serve-modes\"\nlog_level = \"info\"\n"
           "[rates]\nstatus_hz = 20\n"
           "[[model]]\nid = \"box\"\nfile = \"box.h5\"\n"
           "[[tools]]\nid = \"probe\"\ntip = \"sphere\"\ntip_radius_mm = 2\nfriction = 1e9\n"
           "jaw_length_mm = 0\nforce_limit_n = 100\nmax_force_rate_n_per_s = 1e9\n";
  }
  static void TearDownTestSuite() { delete dir_; }

  /// Starts palpated with @p flags, plays the requests and the press, stops
  /// it (SIGTERM, exit 0).
  static Answers play(const std::string& name, std::vector<std::string> flags) {
    flags.insert(flags.begin(), {"--config", (dir_->path() / "palpated.toml").string(), "--domain",
                                 std::to_string(kDomain)});
    Daemon daemon(flags, dir_->path() / (name + ".log"));
    Answers answers;
    {
      Client client(ClientOptions{"serve-" + name, kDomain, ""});
      const auto model = client.wait_for_model("box", kServeTimeout);
      EXPECT_TRUE(model) << daemon.log();
      EXPECT_TRUE(client.wait_for_service(kServeTimeout)) << daemon.log();
      if (!model) return answers;
      const int top = testing::box_top_vertex(model->surface.rest_positions_m,
                                              model->surface.compliance_vertex_count, 50, 20);
      const std::uint32_t v = model->surface.vertex_ids[static_cast<std::size_t>(top)];
      const std::uint32_t w = model->surface.vertex_ids[0];
      const std::vector<std::vector<ConstraintSpec>> requests{
          {ConstraintSpec::displacement(v, {0, 0, -0.002})},
          {ConstraintSpec::force(v, {0, 0, -1}), ConstraintSpec::displacement(w, {0, 0, 0})},
          {ConstraintSpec::normal_displacement(v, {0, 0, 1}, -0.001)},
          {ConstraintSpec::displacement(v, {0, 0, -30})}};  // refused: too long
      for (const auto& request : requests)
        answers.replies.push_back(client.request("box", request, /*want_surface=*/true,
                                                 /*update_state=*/false, kServeTimeout));

      ToolClientOptions tool_options;
      tool_options.domain_id = kDomain;
      ToolClient tools(tool_options);
      tools.open_tool("probe");
      EXPECT_TRUE(tools.wait_for_daemon(kServeTimeout)) << daemon.log();
      const Eigen::Vector3d rest(
          &model->surface.rest_positions_m[3 * static_cast<std::size_t>(top)]);
      std::uint64_t sequence = static_cast<std::uint64_t>(ToolClient::now_ns() / 1000);
      // From 1 mm above to 3 mm deep in 0.05 mm steps, then held.
      for (int step = 0; step <= 100; ++step) {
        const double depth = std::min(0.003, -0.001 + 5e-5 * step);
        const Eigen::Vector3d hinge = rest + Eigen::Vector3d(0, 0, 0.002 - depth);
        std::optional<ToolFeedbackSample> answer;
        for (int attempt = 0; attempt < 5 && !answer; ++attempt) {  // best effort: rarely lost
          tools.send_pose("probe", "box", ++sequence, {hinge.x(), hinge.y(), hinge.z()},
                          kToolPointingDown, 0);
          answer = tools.wait_feedback("probe", sequence, std::chrono::steady_clock::now() + 1s);
        }
        EXPECT_TRUE(answer) << "step " << step << "\n" << daemon.log();
        if (!answer) break;
        answers.press_forces.emplace_back(answer->force_n[0], answer->force_n[1],
                                          answer->force_n[2]);
      }
      EXPECT_TRUE(tools.end_session("probe", "box", kServeTimeout)) << daemon.log();
    }
    EXPECT_EQ(daemon.stop(SIGTERM), 0) << daemon.log();
    log_ = daemon.log();
    return answers;
  }

  /// Equal answers: the same code serves them on another thread. The
  /// replies' numbers agree to round-off (1e-12 relative; the solver's
  /// cache may order sums differently), the statuses exactly.
  static void expect_same(const Answers& a, const Answers& b, const std::string& mode) {
    ASSERT_EQ(a.replies.size(), b.replies.size()) << mode;
    for (std::size_t i = 0; i < a.replies.size(); ++i) {
      const Reply &x = a.replies[i], &y = b.replies[i];
      EXPECT_EQ(x.status, y.status) << mode << ", request " << i << ": " << y.message;
      EXPECT_EQ(x.message, y.message) << mode << ", request " << i;
      ASSERT_EQ(x.results.size(), y.results.size()) << mode << ", request " << i;
      for (std::size_t r = 0; r < x.results.size(); ++r) {
        const Eigen::Vector3d fx(x.results[r].force_n.data()), fy(y.results[r].force_n.data());
        EXPECT_LE((fx - fy).norm(), 1e-12 * std::max(1.0, fx.norm())) << mode << ", request " << i;
      }
      ASSERT_EQ(x.surface_displacement_m.size(), y.surface_displacement_m.size()) << mode;
      const Eigen::Map<const Eigen::VectorXd> ux(
          x.surface_displacement_m.data(),
          static_cast<Eigen::Index>(x.surface_displacement_m.size())),
          uy(y.surface_displacement_m.data(),
             static_cast<Eigen::Index>(y.surface_displacement_m.size()));
      EXPECT_LE((ux - uy).norm(), 1e-12 * std::max(1e-9, ux.norm())) << mode << ", request " << i;
    }
    EXPECT_EQ(a.replies[3].status, RequestStatus::kDisplacementTooLarge) << "the refused request";
    ASSERT_EQ(a.press_forces.size(), b.press_forces.size()) << mode;
    for (std::size_t s = 0; s < a.press_forces.size(); ++s)
      EXPECT_LE((a.press_forces[s] - b.press_forces[s]).norm(),
                1e-9 * std::max(1e-3, a.press_forces[s].norm()))
          << mode << ", press step " << s;
  }

  static const Answers& listener() {
    static const Answers answers = play("listener", {});
    return answers;
  }

  inline static TempDir* dir_ = nullptr;
  inline static std::string log_;
};

TEST_F(ServeModes, TheListenerPressesAndAnswers) {
  const Answers& a = listener();
  ASSERT_EQ(a.replies.size(), 4u);
  EXPECT_EQ(a.replies[0].status, RequestStatus::kOk);
  ASSERT_EQ(a.press_forces.size(), 101u);
  EXPECT_EQ(a.press_forces.front().norm(), 0.0) << "1 mm above: free";
  EXPECT_GT(a.press_forces.back().z(), 0.1) << "3 mm deep: pushed back up";
}

TEST_F(ServeModes, AWaitsetServingThreadGivesTheListenersAnswers) {
  const Answers& reference = listener();
  const Answers waitset = play("waitset", {"--serve", "waitset"});
  EXPECT_NE(log_.find("event=realtime serve=waitset priority=0"), std::string::npos) << log_;
  expect_same(reference, waitset, "waitset");
}

TEST_F(ServeModes, ABusyServingThreadGivesTheListenersAnswers) {
  const Answers& reference = listener();
  const Answers busy = play("busy", {"--serve", "busy"});
  EXPECT_NE(log_.find("event=realtime serve=busy"), std::string::npos) << log_;
  expect_same(reference, busy, "busy");
}

// SCHED_FIFO 10 on one CPU with locked memory (not under a sanitizer): the same answers when this
// process may (root, CAP_SYS_NICE or RLIMIT_RTPRIO), else palpated refuses
// to start with exit 2 and says how to grant it.
TEST_F(ServeModes, ARealTimeServingThreadGivesTheSameAnswersOrIsRefusedWithTheWay) {
  const int cpu = realtime::available_cpus().front();
  std::vector<std::string> flags{"--serve", "waitset", "--rt-priority",
                                 "10",      "--cpus",  std::to_string(cpu)};
#ifndef PALPATE_SHADOW_MEMORY
  const bool lock = true;
  flags.push_back("--lock-memory");
#else
  const bool lock = false;
#endif
  bool permitted = true;
  try {
    realtime::check_permitted({10, {}, false});
  } catch (const InputError&) {
    permitted = false;
  }
  if (!permitted) {
    std::vector<std::string> args{"--config", (dir_->path() / "palpated.toml").string(), "--domain",
                                  std::to_string(kDomain)};
    args.insert(args.end(), flags.begin(), flags.end());
    Daemon refused(args, dir_->path() / "refused.log");
    EXPECT_EQ(refused.stop(0), 2) << refused.log();
    EXPECT_NE(refused.log().find("realtime.priority 10: the kernel refuses SCHED_FIFO"),
              std::string::npos)
        << refused.log();
    EXPECT_NE(refused.log().find("LimitRTPRIO=10"), std::string::npos) << refused.log();
    return;
  }
  const Answers& reference = listener();
  const Answers rt = play("realtime", flags);
  EXPECT_NE(log_.find("event=realtime serve=waitset priority=10 cpus=\"" + std::to_string(cpu) +
                      "\" lock_memory=" + (lock ? "true" : "false")),
            std::string::npos)
      << log_;
  expect_same(reference, rt, "waitset, SCHED_FIFO 10");
}

// The serving thread's own loop (a waitset wait, or a take per reader and
// a yield) allocates nothing: only what it calls may, and palpated's serve
// functions do not. Here it serves a reader of its own with a function that
// takes into fixed samples, 200 samples in each mode, counting C++
// allocations of every thread meanwhile (Cyclone's are C, not counted; not
// under ThreadSanitizer, whose run time owns operator new).
struct Served {
  std::atomic<int> taken{0};
  palpate_ToolCommand samples[4];
  void* pointers[4] = {&samples[0], &samples[1], &samples[2], &samples[3]};
  dds_sample_info_t infos[4];
};

void take_commands(dds_entity_t reader, void* arg) {
  Served& served = *static_cast<Served*>(arg);
  for (dds_return_t n; (n = dds_take(reader, served.pointers, served.infos, 4, 4)) > 0;)
    for (dds_return_t i = 0; i < n; ++i)
      if (served.infos[i].valid_data) served.taken.fetch_add(1, std::memory_order_release);
}

TEST(ServingThreadLoop, ServesEverySampleWithoutAllocating) {
  for (const ServeMode mode : {ServeMode::kWaitset, ServeMode::kBusy}) {
    SCOPED_TRACE(serve_mode_name(mode));
    dds::Participant participant = dds::join_domain(kDomain + 1, "");
    const dds_entity_t topic =
        dds::topic(participant.get(), &palpate_ToolCommand_desc, "serving_thread_test");
    const dds::Entity reader(dds::check(
        dds_create_reader(participant.get(), topic, dds::tool_command_qos().get(), nullptr),
        "reader"));
    const dds::Entity writer(dds::check(
        dds_create_writer(participant.get(), topic, dds::tool_command_qos().get(), nullptr),
        "writer"));
    dds_publication_matched_status_t matched{};
    for (int i = 0; i < 1000 && matched.current_count == 0; ++i) {
      dds_get_publication_matched_status(writer.get(), &matched);
      std::this_thread::sleep_for(5ms);
    }
    ASSERT_EQ(matched.current_count, 1u);

    Served served;
    daemon::ServingThread thread(participant.get(), mode, RealtimeOptions{});
    thread.add(reader.get(), &take_commands, &served);
    thread.start();
    palpate_ToolCommand command{};
    constexpr int kSamples = 200;
#ifdef PALPATE_COUNTS_ALLOCATIONS
    const std::uint64_t before = testing::allocations();
#endif
    for (int i = 0; i < kSamples; ++i) {
      command.pose_sequence = static_cast<std::uint64_t>(i);
      ASSERT_EQ(dds_write(writer.get(), &command), DDS_RETCODE_OK);
      // One at a time: each is served before the next is written.
      for (int wait = 0; wait < 5000 && served.taken.load(std::memory_order_acquire) <= i; ++wait)
        std::this_thread::sleep_for(200us);
    }
#ifdef PALPATE_COUNTS_ALLOCATIONS
    const std::uint64_t allocated = testing::allocations() - before;
    EXPECT_EQ(allocated, 0u);
#endif
    thread.stop();
    EXPECT_EQ(served.taken.load(), kSamples);
  }
}

}  // namespace
}  // namespace palpate
