#pragma once
// The fixture of the haptic tools' end-to-end tests (tool_dds_test.cpp,
// tool_response_dds_test.cpp): the real palpated on a box organ with a
// probe and two graspers, real Cyclone DDS on loopback (CTest runs the
// binary in a private network namespace), one ToolClient driving the tools
// at the haptic rate, a Client watching the surface stream, and G read from
// the compliance file for the direct solves of docs/model/requests.md.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <fstream>
#include <map>
#include <thread>

#include "palpate.h"
#include "palpate/core/units.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/tool_client.hpp"
#include "support/box_job.hpp"
#include "support/daemon_process.hpp"
#include "support/test_meshes.hpp"

namespace palpate::testing {

using namespace std::chrono_literals;

inline constexpr auto kTimeout = 10s;
inline constexpr double kRelativeTolerance = 1e-9;
inline const std::array<double, 4> kPointingDown{0, 1, 0, 0};  // tool +z along the model's −z

class ToolsOverDdsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    box_ = write_box_compliance(dir_->path(), "box", 8, 85e3);
    std::filesystem::create_directory(dir_->path() / "sessions");
    std::ofstream(dir_->path() / "palpated.toml")
        << "[daemon]\nid = \"tools-daemon\"\nlog_level = \"info\"\n"
           "[[model]]\nid = \"box\"\nfile = \"box.h5\"\n"
           "[[tools]]\nid = \"probe\"\ntip = \"sphere\"\ntip_radius_mm = 2\nfriction = 1e9\n"
           "jaw_length_mm = 0\nforce_limit_n = 100\nmax_force_rate_n_per_s = 1e6\n"
           "[[tools]]\nid = \"left\"\nforce_limit_n = 100\n"
           "[[tools]]\nid = \"right\"\nforce_limit_n = 100\n"
           "[contact]\nwatchdog_timeout_ms = 50\nwatchdog_ramp_ms = 100\n"
           "[recording]\ndirectory = \"sessions\"\n";
    daemon_ = new Daemon({"--config", (dir_->path() / "palpated.toml").string()},
                         dir_->path() / "palpated.log");
    Eigen::MatrixXd G;
    const ComplianceModel m = read_compliance_file(box_, &G);
    G_ = new Eigen::MatrixXd(std::move(G));
    client_ = new ToolClient(ToolClientOptions{});
    const auto info = client_->wait_for_model("box", kTimeout);
    ASSERT_TRUE(info) << daemon_->log();
    info_ = new ModelInfo(*info);
    // Open every tool first: the answers to its first poses are then not
    // lost while its readers are matched.
    for (const char* tool : {"probe", "left", "right"}) client_->open_tool(tool);
    ASSERT_TRUE(client_->wait_for_daemon(kTimeout)) << daemon_->log();
    viewer_ = new Client(ClientOptions{"tool-viewer", 0, "", true, false});
  }
  static void TearDownTestSuite() {
    delete viewer_;
    delete client_;
    EXPECT_EQ(daemon_->stop(SIGTERM), 0) << daemon_->log();
    // The session was recorded and closed: the final file, no .partial.
    int sessions = 0;
    for (const auto& entry : std::filesystem::directory_iterator(dir_->path() / "sessions")) {
      EXPECT_EQ(entry.path().extension(), ".h5") << entry.path();
      EXPECT_GT(std::filesystem::file_size(entry.path()), 1000u);
      ++sessions;
    }
    EXPECT_EQ(sessions, 1) << daemon_->log();
    if (::testing::Test::HasFailure()) std::fprintf(stderr, "%s", daemon_->log().c_str());
    delete daemon_;
    delete info_;
    delete G_;
    delete dir_;
  }

  static int top_vertex(double x_mm, double y_mm) {
    return box_top_vertex(info_->surface.rest_positions_m, info_->surface.compliance_vertex_count,
                          x_mm, y_mm);
  }
  static Eigen::Vector3d rest(int j) {
    return Eigen::Map<const Eigen::Vector3d>(
        &info_->surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
  }

  /// One tool driven at the haptic rate: a pose, then its feedback.
  struct Hand {
    std::string tool;
    Eigen::Vector3d at;
    double jaw = 0;
    std::uint64_t sequence;
    std::optional<ToolFeedbackSample> last;
    int answered = 0;

    Hand(std::string id, const Eigen::Vector3d& start, double jaw_angle = 0)
        : tool(std::move(id)), at(start), jaw(jaw_angle), sequence(next_sequence_ += 100000) {}

    void send() {
      client_->send_pose(tool, "box", ++sequence, {at.x(), at.y(), at.z()}, kPointingDown, jaw);
    }
    /// Paces the caller at the haptic rate: the force's slew limit is per second.
    void receive() {
      std::this_thread::sleep_until(next_tick_);
      next_tick_ = std::max(next_tick_ + 1ms, std::chrono::steady_clock::now());
      if (auto f = client_->wait_feedback(tool, sequence, std::chrono::steady_clock::now() + 1s)) {
        last = f;
        ++answered;
      }
    }
    void tick() {
      send();
      receive();
    }
    /// In straight steps of at most 0.05 mm and 1°.
    void move(const Eigen::Vector3d& to, double jaw_to, Hand* other = nullptr) {
      const Eigen::Vector3d from = at;
      const double jaw_from = jaw;
      const int n =
          std::max(1, static_cast<int>(std::ceil(std::max(
                          (to - from).norm() / 5e-5, std::abs(jaw_to - jaw_from) / degrees(1)))));
      for (int i = 1; i <= n; ++i) {
        at = from + (to - from) * (static_cast<double>(i) / n);
        jaw = jaw_from + (jaw_to - jaw_from) * (static_cast<double>(i) / n);
        send();
        if (other) other->send();
        receive();
        if (other) other->receive();
      }
    }
    void hold(int ticks, Hand* other = nullptr) {
      for (int i = 0; i < ticks; ++i) {
        send();
        if (other) other->send();
        receive();
        if (other) other->receive();
      }
    }
    Eigen::Vector3d force() const {
      return last ? Eigen::Vector3d(last->force_n.data()) : Eigen::Vector3d::Zero();
    }
  };

  /// The surface sample of a tick of @p hand (held still) and that tick's
  /// feedback: the hand ticks until the stream publishes one of its ticks
  /// (the stream runs at the visual rate, so it skips most). Poses keep
  /// coming meanwhile: no watchdog.
  static std::pair<SurfaceSample, ToolFeedbackSample> shown_tick(Hand& hand) {
    for (int attempt = 0; attempt < 200; ++attempt) {
      hand.tick();
      if (auto s = viewer_->wait_surface("box", 0, hand.sequence, 20ms); s && hand.last)
        if (hand.last->sequence == hand.sequence) return {std::move(*s), *hand.last};
    }
    ADD_FAILURE() << "no surface sample of a tick of " << hand.tool << "\n" << daemon_->log();
    return {};
  }

  /// What every contact point of @p s must satisfy (docs/dds.md,
  /// SurfaceContact): a tool's point, its vertices valid with weights summing
  /// to 1, and its position Σ w_i (rest_i + u_i) of the sample's own
  /// displacement u: on the deformed triangle. @returns per tool id, the
  /// number of its points and Σ of their forces.
  struct ToolPoints {
    std::uint32_t count = 0;
    Eigen::Vector3d force = Eigen::Vector3d::Zero();
  };
  static std::map<std::string, ToolPoints> check_contact_points(const SurfaceSample& s) {
    const DrawnSurface& surface = info_->surface;
    const auto ns = static_cast<std::size_t>(surface.compliance_vertex_count);
    EXPECT_EQ(s.displacement_m.size(), 3 * ns);
    double largest_u = 0;
    for (std::size_t a = 0; a < ns; ++a)
      largest_u =
          std::max(largest_u, Eigen::Map<const Eigen::Vector3d>(&s.displacement_m[3 * a]).norm());
    // The engine's point and the stream's field are the same G f, summed
    // in another order: they agree to rounding, far below 1e-9 of the press.
    const double on_surface_m = 1e-9 * largest_u;
    std::map<std::string, ToolPoints> tools;
    for (const SurfaceContactSample& c : s.contact_points) {
      EXPECT_TRUE(c.tool_id == "probe" || c.tool_id == "left" || c.tool_id == "right") << c.tool_id;
      const Eigen::Vector3d at(c.position_m.data()), f(c.force_n.data());
      EXPECT_TRUE(at.allFinite() && f.allFinite());
      Eigen::Vector3d expected = Eigen::Vector3d::Zero();
      double weight_sum = 0;
      int used = 0;
      for (std::size_t i = 0; i < 3; ++i) {
        const std::uint32_t v = c.vertices[i];
        if (v == SurfaceContactSample::kNoVertex) {
          EXPECT_EQ(c.weights[i], 0.0);
          continue;
        }
        EXPECT_EQ(used, static_cast<int>(i)) << "used slots come first";
        ++used;
        EXPECT_GT(c.weights[i], 0.0);
        const auto drawn = static_cast<std::size_t>(
            std::find(surface.vertex_ids.begin(), surface.vertex_ids.end(), v) -
            surface.vertex_ids.begin());
        EXPECT_LT(drawn, surface.vertex_ids.size()) << "mesh vertex " << v << " is not drawn";
        if (drawn >= surface.vertex_ids.size()) continue;
        Eigen::Vector3d x = rest(static_cast<int>(drawn));
        if (drawn < ns) x += Eigen::Map<const Eigen::Vector3d>(&s.displacement_m[3 * drawn]);
        expected += c.weights[i] * x;
        weight_sum += c.weights[i];
      }
      EXPECT_GE(used, 1);
      EXPECT_NEAR(weight_sum, 1.0, 1e-12);
      EXPECT_LE((at - expected).norm(), on_surface_m)
          << "contact point off its deformed triangle by " << (at - expected).norm() << " m";
      ++tools[c.tool_id].count;
      tools[c.tool_id].force += f;
    }
    return tools;
  }

  static bool saw_event(const std::vector<ToolEventSample>& events, const std::string& tool,
                        ToolEventKind kind) {
    for (const auto& e : events)
      if (e.tool_id == tool && e.kind == kind) return true;
    return false;
  }

  inline static TempDir* dir_ = nullptr;
  inline static std::filesystem::path box_;
  inline static Daemon* daemon_ = nullptr;
  inline static Eigen::MatrixXd* G_ = nullptr;
  inline static ToolClient* client_ = nullptr;
  inline static Client* viewer_ = nullptr;
  inline static ModelInfo* info_ = nullptr;
  inline static std::uint64_t next_sequence_ = 0;
  inline static std::chrono::steady_clock::time_point next_tick_{};
};

}  // namespace palpate::testing
