#pragma once
/// @file
/// The grasp state of a contact engine's tools (internal to the runtime;
/// the engine's step 2, docs/tools.md "One tick" and "Grasp"): what each
/// tool's jaws hold, and the state machine that takes hold and lets go.
/// Jaws that close past the grasp angle from above it take what lies
/// between them (JawGrasp chooses it, from the deformed triangles near the
/// jaws and what the tip pressed at the last solve); jaws that hold let go
/// when they open past the release angle, which is wider (hysteresis).

#include <Eigen/Core>
#include <span>
#include <vector>

#include "palpate/runtime/contact/deformed_surface.hpp"
#include "palpate/runtime/contact/jaw_grasp.hpp"
#include "palpate/runtime/contact_point.hpp"
#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::detail {

/// Every tool's grasp: its held points (HeldPoint: a surface point and its
/// place in the tool frame, which follows the jaws rigidly), its last jaw
/// angle and the widest its jaws opened since they last held anything (the
/// faces' place when they came around the tissue: line jaws closing slowly
/// pass into it; real ones stop on its surface). Angles in radians. A
/// vertex one tool holds is never taken by another's jaws, nor, in a solve,
/// by any tip (claim()). Allocates nothing after construction.
class GraspState {
 public:
  /// What a tool's new jaw angle does (step()).
  enum class Step {
    kNone,      ///< nothing changes
    kReleased,  ///< the jaws opened past the release angle: they let go
    kClosing,   ///< empty jaws closed past the grasp angle: pick_up() next
  };

  /// @p tools tools (≥ 1), each holding at most @p per_tool_capacity
  /// points (≥ 1); @p max_points: the engine's points in all (what the tip
  /// pressed at the last solve, at most); @p compliance_count: vertices from
  /// it on are fixed; @p triangles: the drawn surface's.
  GraspState(int tools, int per_tool_capacity, int max_points, int compliance_count, int triangles);

  /// What tool @p tool holds (in the tool frame), in the order taken.
  const std::vector<HeldPoint>& held(int tool) const {
    return jaws_[static_cast<std::size_t>(tool)].held;
  }
  bool holding(int tool) const { return !held(tool).empty(); }

  /// Tool @p tool takes a new pose: @p last_jaw_rad is its last pose's jaw
  /// angle, @p continuing whether that pose was of this session.
  void new_pose(int tool, double last_jaw_rad, bool continuing);
  /// The state machine for tool @p tool's new jaw angle @p jaw_rad (its
  /// geometry @p g): jaws that hold let go at the release angle or wider;
  /// empty jaws that were open wider than the grasp angle and are now at it
  /// or under close (a tool with jaws that does not cut).
  Step step(int tool, double jaw_rad, const ToolGeometry& g);
  /// What the closing jaws of tool @p tool opened to: the widest since they
  /// last held anything, or the last angle if wider.
  double opening_rad(int tool) const;
  /// Closing jaws @p jaws (opened to opening_rad()) take hold: of
  /// @p near_triangles (the surface's, near the jaws) those not wholly fixed
  /// and with no vertex another tool holds, deformed on @p surface (this
  /// epoch), and the points of @p last_points (the last solve's) that tool
  /// @p tool's tip pressed. @returns whether the jaws now hold anything.
  bool pick_up(int tool, const JawsAtClosing& jaws, std::span<const int> near_triangles,
               DeformedSurface& surface, std::span<const ContactPoint> last_points);
  /// Tool @p tool's held vertices are its own for a solve: no tip takes
  /// them (owner()). Called for every living tool before the tip search.
  void claim(int tool);
  /// Every tool's held vertices are free again (after the solve).
  void unclaim();
  /// Per compliance vertex: the tool that claimed it, or −1.
  std::span<const int> owner() const { return owner_; }

  /// Tool @p tool lets go of everything (the watchdog ramped it out).
  void let_go(int tool);
  /// Tool @p tool's session ended: it lets go, and its jaws' history is
  /// forgotten (its next pose starts a new session).
  void forget(int tool);

 private:
  struct Jaws {
    std::vector<HeldPoint> held;  // in the tool frame
    double previous_jaw = 0;
    bool has_previous_jaw = false;
    double widest_jaw = 0;
  };
  bool held_elsewhere(int vertex, int tool) const;

  int capacity_;
  int compliance_count_;
  std::vector<Jaws> jaws_;
  std::vector<int> owner_;  // per compliance vertex: the tool claiming it, or -1
  JawGrasp grasp_;
  // Scratch, sized once.
  std::vector<int> triangles_;            // near the closing jaws
  std::vector<Eigen::Vector3d> corners_;  // 3 per triangle, deformed
  std::vector<HeldPoint> touched_;        // the tip's points at the last solve
};

}  // namespace palpate::detail
