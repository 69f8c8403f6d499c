// A tool held still feels still (issue 34; docs/tools.md, "Where a
// frictionless point pushes"): issue 34's hold (tests/support/held_still.hpp)
// on the sample organ of tests/feel/make_organ.sh, every tip of the protocol
// (spheres of 1, 3, 6 and 12.5 mm, the default capsule), friction 0 and
// 0.3, pressed at the organ's six flattest spots and held at every depth to
// the force limit: after 50 ms, |ΔF| p99 ≤ 1 mN a tick and a constant
// contact count (issue 34's target).
//
// Before frictionless points' loads were placed by the secant step, 6 of
// these 284 holds buzzed (all frictionless, up to 0.1 N a tick, the slew
// limit: the load jumped between two places on its triangle every tick, the
// count 1 ↔ 2). One still does: the 12.5 mm sphere at spot 93, 3 mm deep,
// 19 mN a tick, its load near a vertex found from one triangle, then from
// its neighbour, by turns (docs/tools.md, "Limits of the model"). The test
// holds that line: at most that one.

#include "support/held_still.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <vector>

#include "palpate/runtime/surface_model.hpp"

namespace palpate::feel::held_still {
namespace {

TEST(HeldStill, EveryTipHeldAtEveryDepthFeelsStillButOne) {
  const char* path = std::getenv("PALPATE_FEEL_MODEL");
  ASSERT_NE(path, nullptr) << "PALPATE_FEEL_MODEL: the organ of tests/feel/make_organ.sh "
                              "(CTest sets it: ctest -R feel_)";
  const SurfaceModel organ = load_surface_model("organ", path);
  const std::vector<int> spots = testing::flattest_spots(organ, 6);
  ASSERT_EQ(spots.size(), 6U);
  struct Tip {
    bool capsule;
    double radius_m;
  };
  int holds = 0;
  ::testing::Message buzzing;
  int not_still = 0;
  for (const Tip tip : {Tip{false, 0.001}, Tip{false, 0.003}, Tip{false, 0.006}, Tip{false, 0.0125},
                        Tip{true, 0.004}})
    for (const double friction : {0.0, 0.3}) {
      const ToolGeometry g = testing::held_tip(tip.capsule, tip.radius_m, friction);
      for (const int spot : spots)
        for (const testing::Hold& h : testing::hold_at_every_depth(organ, g, spot)) {
          ++holds;
          if (h.still()) continue;
          ++not_still;
          buzzing << "\n  " << g.id << " r " << tip.radius_m * 1e3 << " mm, friction " << friction
                  << ", spot " << spot << " at " << h.depth_mm << " mm: |dF| p99 " << h.step_p99_n
                  << " N, count " << h.least_count << "-" << h.most_count;
        }
    }
  EXPECT_LE(not_still, 1) << "holds not still:" << buzzing;
  // Each press went to its force limit (3 N) 1 mm at a time.
  EXPECT_GE(holds, 250);
}

}  // namespace
}  // namespace palpate::feel::held_still
