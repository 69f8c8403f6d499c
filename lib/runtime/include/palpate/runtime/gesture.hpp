#pragma once
/// @file
/// Scripted tool gestures (press, glide, grasp, two hands) that work on any
/// organ: keyframes per tool in an anchor frame set on the organ's surface,
/// played at the haptic rate (docs/pliers.md, "Gesture files").
///
/// The anchor frame of a tool: origin at a surface vertex, z the outward
/// surface normal there, x and y tangents. The first tool's anchor is chosen
/// from the model's description (`anchor = "auto"`: the compliance vertex
/// farthest from the attached surface, or a given mesh vertex id); another
/// tool's anchor is the compliance vertex nearest to the first anchor plus
/// its `offset_mm` in the first anchor's tangent plane.
///
/// A keyframe gives the tool's **tip point** (the distal end of its tip:
/// hinge + reach·z_tool) in the anchor frame, so that position z = −6 mm
/// means 6 mm below the rest surface whatever the tool; its tilt and roll;
/// its jaw opening. Between keyframes: linear interpolation of the tip
/// point and the jaw angle, slerp of the orientation; before the first and
/// after the last keyframe a tool holds still.

#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/drawn_surface.hpp"

namespace palpate {

/// One keyframe of a tool, as read (SI).
struct GestureKeyframe {
  double time_s = 0;  ///< from the start of the gesture
  /// Tip point in the tool's anchor frame (x, y tangent, z outward normal), m.
  Eigen::Vector3d tip_m = Eigen::Vector3d::Zero();
  /// The shaft turned by tilt_rad[0] about the anchor's x axis, then by
  /// tilt_rad[1] about its y axis (right-hand rule), pivoting on the tip
  /// point; {0, 0}: along the inward normal.
  Eigen::Vector2d tilt_rad = Eigen::Vector2d::Zero();
  double roll_rad = 0;       ///< about the shaft; 0: jaws open in the anchor's x-z plane
  double jaw_angle_rad = 0;  ///< total opening between the jaws
  int line = 0;              ///< in the gesture file (0 when built in code)
};

/// One tool of a gesture.
struct GestureTool {
  std::string id;          ///< the tool id poses carry (one of palpated's tools)
  double reach_m = 0.019;  ///< hinge to tip point along the shaft: palpated's default tool (15 mm
                           ///< capsule + 4 mm radius)
  Eigen::Vector2d offset_m =
      Eigen::Vector2d::Zero();             ///< anchor offset in the first anchor's tangent plane
  std::vector<GestureKeyframe> keyframes;  ///< times strictly increasing, at least one
};

/// A gesture file (docs/pliers.md).
struct Gesture {
  std::string name;         ///< `name`, else the file's stem
  std::string description;  ///< optional free text
  std::string source;       ///< the file it came from, for messages
  /// The first tool's anchor: -1 for "auto", else a mesh vertex id.
  std::int64_t anchor_vertex_id = -1;
  /// Or (`anchor = [x, y, z]`, mm in the file): the compliance vertex
  /// nearest to this point, model frame, m. Takes precedence when set.
  std::optional<Eigen::Vector3d> anchor_point_m;
  std::vector<GestureTool> tools;  ///< at least one, distinct ids

  /// Time of the last keyframe of any tool, s.
  double duration_s() const;
};

/// Reads a gesture file. @throws InputError "<file>:<line>: <key>: <what>
/// (accepted: ...)" for a missing file, bad TOML, an unknown key, a wrong
/// type or value, keyframe times that do not increase.
Gesture read_gesture_file(const std::filesystem::path& file);
/// The same from TOML text; @p source names it in messages.
Gesture parse_gesture(std::string_view toml_text, const std::string& source);

/// An anchor frame on the organ's rest surface (model frame).
struct AnchorFrame {
  int drawn_index = -1;         ///< drawn vertex (a compliance vertex)
  std::uint32_t vertex_id = 0;  ///< its mesh vertex id
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d x = Eigen::Vector3d::UnitX();       ///< tangent
  Eigen::Vector3d y = Eigen::Vector3d::UnitY();       ///< normal × x
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< outward, unit
  /// Anchor frame → model frame (columns x, y, normal).
  Eigen::Matrix3d rotation() const;
};

/// Unit outward normal at drawn vertex @p v (vertex_normals(), drawn_surface.hpp).
/// @throws InputError when the vertex belongs to no triangle of non-zero area.
Eigen::Vector3d outward_normal(const DrawnSurface& surface, int v);

/// The frame at compliance vertex @p v: its outward normal, x the model's
/// @p x_hint projected on the tangent plane (the model's y axis instead when
/// @p x_hint is within 10° of the normal), y = normal × x.
AnchorFrame anchor_frame(const DrawnSurface& surface, int v,
                         const Eigen::Vector3d& x_hint = Eigen::Vector3d::UnitX());

/// The "auto" anchor: the compliance vertex whose distance to the nearest
/// fixed (attached) surface vertex is largest (ties: the lowest index); on a
/// surface with no fixed vertex, the compliance vertex farthest from the
/// centroid of the drawn vertices.
/// @throws InputError for a surface without compliance vertices.
AnchorFrame auto_anchor(const DrawnSurface& surface);

/// The anchors of every tool of @p gesture, in its tool order. On a model
/// with a served cut region, @p covered_triangles are the rest's triangles
/// the region covers (SurfaceSample::hidden_triangles): their vertices are
/// the region's interface Γ, on which no anchor is placed (`auto`, a point
/// and offsets take the nearest vertex off Γ); the normals still take
/// every triangle of @p surface, the covered ones included.
/// @throws InputError when the anchor vertex id is not a compliance vertex
/// or is on Γ, or a covered triangle is not one of @p surface.
std::vector<AnchorFrame> place_gesture(const Gesture& gesture, const DrawnSurface& surface,
                                       std::span<const std::uint32_t> covered_triangles = {});

/// A tool's pose at one instant, model frame.
struct GesturePose {
  Eigen::Vector3d hinge_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d tip_m = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< tool → model
  double jaw_angle_rad = 0;
};

/// A gesture placed on a model, ready to sample. Sampling allocates nothing.
class GesturePlayer {
 public:
  GesturePlayer(const Gesture& gesture, std::vector<AnchorFrame> anchors);

  int tool_count() const { return static_cast<int>(tools_.size()); }
  const std::string& tool_id(int tool) const;
  const AnchorFrame& anchor(int tool) const;
  double duration_s() const { return duration_s_; }

  /// The pose of @p tool at @p time_s (clamped to [0, duration]).
  GesturePose sample(int tool, double time_s) const;

 private:
  struct Key {
    double time_s;
    Eigen::Vector3d tip_m;           // model frame
    Eigen::Quaterniond orientation;  // tool → model
    double jaw_angle_rad;
  };
  struct Tool {
    std::string id;
    double reach_m;
    AnchorFrame anchor;
    std::vector<Key> keys;
  };
  std::vector<Tool> tools_;
  double duration_s_ = 0;
};

/// The tool orientation (tool → anchor frame) of a keyframe: the shaft (+z
/// of the tool) along −z of the anchor and the jaws in its x-z plane, then
/// roll about the shaft, then the tilts about the anchor's x and y axes:
/// Ry(tilt[1]) · Rx(tilt[0]) · diag(1, −1, −1) · Rz(roll).
Eigen::Quaterniond keyframe_orientation(const Eigen::Vector2d& tilt_rad, double roll_rad);

}  // namespace palpate
