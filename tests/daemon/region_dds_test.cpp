// palpated serving a compliance file with a cuttable region, end to end over
// real Cyclone DDS on loopback (CTest runs this inside a private network
// namespace): the model's description names the region, and every surface
// sample carries its part (docs/dds.md, "The cut region") as the region
// itself says it, computed here from the same file by HybridRegion; a
// model without a region streams none; a probe pressing the region feels
// it, and a cutting tool's live edge cuts it (docs/tools.md, "Cutting").

#include <gtest/gtest.h>
#include <signal.h>

#include <Eigen/Core>
#include <array>
#include <chrono>
#include <cmath>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/hybrid_region.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/tool_client.hpp"
#include "support/box_job.hpp"
#include "support/daemon_process.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace std::chrono_literals;
using testing::Daemon;
using testing::TempDir;

constexpr auto kRegionTimeout = 10s;
// At rest nothing loads the region: its vertices are where the file puts
// them, sent as doubles (no arithmetic on the way).
constexpr double kRestTolerance_m = 1e-12;

class RegionStream : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    // A 96 × 64 × 48 mm box of 16 mm cells clamped on x = 0; the region is
    // the block of 8 cells at the free end under the top face (48 tetrahedra).
    PrecomputeJob job = testing::clamped_job(testing::box_mesh(0.096, 0.064, 0.048, 6, 4, 4),
                                             dir_->path(), "cut", 85e3);
    job.cut_region =
        CutRegionJob{RegionSpec::box({0.064, 0.016, 0.024}, {0.096, 0.048, 0.048}), 1060, 20};
    run_precompute(job, {});
    plain_ = testing::write_box_compliance(dir_->path(), "plain", 4, 85e3);
    model_ = new SurfaceModel(load_surface_model("cut", job.output));
    std::ofstream(dir_->path() / "palpated.toml")
        << "[daemon]\nid = \"region-daemon\"\n"
           "[rates]\nsurface_hz = 200\n"
           "[[model]]\nid = \"cut\"\nfile = \"cut.h5\"\n"
           "[[model]]\nid = \"plain\"\nfile = \"plain.h5\"\n"
           "[[tools]]\nid = \"probe\"\ntip = \"sphere\"\ntip_radius_mm = 4\n"
           "jaw_length_mm = 0\nforce_limit_n = 100\nmax_force_rate_n_per_s = 1e6\n"
           "[[tools]]\nid = \"hook\"\ntip_radius_mm = 1\ntip_length_mm = 35\n"
           "jaw_length_mm = 0\ncutting = true\nforce_limit_n = 100\n"
           "max_force_rate_n_per_s = 1e6\n"
           "[contact]\nwatchdog_timeout_ms = 200\n";
    daemon_ = new Daemon({"--config", (dir_->path() / "palpated.toml").string()},
                         dir_->path() / "palpated.log");
  }
  static void TearDownTestSuite() {
    EXPECT_EQ(daemon_->stop(SIGTERM), 0) << daemon_->log();
    delete daemon_;
    delete model_;
    delete dir_;
  }

  inline static TempDir* dir_ = nullptr;
  inline static std::filesystem::path plain_;
  inline static SurfaceModel* model_ = nullptr;
  inline static Daemon* daemon_ = nullptr;
};

TEST_F(RegionStream, TheDescriptionNamesTheRegionAndTheStreamCarriesItsSurface) {
  ASSERT_FALSE(model_->cut_region_spec.empty());
  Client client(ClientOptions{"region-viewer", 0, "", true, false});
  const auto info = client.wait_for_model("cut", kRegionTimeout);
  ASSERT_TRUE(info) << daemon_->log();
  EXPECT_EQ(info->cut_region, model_->cut_region_spec);

  // What the region says of itself, from the same file.
  const HybridRegion region(*model_);
  const int nrv = region.tensor_mass().vertex_count();
  std::vector<std::array<int, 3>> visible;
  visible.reserve(4 * static_cast<std::size_t>(region.tensor_mass().tetrahedron_count()));
  region.visible_triangles(visible);
  std::vector<std::uint32_t> hidden(static_cast<std::size_t>(region.interface_face_count()));
  hidden.resize(static_cast<std::size_t>(region.covered_rest_triangles(hidden)));
  ASSERT_FALSE(visible.empty());
  ASSERT_FALSE(hidden.empty());

  const auto rest = client.wait_surface("cut", 1, 0, kRegionTimeout);
  ASSERT_TRUE(rest) << daemon_->log();
  EXPECT_GE(rest->topology_version, 1u);
  ASSERT_EQ(rest->region_positions_m.size(), 3 * static_cast<std::size_t>(nrv));
  for (int v = 0; v < nrv; ++v) {
    const Eigen::Vector3d x = region.position_m(v);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(rest->region_positions_m[3 * static_cast<std::size_t>(v) + c], x[c],
                  kRestTolerance_m)
          << "region vertex " << v;
  }
  ASSERT_EQ(rest->region_triangles.size(), 3 * visible.size());
  for (std::size_t f = 0; f < visible.size(); ++f)
    for (int c = 0; c < 3; ++c)
      EXPECT_EQ(rest->region_triangles[3 * f + static_cast<std::size_t>(c)],
                static_cast<std::uint32_t>(visible[f][static_cast<std::size_t>(c)]));
  EXPECT_EQ(rest->hidden_triangles, hidden);
  for (const std::uint32_t t : rest->hidden_triangles)
    EXPECT_LT(t, info->surface.triangles.size() / 3);
  // At rest nothing pushes on the rest: f_Γ = 0 adds nothing to the field.
  for (const double u : rest->displacement_m) EXPECT_EQ(u, 0.0);

  // A request's state keeps the region's part, whole, in the same version.
  ASSERT_GT(info->surface.compliance_vertex_count, 0);
  const std::vector<ConstraintSpec> press{
      ConstraintSpec::force(info->surface.vertex_ids[0], {0, 0, -0.2})};
  const Reply reply = client.request("cut", press);
  ASSERT_EQ(reply.status, RequestStatus::kOk) << reply.message;
  const auto pressed =
      client.wait_surface("cut", rest->sequence_number + 1, reply.request_id, kRegionTimeout);
  ASSERT_TRUE(pressed) << daemon_->log();
  EXPECT_EQ(pressed->topology_version, rest->topology_version);
  EXPECT_EQ(pressed->region_triangles, rest->region_triangles);
  EXPECT_EQ(pressed->hidden_triangles, rest->hidden_triangles);
  EXPECT_EQ(pressed->region_positions_m.size(), rest->region_positions_m.size());
}

// A client takes the samples of every model while it waits for one: the
// model without a region has its own.
TEST_F(RegionStream, AModelWithoutARegionStreamsNone) {
  Client client(ClientOptions{"plain-viewer", 0, "", true, false});
  const auto plain = client.wait_for_model("plain", kRegionTimeout);
  ASSERT_TRUE(plain) << daemon_->log();
  EXPECT_EQ(plain->cut_region, "");
  const auto none = client.wait_surface("plain", 1, 0, kRegionTimeout);
  ASSERT_TRUE(none) << daemon_->log();
  EXPECT_EQ(none->topology_version, 0u);
  EXPECT_TRUE(none->region_positions_m.empty());
  EXPECT_TRUE(none->region_triangles.empty());
  EXPECT_TRUE(none->hidden_triangles.empty());
}

// Poses at the haptic rate (1 ms apart), each answered before the next.
struct Driver {
  ToolClient client{ToolClientOptions{}};
  std::uint64_t sequence = 0;
  std::optional<ToolFeedbackSample> pose(const std::string& tool, const Eigen::Vector3d& at,
                                         double jaw_rad) {
    ++sequence;
    // Tool +z along the model's −z: the tip points down.
    client.send_pose(tool, "cut", sequence, {at.x(), at.y(), at.z()}, {0, 1, 0, 0}, jaw_rad);
    auto feedback = client.wait_feedback(tool, sequence, std::chrono::steady_clock::now() + 1s);
    std::this_thread::sleep_for(1ms);
    return feedback;
  }
};

TEST_F(RegionStream, AProbeFeelsTheRegionAndAHookCutsIt) {
  Driver hand;
  hand.client.open_tool("probe");
  hand.client.open_tool("hook");
  ASSERT_TRUE(hand.client.wait_for_daemon(kRegionTimeout)) << daemon_->log();
  Client viewer(ClientOptions{"cut-viewer", 0, "", true, false});
  ASSERT_TRUE(viewer.wait_for_model("cut", kRegionTimeout)) << daemon_->log();
  const auto before = viewer.wait_surface("cut", 1, 0, kRegionTimeout);
  ASSERT_TRUE(before) << daemon_->log();

  // A 4 mm sphere 2 mm into the region's top at (80, 32) mm, a region vertex
  // off Γ and 16 mm from the rest's top faces: only the region is touched.
  // The region pushes the probe up, by at most k · 2 mm (the vertex moves
  // away: docs/model/hybrid-serving.md, "The hybrid model as served").
  const Eigen::Vector3d touch(0.080, 0.032, 0.048 + 0.004 - 0.002);
  for (int i = 0; i <= 20; ++i)
    hand.pose("probe", touch + Eigen::Vector3d(0, 0, 0.002 - i * 1e-4), 0);
  std::optional<ToolFeedbackSample> pressed;
  for (int i = 0; i < 300; ++i) pressed = hand.pose("probe", touch, 0);
  ASSERT_TRUE(pressed) << daemon_->log();
  const Eigen::Vector3d f(pressed->force_n.data());
  EXPECT_GT(f.z(), 0.05) << "N, up";
  EXPECT_LE(f.norm(), 200 * 0.002 * (1 + 1e-9)) << "N: k · depth at most";
  EXPECT_EQ(pressed->contacts, 0u) << "nothing of the rest is touched";

  // A hook 35 mm long, its edge live (jaws closed), drawn along y through
  // the region at x = 88 mm from 2 mm above the top to 25 mm (1 mm above
  // the region's floor on the rest) and away from its sides.
  const std::string log_before = daemon_->log();
  const Eigen::Vector3d start(0.088, 0.020, 0.060), end(0.088, 0.044, 0.060);
  for (int i = 0; i <= 240; ++i) hand.pose("hook", start + (end - start) * (i / 240.0), 0);
  const auto after = viewer.wait_surface("cut", before->sequence_number + 1, 0, kRegionTimeout);
  ASSERT_TRUE(after) << daemon_->log();
  std::optional<SurfaceSample> cut = after;
  for (int i = 0; i < 100 && cut && cut->topology_version == before->topology_version; ++i) {
    hand.pose("hook", end, 0);
    cut = viewer.wait_surface("cut", cut->sequence_number + 1, 0, 100ms);
  }
  ASSERT_TRUE(cut) << daemon_->log();
  EXPECT_GT(cut->topology_version, before->topology_version) << daemon_->log();
  EXPECT_NE(cut->region_triangles, before->region_triangles) << "the cut's faces";
  // The edge reached the bottom layer: rest faces under it are open now.
  EXPECT_LT(cut->hidden_triangles.size(), before->hidden_triangles.size());
  EXPECT_NE(daemon_->log().find("event=cut tool=hook model=cut"), std::string::npos);
  for (const double x : cut->region_positions_m) EXPECT_TRUE(std::isfinite(x));
}

}  // namespace
}  // namespace palpate
