#include "palpate/runtime/gesture.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "palpate/core/detail/toml_reader.hpp"
#include "palpate/core/error.hpp"
#include "palpate/core/ids.hpp"
#include "palpate/core/units.hpp"

namespace palpate {

namespace {

using detail::TomlReader;

/// A keyframe key that is a pair of numbers [a, b].
Eigen::Vector2d vec2(const TomlReader& r, const toml::node& node, const std::string& key,
                     const char* what) {
  const auto* arr = node.as_array();
  if (!arr || arr->size() != 2) r.fail(&node, key, fmt::format("expected {}", what));
  return {r.number((*arr)[0], key), r.number((*arr)[1], key)};
}

double finite(const TomlReader& r, const toml::node& node, const std::string& key, double value,
              const char* accepted) {
  if (!std::isfinite(value))
    r.fail(&node, key, fmt::format("{} is not finite; {}", value, accepted));
  return value;
}

GestureTool read_tool(const TomlReader& r, const toml::table& t, std::size_t index) {
  const std::string where = "tool";
  r.only_keys(t, where, {"id", "reach_mm", "offset_mm", "keyframe"});
  GestureTool tool;
  const toml::node* id = t.get("id");
  if (!id)
    r.fail(&t, where,
           fmt::format("tool {} needs an id (one of palpated's tools, e.g. \"left\")", index + 1));
  tool.id = r.string(*id, "tool.id");
  if (!is_valid_id(tool.id))
    r.fail(id, "tool.id",
           fmt::format("'{}': expected 1 to 63 characters among A-Z a-z 0-9 _ - .", tool.id));
  if (const toml::node* n = t.get("reach_mm")) {
    const double reach = r.number(*n, "tool.reach_mm");
    if (!(reach > 0) || !std::isfinite(reach))
      r.fail(n, "tool.reach_mm",
             fmt::format("{} mm: expected a positive length (hinge to tip point, e.g. 19)", reach));
    tool.reach_m = millimetres(reach);
  }
  if (const toml::node* n = t.get("offset_mm")) {
    const Eigen::Vector2d offset = vec2(r, *n, "tool.offset_mm", "[dx, dy] in mm");
    if (!offset.allFinite()) r.fail(n, "tool.offset_mm", "expected finite numbers [dx, dy] in mm");
    tool.offset_m = offset * 1e-3;
  }
  const toml::node* frames = t.get("keyframe");
  if (!frames)
    r.fail(&t, where,
           fmt::format("tool '{}' has no keyframe: add [[tool.keyframe]] tables (t, position, ...)",
                       tool.id));
  const GestureKeyframe* previous = nullptr;
  r.each_table(*frames, "tool.keyframe", [&](const toml::table& k) {
    r.only_keys(k, "tool.keyframe", {"t", "position", "tilt", "roll", "jaw"});
    // Every key but t carries over from the previous keyframe.
    GestureKeyframe frame = previous ? *previous : GestureKeyframe{};
    frame.line = static_cast<int>(k.source().begin.line);
    const toml::node* time = k.get("t");
    if (!time) r.fail(&k, "tool.keyframe", "needs t, its time in s from the start of the gesture");
    frame.time_s = finite(r, *time, "tool.keyframe.t", r.number(*time, "tool.keyframe.t"),
                          "expected a time in s");
    if (!(frame.time_s >= 0))
      r.fail(time, "tool.keyframe.t", fmt::format("{} s: expected a time ≥ 0", frame.time_s));
    if (previous && !(frame.time_s > previous->time_s))
      r.fail(time, "tool.keyframe.t",
             fmt::format("{} s is not after the previous keyframe's {} s (line {}); the keyframes "
                         "of a tool must be in increasing time",
                         frame.time_s, previous->time_s, previous->line));
    if (const toml::node* n = k.get("position")) {
      const Eigen::Vector3d p = r.vec3(*n, "tool.keyframe.position");
      if (!p.allFinite())
        r.fail(n, "tool.keyframe.position", "expected finite numbers [x, y, z] in mm");
      frame.tip_m = p * 1e-3;
    } else if (!previous) {
      r.fail(&k, "tool.keyframe",
             "the first keyframe of a tool needs a position [x, y, z] (mm, tip point in the "
             "anchor frame: z along the outward normal)");
    }
    if (const toml::node* n = k.get("tilt")) {
      const Eigen::Vector2d tilt =
          vec2(r, *n, "tool.keyframe.tilt", "[about x, about y] in degrees");
      if (!(tilt.cwiseAbs().maxCoeff() <= 90))
        r.fail(n, "tool.keyframe.tilt",
               fmt::format("[{}, {}]: expected angles in [-90, 90] degrees", tilt[0], tilt[1]));
      frame.tilt_rad = {degrees(tilt[0]), degrees(tilt[1])};
    }
    if (const toml::node* n = k.get("roll")) {
      const double roll = r.number(*n, "tool.keyframe.roll");
      if (!(std::abs(roll) <= 360))
        r.fail(n, "tool.keyframe.roll",
               fmt::format("{}: expected an angle in [-360, 360] degrees", roll));
      frame.roll_rad = degrees(roll);
    }
    if (const toml::node* n = k.get("jaw")) {
      const double jaw = r.number(*n, "tool.keyframe.jaw");
      if (!(jaw >= 0 && jaw < 180))
        r.fail(n, "tool.keyframe.jaw",
               fmt::format("{}: expected a jaw opening in [0, 180) degrees (palpated refuses poses "
                           "beyond its tool's max_jaw_angle, 75 by default)",
                           jaw));
      frame.jaw_angle_rad = degrees(jaw);
    }
    tool.keyframes.push_back(frame);
    previous = &tool.keyframes.back();
  });
  if (tool.keyframes.empty())
    r.fail(frames, "tool.keyframe", fmt::format("tool '{}' has no keyframe", tool.id));
  return tool;
}

Gesture read(const toml::table& root, const std::string& source) {
  const TomlReader r(source);
  r.only_keys(root, "", {"name", "description", "anchor", "tool"});
  Gesture g;
  g.source = source;
  g.name = std::filesystem::path(source).stem().string();
  if (const toml::node* n = root.get("name")) g.name = r.string(*n, "name");
  if (const toml::node* n = root.get("description")) g.description = r.string(*n, "description");
  if (const toml::node* n = root.get("anchor")) {
    if (n->is_string()) {
      if (r.string(*n, "anchor") != "auto")
        r.fail(n, "anchor",
               fmt::format(
                   "'{}': expected \"auto\", a mesh vertex id (an integer) or a point [x, y, z] "
                   "in mm",
                   r.string(*n, "anchor")));
    } else if (const auto id = n->value_exact<std::int64_t>()) {
      if (*id < 0 || *id > std::numeric_limits<std::uint32_t>::max())
        r.fail(n, "anchor", fmt::format("{}: expected a mesh vertex id ≥ 0, or \"auto\"", *id));
      g.anchor_vertex_id = *id;
    } else if (n->is_array()) {
      const Eigen::Vector3d p = r.vec3(*n, "anchor");
      if (!p.allFinite()) r.fail(n, "anchor", "expected finite numbers [x, y, z] in mm");
      g.anchor_point_m = p * 1e-3;
    } else {
      r.fail(n, "anchor",
             "expected \"auto\", a mesh vertex id (an integer) or a point [x, y, z] in mm");
    }
  }
  const toml::node* tools = root.get("tool");
  if (!tools)
    r.fail(
        nullptr, "tool",
        "no tool: a gesture needs at least one [[tool]] table (id, then [[tool.keyframe]] tables)");
  r.each_table(*tools, "tool", [&](const toml::table& t) {
    GestureTool tool = read_tool(r, t, g.tools.size());
    for (const auto& other : g.tools)
      if (other.id == tool.id)
        r.fail(t.get("id"), "tool.id",
               fmt::format("tool '{}' is given twice; one [[tool]] table per tool", tool.id));
    g.tools.push_back(std::move(tool));
  });
  if (g.tools.empty())
    r.fail(tools, "tool", "no tool: a gesture needs at least one [[tool]] table");
  return g;
}

double squared_distance(const DrawnSurface& s, int a, const Eigen::Vector3d& p) {
  return (s.rest_position(a) - p).squaredNorm();
}

/// A model whose every compliance vertex is on the cut region's interface
/// offers no anchor off it.
[[noreturn]] void refuse_every_vertex_on_interface() {
  throw InputError(
      "model description: every compliance vertex is on the cut region's "
      "interface; no place to anchor a gesture");
}

/// The compliance vertex off the interface nearest to @p p (ties: the lowest index).
int nearest_compliance_vertex(const DrawnSurface& s, const std::vector<bool>& on_interface,
                              const Eigen::Vector3d& p) {
  int best = -1;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (int v = 0; v < s.compliance_vertex_count; ++v)
    if (const double d2 = squared_distance(s, v, p);
        !on_interface[static_cast<std::size_t>(v)] && d2 < best_d2) {
      best = v;
      best_d2 = d2;
    }
  if (best < 0) refuse_every_vertex_on_interface();
  return best;
}

/// Which drawn vertices are on a served cut region's interface Γ: the
/// vertices of the rest's triangles the region covers.
std::vector<bool> interface_vertices(const DrawnSurface& s,
                                     std::span<const std::uint32_t> covered_triangles) {
  std::vector<bool> on(static_cast<std::size_t>(s.vertex_count()), false);
  for (const std::uint32_t t : covered_triangles) {
    if (t >= static_cast<std::uint32_t>(s.triangle_count()))
      throw InputError(fmt::format(
          "cut region: covered triangle {} is not a triangle of the model (there are {})", t,
          s.triangle_count()));
    for (int c = 0; c < 3; ++c) on[s.triangles[3 * static_cast<std::size_t>(t) + c]] = true;
  }
  return on;
}

void check_surface(const DrawnSurface& s) {
  const auto drawn = s.vertex_ids.size();
  if (s.compliance_vertex_count <= 0 ||
      static_cast<std::size_t>(s.compliance_vertex_count) > drawn ||
      s.rest_positions_m.size() != 3 * drawn || s.triangles.size() % 3 != 0)
    throw InputError(fmt::format(
        "model description: {} compliance vertices, {} drawn vertices, {} rest coordinates, {} "
        "triangle indices; expected at least one compliance vertex, 3 coordinates per drawn "
        "vertex and 3 indices per triangle",
        s.compliance_vertex_count, drawn, s.rest_positions_m.size(), s.triangles.size()));
  for (const std::uint32_t t : s.triangles)
    if (t >= drawn)
      throw InputError(fmt::format(
          "model description: triangle index {} is not a drawn vertex (there are {})", t, drawn));
}

}  // namespace

double Gesture::duration_s() const {
  double d = 0;
  for (const auto& t : tools)
    if (!t.keyframes.empty()) d = std::max(d, t.keyframes.back().time_s);
  return d;
}

Gesture read_gesture_file(const std::filesystem::path& file) {
  return read(detail::parse_toml_file(file), file.string());
}

Gesture parse_gesture(std::string_view toml_text, const std::string& source) {
  try {
    return read(toml::parse(toml_text, source), source);
  } catch (const toml::parse_error& e) {
    throw InputError(fmt::format("{}:{}:{}: not valid TOML: {}", source, e.source().begin.line,
                                 e.source().begin.column, e.description()));
  }
}

Eigen::Matrix3d AnchorFrame::rotation() const {
  Eigen::Matrix3d r;
  r << x, y, normal;
  return r;
}

Eigen::Vector3d outward_normal(const DrawnSurface& s, int v) {
  const Eigen::Vector3d n = vertex_normals(s).row(v).transpose();
  if (!(n.squaredNorm() > 0))
    throw InputError(fmt::format(
        "vertex {} (drawn vertex {}) belongs to no surface triangle of non-zero area: no normal "
        "to anchor a gesture on",
        s.vertex_ids[static_cast<std::size_t>(v)], v));
  return n;
}

AnchorFrame anchor_frame(const DrawnSurface& s, int v, const Eigen::Vector3d& x_hint) {
  AnchorFrame f;
  f.drawn_index = v;
  f.vertex_id = s.vertex_ids[static_cast<std::size_t>(v)];
  f.origin_m = s.rest_position(v);
  f.normal = outward_normal(s, v);
  Eigen::Vector3d hint = x_hint.normalized();
  // Within 10° of the normal the projection is too short to trust.
  if (std::abs(hint.dot(f.normal)) > std::cos(degrees(10))) hint = Eigen::Vector3d::UnitY();
  if (std::abs(hint.dot(f.normal)) > std::cos(degrees(10))) hint = Eigen::Vector3d::UnitX();
  f.x = (hint - hint.dot(f.normal) * f.normal).normalized();
  f.y = f.normal.cross(f.x);
  return f;
}

namespace {

/// auto_anchor() among the compliance vertices off the interface.
AnchorFrame auto_anchor_off(const DrawnSurface& s, const std::vector<bool>& on_interface) {
  const int n = s.compliance_vertex_count;
  const int drawn = static_cast<int>(s.vertex_ids.size());
  int best = -1;
  double best_score = -1;
  const auto eligible = [&](int v) { return !on_interface[static_cast<std::size_t>(v)]; };
  if (drawn > n) {
    // Largest distance to the nearest fixed vertex: the freest place.
    for (int v = 0; v < n; ++v) {
      if (!eligible(v)) continue;
      double nearest = std::numeric_limits<double>::infinity();
      const Eigen::Vector3d p = s.rest_position(v);
      for (int f = n; f < drawn; ++f) nearest = std::min(nearest, squared_distance(s, f, p));
      if (nearest > best_score) {
        best_score = nearest;
        best = v;
      }
    }
  } else {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int v = 0; v < drawn; ++v) centroid += s.rest_position(v);
    centroid /= drawn;
    for (int v = 0; v < n; ++v)
      if (const double d2 = squared_distance(s, v, centroid); eligible(v) && d2 > best_score) {
        best_score = d2;
        best = v;
      }
  }
  if (best < 0) refuse_every_vertex_on_interface();
  return anchor_frame(s, best);
}

}  // namespace

AnchorFrame auto_anchor(const DrawnSurface& s) {
  check_surface(s);
  return auto_anchor_off(s, std::vector<bool>(static_cast<std::size_t>(s.vertex_count()), false));
}

std::vector<AnchorFrame> place_gesture(const Gesture& gesture, const DrawnSurface& s,
                                       std::span<const std::uint32_t> covered_triangles) {
  check_surface(s);
  // A vertex the region shares with the rest moves with the region's push
  // and loses its rest triangles' support when the region is cut: tools
  // are anchored on the rest proper. Normals still take every triangle of
  // the description, the covered ones included (anchor_frame()).
  const std::vector<bool> on_interface = interface_vertices(s, covered_triangles);
  AnchorFrame base;
  if (gesture.anchor_point_m) {
    base = anchor_frame(s, nearest_compliance_vertex(s, on_interface, *gesture.anchor_point_m));
  } else if (gesture.anchor_vertex_id < 0) {
    base = auto_anchor_off(s, on_interface);
  } else {
    const auto id = static_cast<std::uint32_t>(gesture.anchor_vertex_id);
    const auto end = s.vertex_ids.begin() + s.compliance_vertex_count;
    const auto it = std::find(s.vertex_ids.begin(), end, id);
    if (it == end)
      throw InputError(fmt::format(
          "{}: anchor {}: not a compliance vertex of this model (a free surface vertex: "
          "ModelDescription.vertex_ids, first compliance_vertex_count); or use anchor = \"auto\"",
          gesture.source, id));
    const auto v = static_cast<int>(it - s.vertex_ids.begin());
    if (on_interface[static_cast<std::size_t>(v)])
      throw InputError(fmt::format(
          "{}: anchor {}: on the interface of the model's cut region (a vertex the region shares "
          "with the rest); anchor on the rest beside it, or use a point [x, y, z] in mm",
          gesture.source, id));
    base = anchor_frame(s, v);
  }
  std::vector<AnchorFrame> anchors;
  for (const auto& tool : gesture.tools) {
    if (tool.offset_m.isZero()) {
      anchors.push_back(base);
      continue;
    }
    const Eigen::Vector3d target =
        base.origin_m + tool.offset_m[0] * base.x + tool.offset_m[1] * base.y;
    anchors.push_back(anchor_frame(s, nearest_compliance_vertex(s, on_interface, target), base.x));
  }
  return anchors;
}

Eigen::Quaterniond keyframe_orientation(const Eigen::Vector2d& tilt_rad, double roll_rad) {
  // diag(1, −1, −1): a half turn about x, the shaft pointing into the organ.
  const Eigen::Quaterniond down(Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()));
  return (Eigen::AngleAxisd(tilt_rad[1], Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(tilt_rad[0], Eigen::Vector3d::UnitX()) * down *
          Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()))
      .normalized();
}

GesturePlayer::GesturePlayer(const Gesture& gesture, std::vector<AnchorFrame> anchors) {
  PALPATE_DEMAND(anchors.size() == gesture.tools.size());
  for (std::size_t i = 0; i < gesture.tools.size(); ++i) {
    const GestureTool& in = gesture.tools[i];
    PALPATE_DEMAND(!in.keyframes.empty());
    Tool& tool = tools_.emplace_back();
    tool.id = in.id;
    tool.reach_m = in.reach_m;
    tool.anchor = anchors[i];
    const Eigen::Matrix3d rotation = tool.anchor.rotation();
    const Eigen::Quaterniond to_model(rotation);
    for (const auto& k : in.keyframes)
      tool.keys.push_back({k.time_s, tool.anchor.origin_m + rotation * k.tip_m,
                           (to_model * keyframe_orientation(k.tilt_rad, k.roll_rad)).normalized(),
                           k.jaw_angle_rad});
  }
  duration_s_ = gesture.duration_s();
}

const std::string& GesturePlayer::tool_id(int tool) const {
  return tools_.at(static_cast<std::size_t>(tool)).id;
}
const AnchorFrame& GesturePlayer::anchor(int tool) const {
  return tools_.at(static_cast<std::size_t>(tool)).anchor;
}

GesturePose GesturePlayer::sample(int tool_index, double time_s) const {
  const Tool& tool = tools_[static_cast<std::size_t>(tool_index)];
  const auto& keys = tool.keys;
  // The first key after time_s; before the first and after the last, hold.
  const auto after = std::upper_bound(keys.begin(), keys.end(), time_s,
                                      [](double t, const Key& k) { return t < k.time_s; });
  GesturePose pose;
  if (after == keys.begin() || after == keys.end()) {
    const Key& k = after == keys.begin() ? keys.front() : keys.back();
    pose.tip_m = k.tip_m;
    pose.orientation = k.orientation;
    pose.jaw_angle_rad = k.jaw_angle_rad;
  } else {
    const Key& a = *(after - 1);
    const Key& b = *after;
    const double s = (time_s - a.time_s) / (b.time_s - a.time_s);
    pose.tip_m = (1 - s) * a.tip_m + s * b.tip_m;
    pose.orientation = a.orientation.slerp(s, b.orientation);
    pose.jaw_angle_rad = (1 - s) * a.jaw_angle_rad + s * b.jaw_angle_rad;
  }
  pose.hinge_m = pose.tip_m - tool.reach_m * (pose.orientation * Eigen::Vector3d::UnitZ());
  return pose;
}

}  // namespace palpate
