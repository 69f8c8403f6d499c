// What the jaws may hold (lib/runtime/src/jaw_grasp.hpp): rows kept
// independent with a margin, and the region between the jaws.

#include "../../lib/runtime/src/jaw_grasp.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>

namespace palpate::detail {
namespace {

using Eigen::Vector3d;

bool add(IndependentRows& rows, std::array<int, 3> vertices, std::array<double, 3> weights,
         double threshold = 0.5) {
  return rows.add(vertices, weights, threshold);
}

TEST(IndependentRows, AtMostAsManyRowsAsTheirVerticesCanTake) {
  IndependentRows rows(8);
  // Three points of one triangle, well apart: independent.
  EXPECT_TRUE(add(rows, {0, 1, 2}, {0.8, 0.1, 0.1}));
  EXPECT_TRUE(add(rows, {0, 1, 2}, {0.1, 0.8, 0.1}));
  EXPECT_TRUE(add(rows, {0, 1, 2}, {0.1, 0.1, 0.8}));
  // A fourth on the same three vertices is in their span, whatever its weights.
  EXPECT_FALSE(add(rows, {0, 1, 2}, {1.0 / 3, 1.0 / 3, 1.0 / 3}, 1e-9));
  EXPECT_FALSE(add(rows, {2, 0, 1}, {1, 0, 0}, 1e-9));
  EXPECT_EQ(rows.size(), 3);
  // A neighbouring triangle brings one more vertex, so one more row.
  EXPECT_TRUE(add(rows, {1, 2, 3}, {0.1, 0.1, 0.8}));
  EXPECT_FALSE(add(rows, {1, 2, 3}, {0.2, 0.2, 0.6}, 1e-9));
  EXPECT_EQ(rows.size(), 4);
}

TEST(IndependentRows, TheThresholdIsTheNormLeftOutsideTheKeptRows) {
  // (1, 0) kept; (0.9, 0.1) has 0.1 of its norm outside it.
  IndependentRows rows(4);
  EXPECT_TRUE(add(rows, {0, -1, -1}, {1, 0, 0}));
  EXPECT_FALSE(add(rows, {0, 1, -1}, {0.9, 0.1, 0}, 0.1 + 1e-9));
  EXPECT_TRUE(add(rows, {0, 1, -1}, {0.9, 0.1, 0}, 0.1 - 1e-9));
  EXPECT_EQ(rows.size(), 2);
  rows.clear();
  EXPECT_EQ(rows.size(), 0);
  EXPECT_TRUE(add(rows, {0, 1, -1}, {0.9, 0.1, 0}));
}

TEST(IndependentRows, FixedVerticesAreNoUnknownsAndCapacityIsKept) {
  IndependentRows rows(2);
  // A point whose weight is all on fixed vertices (−1) moves nothing.
  EXPECT_FALSE(add(rows, {-1, -1, -1}, {0.5, 0.25, 0.25}, 1e-9));
  // Only the movable share counts: 0.3 on vertex 4.
  EXPECT_FALSE(add(rows, {4, -1, -1}, {0.3, 0.7, 0}, 0.5));
  EXPECT_TRUE(add(rows, {4, -1, -1}, {0.3, 0.7, 0}, 0.25));
  EXPECT_TRUE(add(rows, {5, -1, -1}, {1, 0, 0}));
  EXPECT_FALSE(add(rows, {6, -1, -1}, {1, 0, 0})) << "full";
}

TEST(JawGrasp, BetweenTheJawsIsTheWedgeOfTheirFacesWidenedByTheTipsRadius) {
  ToolGeometry g;  // jaws 15 × 5 mm, r = 4 mm
  const JawsAtClosing jaws{Vector3d(0, 0, 0), Eigen::Matrix3d::Identity(), &g, 0.0};
  const double open = 40 * M_PI / 180, slope = std::tan(open / 2);
  EXPECT_TRUE(JawGrasp::between(jaws, Vector3d(10e-3 * slope + 3.9e-3, 0, 10e-3), open));
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(10e-3 * slope + 4.1e-3, 0, 10e-3), open));
  EXPECT_TRUE(JawGrasp::between(jaws, Vector3d(0, 2.5e-3 + 3.9e-3, 10e-3), open));
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(0, 2.5e-3 + 4.1e-3, 10e-3), open));
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(0, 0, -1e-4), open)) << "behind the hinge";
  EXPECT_FALSE(JawGrasp::between(jaws, Vector3d(0, 0, 16e-3), open)) << "past the jaws";
  EXPECT_TRUE(JawGrasp::between(jaws, Vector3d(0, 0, 16e-3), open, 4e-3)) << "their rounded end";
  ToolGeometry probe;
  probe.jaw_length_m = 0;
  const JawsAtClosing none{Vector3d::Zero(), Eigen::Matrix3d::Identity(), &probe, 0.0};
  EXPECT_FALSE(JawGrasp::between(none, Vector3d(0, 0, 1e-3), open)) << "a probe never grasps";
}

}  // namespace
}  // namespace palpate::detail
