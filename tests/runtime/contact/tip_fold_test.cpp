// A wide tip over a fold of tissue thinner than itself (docs/tools.md, "Tip
// contacts"): a 10 mm sphere arrives beyond the free end of a 4 mm plate,
// level with its mid-plane, so that the plate's end, top and bottom faces,
// is inside it. A face the axis has passed is pushed along its inward
// normal: the top face down, the bottom face up, the end face's points from
// both — nearly opposite rows at nearly the same points, which the solve
// met with forces that cancel (on the h8 liver's thin edges, the contact
// bench's wide presses summed hundreds of newtons to 5e5 N over their points
// for a tool force of tens, and flung points decimetres). Of two points
// closer than r whose pushes oppose, only the one pushed more along the
// tool's direction stays.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "support/box_job.hpp"
#include "support/sphere_tool.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;

TEST(TipOverAFold, NoTwoPointsWithinTheTipPushItFromOppositeSides) {
  testing::TempDir dir;
  // 80 × 40 × 4 mm, 5 mm cells one layer thick, clamped on x ≤ 1 mm.
  const TetMesh plate = testing::box_mesh(0.080, 0.040, 0.004, 16, 8, 1);
  const SurfaceModel model = load_surface_model(
      "plate", testing::write_clamped_compliance(plate, dir.path(), "plate", 85e3));
  const ToolGeometry g = testing::sphere_tool("finger", 0.010);
  ToolContactEngine engine(model, {g}, {}, {});
  ToolPoseInput pose;
  pose.orientation = Eigen::Quaterniond(0, 1, 0, 0);  // pointing down: +z is the model's −z
  // Beyond the plate's end (x = 80 mm), level with its mid-plane: its last
  // 2 mm are inside the tip, top and bottom faces, in one tick (a fast
  // hand, or a fold that moved). Then held there.
  pose.position_m = Vector3d(0.082, 0.020, 0.002);
  for (int tick = 1; tick <= 5; ++tick) {
    pose.sequence = static_cast<std::uint64_t>(tick);
    ASSERT_EQ(engine.check(0, pose), PoseProblem::kNone);
    ASSERT_EQ(engine.update(0, pose, 1e-3 * tick), RequestStatus::kOk) << engine.solver_message();
  }
  const std::span<const ContactPoint> points = engine.contact_points();
  ASSERT_GE(points.size(), 2u);
  double summed = 0;
  int opposed = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    summed += points[i].force_n.norm();
    for (std::size_t j = 0; j < i; ++j)
      if (points[i].normal.dot(points[j].normal) < 0 &&
          (points[i].position_m - points[j].position_m).norm() < g.tip_radius_m)
        ++opposed;
  }
  std::printf("%zu points: Σ|f| %.3f N, tool %.3f N\n", points.size(), summed,
              engine.output(0).force_n.norm());
  EXPECT_EQ(opposed, 0) << "two points closer than r push the tip from opposite sides";
  EXPECT_TRUE(std::isfinite(summed));
  EXPECT_GT(engine.output(0).force_n.norm(), 0.1);
}

}  // namespace
}  // namespace palpate
