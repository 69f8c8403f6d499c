// Gesture files: parsing and units, errors with file:line:key, anchors on a
// small synthetic model, interpolation values against hand-computed ones,
// and the gesture files shipped in config/gestures.

#include "palpate/runtime/gesture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include "palpate/core/error.hpp"
#include "palpate/transport/client.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;

constexpr double kDeg = std::numbers::pi / 180;
// Values computed from a few exact operations on numbers of order 0.01–1:
// round-off stays below 1e-15 relative; 1e-12 leaves room and catches any
// formula error (the smallest expected difference is 1e-4 m).
constexpr double kTol = 1e-12;

/// An octahedron_model of radius 10 mm centred at the origin, outward triangles:
/// top (0, 0, 10 mm) and the four equator vertices move (compliance
/// vertices), the bottom one is attached. Mesh vertex ids are 100 + index.
ModelInfo octahedron_model() {
  ModelInfo m;
  m.model_id = "octahedron_model";
  m.surface.compliance_vertex_count = 5;
  const double r = 0.01;
  // drawn: 0 top, 1 +x, 2 +y, 3 -x, 4 -y, 5 bottom (fixed)
  m.surface.rest_positions_m = {0, 0, r, r, 0, 0, 0, r, 0, -r, 0, 0, 0, -r, 0, 0, 0, -r};
  m.surface.vertex_ids = {100, 101, 102, 103, 104, 105};
  for (std::uint32_t i = 0; i < 4; ++i) {
    const std::uint32_t a = 1 + i, b = 1 + (i + 1) % 4;
    m.surface.triangles.insert(m.surface.triangles.end(),
                               {0, a, b});  // upper: counter-clockwise seen from outside
    m.surface.triangles.insert(m.surface.triangles.end(), {5, b, a});  // lower
  }
  return m;
}

const DrawnSurface& view(const ModelInfo& m) { return m.surface; }

void expect_near(const Eigen::Vector3d& actual, const Eigen::Vector3d& expected,
                 double tol = kTol) {
  EXPECT_LT((actual - expected).norm(), tol)
      << "actual " << actual.transpose() << "\nexpected " << expected.transpose();
}

const char* kTwoTools = R"(name = "pinch and press"
description = "test"
anchor = "auto"

[[tool]]
id = "left"
reach_mm = 20

[[tool.keyframe]]
t = 0
position = [0, 0, 10]
jaw = 40

[[tool.keyframe]]
t = 1.0
position = [0, 0, -6]
jaw = 0

[[tool.keyframe]]
t = 2.0
tilt = [0, 40]

[[tool]]
id = "right"
offset_mm = [14, 0]

[[tool.keyframe]]
t = 0.5
position = [1, 2, 3]
roll = 90
)";

TEST(Gesture, ParsesKeyframesInSIUnitsAndCarriesKeysOver) {
  const Gesture g = parse_gesture(kTwoTools, "two.toml");
  EXPECT_EQ(g.name, "pinch and press");
  EXPECT_EQ(g.description, "test");
  EXPECT_EQ(g.anchor_vertex_id, -1);
  ASSERT_EQ(g.tools.size(), 2u);
  const GestureTool& left = g.tools[0];
  EXPECT_EQ(left.id, "left");
  EXPECT_NEAR(left.reach_m, 0.020, kTol);
  ASSERT_EQ(left.keyframes.size(), 3u);
  EXPECT_EQ(left.keyframes[0].line, 9);
  expect_near(left.keyframes[0].tip_m, {0, 0, 0.010});
  EXPECT_NEAR(left.keyframes[0].jaw_angle_rad, 40 * kDeg, kTol);
  expect_near(left.keyframes[1].tip_m, {0, 0, -0.006});
  // The third keyframe gives only t and tilt: position and jaw carry over.
  EXPECT_EQ(left.keyframes[2].time_s, 2.0);
  expect_near(left.keyframes[2].tip_m, {0, 0, -0.006});
  EXPECT_EQ(left.keyframes[2].jaw_angle_rad, 0);
  EXPECT_NEAR(left.keyframes[2].tilt_rad[1], 40 * kDeg, kTol);
  const GestureTool& right = g.tools[1];
  EXPECT_NEAR(right.reach_m, 0.019, kTol);  // palpated's default tool
  EXPECT_NEAR(right.offset_m[0], 0.014, kTol);
  EXPECT_NEAR(right.keyframes[0].roll_rad, 90 * kDeg, kTol);
  EXPECT_EQ(g.duration_s(), 2.0);
}

TEST(Gesture, NameDefaultsToTheFileStemAndAnchorMayBeAVertexId) {
  testing::TempDir dir;
  const auto path = dir / "my-press.toml";
  std::ofstream(path)
      << "anchor = 102\n[[tool]]\nid = \"left\"\n[[tool.keyframe]]\nt = 0\nposition = [0, 0, 5]\n";
  const Gesture g = read_gesture_file(path);
  EXPECT_EQ(g.name, "my-press");
  EXPECT_EQ(g.anchor_vertex_id, 102);
  EXPECT_EQ(g.duration_s(), 0);
}

TEST(Gesture, ErrorsNameTheFileLineAndKey) {
  auto parse = [](const std::string& text) { return [text] { parse_gesture(text, "g.toml"); }; };
  const std::string head =
      "[[tool]]\nid = \"left\"\n[[tool.keyframe]]\nt = 0\nposition = [0, 0, 5]\n";
  expect_error<InputError>(parse(head + "speed = 3\n"),
                           {"g.toml:6:", "tool.keyframe.speed", "unknown key", "position", "jaw"});
  expect_error<InputError>(parse(head + "[[tool.keyframe]]\nt = 0\n"),
                           {"g.toml:7:", "tool.keyframe.t", "not after", "line 3", "increasing"});
  expect_error<InputError>(parse(head + "[[tool.keyframe]]\nt = 1\njaw = 190\n"),
                           {"g.toml:8:", "tool.keyframe.jaw", "190", "[0, 180)"});
  expect_error<InputError>(parse(head + "[[tool.keyframe]]\nt = 1\ntilt = [10]\n"),
                           {"g.toml:8:", "tool.keyframe.tilt", "[about x, about y]"});
  expect_error<InputError>(parse(head + "[[tool.keyframe]]\nposition = [0, 0, 1]\n"),
                           {"g.toml:6:", "needs t"});
  expect_error<InputError>(parse(head + "[[tool.keyframe]]\nt = 1\nposition = [0, \"a\", 1]\n"),
                           {"g.toml:8:", "tool.keyframe.position", "expected a number"});
  expect_error<InputError>(parse("[[tool]]\nid = \"left\"\n[[tool.keyframe]]\nt = 0\n"),
                           {"g.toml:3:", "first keyframe", "position"});
  expect_error<InputError>(parse("[[tool]]\nid = \"left\"\n"), {"g.toml:1:", "no keyframe"});
  expect_error<InputError>(parse("[[tool]]\nid = \"left hand\"\n"),
                           {"g.toml:2:", "tool.id", "A-Z"});
  expect_error<InputError>(parse(head + head), {"g.toml:7:", "tool.id", "given twice"});
  expect_error<InputError>(parse("anchor = \"top\"\n" + head), {"g.toml:1:", "anchor", "auto"});
  expect_error<InputError>(parse("anchor = -3\n" + head), {"g.toml:1:", "anchor", "≥ 0"});
  expect_error<InputError>(parse("name = \"x\"\n"), {"g.toml", "no tool", "[[tool]]"});
  expect_error<InputError>(parse("[tool]\nid = \"left\"\n"), {"g.toml:1:", "array of tables"});
  expect_error<InputError>(parse("[[tool]]\nid = \"left\"\nreach_mm = 0\n"),
                           {"g.toml:3:", "tool.reach_mm", "positive"});
  expect_error<InputError>(parse("[[tool]\n"), {"g.toml:1:", "not valid TOML"});
  expect_error<InputError>([] { read_gesture_file("/nonexistent/press.toml"); },
                           {"/nonexistent/press.toml", "no such file"});
}

TEST(Gesture, OutwardNormalsAreAreaWeighted) {
  const ModelInfo m = octahedron_model();
  const DrawnSurface& s = view(m);
  expect_near(outward_normal(s, 0), {0, 0, 1});
  expect_near(outward_normal(s, 1), {1, 0, 0});
  // Raise +x to (r, 0, r/2): the faces around the top are no longer alike.
  // The sum of their (b − a) × (c − a) around a closed ring p_1..p_4 is
  // Σ p_i × p_i+1 (the apex cancels): here (−2rh, 0, 4r²) with h = r/2,
  // so the normal is (−1, 0, 4)/√17, leaning away from the raised side.
  ModelInfo raised = m;
  raised.surface.rest_positions_m[5] = 0.005;
  expect_near(outward_normal(view(raised), 0), Eigen::Vector3d(-1, 0, 4) / std::sqrt(17.0));

  ModelInfo lonely = m;
  lonely.surface.triangles.clear();
  expect_error<InputError>([&] { outward_normal(view(lonely), 0); },
                           {"vertex 100", "no surface triangle"});
}

TEST(Gesture, AutoAnchorIsTheFreeVertexFarthestFromTheAttachment) {
  const ModelInfo m = octahedron_model();
  const AnchorFrame a = auto_anchor(view(m));
  EXPECT_EQ(a.drawn_index, 0);
  EXPECT_EQ(a.vertex_id, 100u);
  expect_near(a.origin_m, {0, 0, 0.01});
  expect_near(a.normal, {0, 0, 1});
  expect_near(a.x, {1, 0, 0});  // the model's x projected on the tangent plane
  expect_near(a.y, {0, 1, 0});

  // Mirror it (z → −z, windings reversed to stay outward): the attached
  // vertex is now at the top, and the free one farthest from it at the bottom.
  ModelInfo flipped = m;
  for (std::size_t i = 2; i < flipped.surface.rest_positions_m.size(); i += 3)
    flipped.surface.rest_positions_m[i] = -flipped.surface.rest_positions_m[i];
  for (std::size_t t = 0; t < flipped.surface.triangles.size(); t += 3)
    std::swap(flipped.surface.triangles[t + 1], flipped.surface.triangles[t + 2]);
  const AnchorFrame b = auto_anchor(view(flipped));
  EXPECT_EQ(b.drawn_index, 0);
  expect_near(b.origin_m, {0, 0, -0.01});
  expect_near(b.normal, {0, 0, -1});

  // No fixed vertex at all: farthest from the centroid (all equal here: the lowest index).
  ModelInfo free = m;
  free.surface.compliance_vertex_count = 6;
  EXPECT_EQ(auto_anchor(view(free)).drawn_index, 0);

  ModelInfo empty = m;
  empty.surface.compliance_vertex_count = 0;
  expect_error<InputError>([&] { auto_anchor(view(empty)); }, {"0 compliance vertices"});
}

TEST(Gesture, SecondToolIsAnchoredAtTheNearestVertexToTheOffset) {
  const ModelInfo m = octahedron_model();
  const Gesture g = parse_gesture(kTwoTools, "two.toml");
  const auto anchors = place_gesture(g, view(m));
  ASSERT_EQ(anchors.size(), 2u);
  EXPECT_EQ(anchors[0].vertex_id, 100u);
  // top + 14 mm along x = (14, 0, 10) mm: nearest is +x (10.8 mm) rather than the top (14 mm).
  EXPECT_EQ(anchors[1].vertex_id, 101u);
  expect_near(anchors[1].normal, {1, 0, 0});
  // The first anchor's x is along this normal: the model's y is used instead.
  expect_near(anchors[1].x, {0, 1, 0});
  expect_near(anchors[1].y, {0, 0, 1});

  Gesture fixed = g;
  fixed.anchor_vertex_id = 105;  // the attached bottom vertex
  expect_error<InputError>([&] { place_gesture(fixed, view(m)); },
                           {"two.toml", "anchor 105", "not a compliance vertex"});
  fixed.anchor_vertex_id = 102;
  EXPECT_EQ(place_gesture(fixed, view(m))[0].vertex_id, 102u);
}

// A served cut region covers some of the rest's triangles (the stream's
// hidden_triangles); their vertices are its interface Γ, which moves with
// the region and is released when it is cut: no anchor goes there. Here the
// region covers the two upper triangles at +x (top, +x, ±y): the top, +x,
// +y and −y vertices are Γ, and only −x (drawn 3) is left to anchor on.
TEST(Gesture, AnchorsAvoidTheCutRegionsInterface) {
  const ModelInfo m = octahedron_model();
  // Upper triangles i = 0 (0, 1, 2) and 3 (0, 4, 1): drawn triangles 0 and 6.
  const std::vector<std::uint32_t> covered = {0, 6};
  const Gesture g = parse_gesture(kTwoTools, "two.toml");

  // Without the region: auto is the top (100), the offset tool +x (101).
  const auto plain = place_gesture(g, view(m));
  EXPECT_EQ(plain[0].vertex_id, 100u);
  EXPECT_EQ(plain[1].vertex_id, 101u);
  // With it: both land on −x, the only vertex off Γ; its normal is the
  // area-weighted one of every triangle around it, covered or not.
  const auto cut = place_gesture(g, view(m), covered);
  EXPECT_EQ(cut[0].vertex_id, 103u);
  EXPECT_EQ(cut[1].vertex_id, 103u);
  expect_near(cut[0].normal, {-1, 0, 0});

  // A point anchor: the vertex off Γ nearest to it. (9, 1, 0) mm is
  // nearest to +x (101), which is on Γ once the region covers it.
  Gesture at_point = g;
  at_point.anchor_point_m = Eigen::Vector3d(0.009, 0.001, 0);
  EXPECT_EQ(place_gesture(at_point, view(m))[0].vertex_id, 101u);
  EXPECT_EQ(place_gesture(at_point, view(m), covered)[0].vertex_id, 103u);

  // An explicit vertex on Γ is refused with the reason; a covered
  // triangle that is not the model's is refused too.
  Gesture on_gamma = g;
  on_gamma.anchor_vertex_id = 101;
  expect_error<InputError>([&] { place_gesture(on_gamma, view(m), covered); },
                           {"two.toml", "anchor 101", "interface of the model's cut region"});
  const std::vector<std::uint32_t> bad = {8};
  expect_error<InputError>([&] { place_gesture(g, view(m), bad); },
                           {"covered triangle 8", "there are 8"});
  // Every compliance vertex on Γ: nowhere to anchor.
  const std::vector<std::uint32_t> all = {0, 2, 4, 6};
  expect_error<InputError>([&] { place_gesture(g, view(m), all); },
                           {"every compliance vertex is on the cut region's interface"});
}

TEST(Gesture, AnchorMayBeAPointInMillimetres) {
  const Gesture g = parse_gesture(
      "anchor = [1, -2.5, 30]\n[[tool]]\nid = \"left\"\n[[tool.keyframe]]\nt = 0\n"
      "position = [0, 0, 5]\n",
      "point.toml");
  ASSERT_TRUE(g.anchor_point_m.has_value());
  expect_near(*g.anchor_point_m, {0.001, -0.0025, 0.03});
  EXPECT_EQ(g.anchor_vertex_id, -1);
  // Near the top of the octahedron_model (0, 0, 10) mm: the top vertex.
  EXPECT_EQ(place_gesture(g, view(octahedron_model()))[0].vertex_id, 100u);
  expect_error<InputError>(
      [] {
        parse_gesture(
            "anchor = [1, 2]\n[[tool]]\nid = \"left\"\n[[tool.keyframe]]\nt = 0\n"
            "position = [0, 0, 5]\n",
            "g.toml");
      },
      {"g.toml:1", "anchor"});
}

TEST(Gesture, KeyframeOrientationPointsTheShaftIntoTheOrganAndTilts) {
  const Eigen::Quaterniond straight = keyframe_orientation({0, 0}, 0);
  expect_near(straight * Eigen::Vector3d::UnitZ(), {0, 0, -1});
  expect_near(straight * Eigen::Vector3d::UnitX(), {1, 0, 0});  // jaws open in the x-z plane
  const Eigen::Quaterniond rolled = keyframe_orientation({0, 0}, 90 * kDeg);
  expect_near(rolled * Eigen::Vector3d::UnitZ(), {0, 0, -1});
  expect_near(rolled * Eigen::Vector3d::UnitX(), {0, -1, 0});
  // 30° about x: Rx(θ)(0, 0, −1) = (0, sin θ, −cos θ).
  expect_near(keyframe_orientation({30 * kDeg, 0}, 0) * Eigen::Vector3d::UnitZ(),
              {0, std::sin(30 * kDeg), -std::cos(30 * kDeg)});
  // 20° about y: Ry(θ)(0, 0, −1) = (−sin θ, 0, −cos θ).
  expect_near(keyframe_orientation({0, 20 * kDeg}, 0) * Eigen::Vector3d::UnitZ(),
              {-std::sin(20 * kDeg), 0, -std::cos(20 * kDeg)});
}

TEST(Gesture, SamplesInterpolateLinearlyAndSlerp) {
  const ModelInfo m = octahedron_model();
  const Gesture g = parse_gesture(kTwoTools, "two.toml");
  const GesturePlayer player(g, place_gesture(g, view(m)));
  ASSERT_EQ(player.tool_count(), 2);
  EXPECT_EQ(player.tool_id(1), "right");
  EXPECT_EQ(player.duration_s(), 2.0);

  // Left at t = 0.25: tip z = 10 − 16 · 0.25 = 6 mm above the top; jaw 40 − 40 · 0.25 = 30°;
  // the shaft along −z, so the hinge is reach = 20 mm above the tip.
  const GesturePose p = player.sample(0, 0.25);
  expect_near(p.tip_m, {0, 0, 0.010 + 0.006});
  expect_near(p.hinge_m, {0, 0, 0.010 + 0.006 + 0.020});
  EXPECT_NEAR(p.jaw_angle_rad, 30 * kDeg, kTol);
  expect_near(p.orientation * Eigen::Vector3d::UnitZ(), {0, 0, -1});

  // t = 1.5: half way from tilt [0, 0] to [0, 40]: slerp gives 20° about y,
  // pivoting on the tip, which stays 6 mm below the top.
  const GesturePose q = player.sample(0, 1.5);
  const Eigen::Vector3d shaft(-std::sin(20 * kDeg), 0, -std::cos(20 * kDeg));
  expect_near(q.orientation * Eigen::Vector3d::UnitZ(), shaft);
  expect_near(q.tip_m, {0, 0, 0.010 - 0.006});
  expect_near(q.hinge_m, q.tip_m - 0.020 * shaft);
  EXPECT_NEAR(q.orientation.norm(), 1, kTol);

  // Before the first and after the last keyframe a tool holds still.
  expect_near(player.sample(0, -1).tip_m, {0, 0, 0.020});
  expect_near(player.sample(0, 5).tip_m, {0, 0, 0.004});
  // Right: one keyframe at 0.5 s, in its own anchor frame at +x
  // (x = model y, y = model z, z = model x): tip (1, 2, 3) mm → model (10 + 3, 1, 2) mm.
  for (double t : {0.0, 0.5, 2.0}) expect_near(player.sample(1, t).tip_m, {0.013, 0.001, 0.002});
  // Its shaft points into the organ along −x; with roll 90° the jaws open along −y of the anchor
  // (model −z).
  const GesturePose r = player.sample(1, 1.0);
  expect_near(r.orientation * Eigen::Vector3d::UnitZ(), {-1, 0, 0});
  expect_near(r.orientation * Eigen::Vector3d::UnitX(), {0, 0, -1});
  expect_near(r.hinge_m, {0.013 + 0.019, 0.001, 0.002});
}

TEST(Gesture, TheShippedGesturesReadAndPlaceOnAnyOrgan) {
  const auto dir = std::filesystem::path(PALPATE_SOURCE_DIR) / "config" / "gestures";
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  const ModelInfo m = octahedron_model();
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".toml") continue;
    SCOPED_TRACE(entry.path().string());
    const Gesture g = read_gesture_file(entry.path());
    const GesturePlayer player(g, place_gesture(g, view(m)));
    EXPECT_GT(player.duration_s(), 0);
    for (int tool = 0; tool < player.tool_count(); ++tool)
      for (double t = 0; t <= player.duration_s(); t += 0.01) {
        const GesturePose p = player.sample(tool, t);
        EXPECT_TRUE(p.hinge_m.allFinite());
        EXPECT_LE(p.jaw_angle_rad, 75 * kDeg);  // palpated's default max_jaw_angle
      }
    ++count;
  }
  EXPECT_GE(count, 5);
}

}  // namespace
}  // namespace palpate
