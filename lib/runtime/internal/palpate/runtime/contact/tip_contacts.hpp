#pragma once
/// @file
/// A tool tip's contacts with the deformed surface (internal to the runtime;
/// the contact engine's step 3, docs/tools.md "One tick" and "Tip
/// contacts"): for every surface triangle near the tip, the closest points
/// between the tip's axis (a sphere's centre, a capsule's segment) and the
/// deformed triangle; a triangle closer than the radius r is penetrated,
/// and its closest point is put back on the tip's surface along the normal
/// from the axis. Deepest first, each point once, points kept apart so that
/// their rows are independent. Allocation-free after construction.
///
/// The points are material (docs/tools.md, "Material contact points"): a
/// point found once keeps its triangle and barycentric weights from tick to
/// tick, its gap and normal recomputed where the surface has it now, while
/// it stays within reach of the tip; a new point is added only where the
/// deformed surface meets the tip farther than the spacing from every kept
/// one. A tool held still therefore solves the same points every tick, and
/// their complementarity (the active set), not the search, decides which
/// of them push.

#include <Eigen/Core>
#include <array>
#include <span>
#include <vector>

#include "palpate/runtime/contact/deformed_surface.hpp"
#include "palpate/runtime/contact/surface_point.hpp"
#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::detail {

/// A tip contact found this tick: the deepest point of a surface triangle
/// inside the tip, on the triangle's vertices that carry a weight.
struct TipCandidate : SurfacePoint {
  double depth = 0;  ///< r − distance to the tip's axis, m (negative: within the hysteresis shell)
  /// Unit: the direction the tip pushes the tissue (from the axis to the point).
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  Eigen::Vector3d target = Eigen::Vector3d::Zero();  ///< the point put back on the tip's surface, m
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   ///< the point on the deformed triangle, m
  /// Penetrating (or within the hysteresis shell); else a near triangle the
  /// solve may push into the tip.
  bool active = false;
  /// Its row was in contact at the last solve (set by the engine after it):
  /// it stays while within the hysteresis shell.
  bool touched = false;
  /// Solves in a row its row stuck in (set by the engine after each: 0
  /// when it slid or pushed no more). From kMaterialAfter on the point is
  /// kept material; before, it is found again as its triangle's closest
  /// point, which carries the count over.
  int stuck = 0;
  /// Where on its triangle the point lies, per corner of the triangle (the
  /// weights above, in corner order, 0 off the point).
  std::array<double, 3> corner_weights{};
  /// The secant of a frictionless point's place (docs/tools.md, "Where a
  /// frictionless point pushes"): its weights the tick before, and the step from
  /// them to the closest point then; `placed` once it has them.
  std::array<double, 3> weights_before{};
  std::array<double, 3> step_before{};
  bool placed = false;
};

/// Solves in a row a tip point must stick in before it is kept as a
/// material point (docs/tools.md, "Material contact points"): a sliding
/// contact stays the closest point, a held one becomes material.
inline constexpr int kMaterialAfter = 2;

/// A tool's segment: a capsule's from its hinge along +z; a sphere's is its centre.
inline double tip_length(const ToolGeometry& g) {
  return g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0;
}
/// Longest reach of a tool from its hinge along z: its tip or its jaws.
inline double reach_length(const ToolGeometry& g) {
  return std::max(tip_length(g), g.jaw_length_m);
}

/// One tool at its pose, as the search needs it.
struct TipQuery {
  int tool = 0;  ///< its index (the hysteresis: its triangles of last tick)
  const ToolGeometry* geometry = nullptr;
  Eigen::Vector3d hinge = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  ///< tool → model
  double jaw_angle_rad = 0;
  bool holding = false;      ///< the jaws hold tissue
  double search_radius = 0;  ///< of its candidate vertices about its segment at rest, m
};

class TipContacts {
 public:
  /// Scratch for a surface of @p triangles triangles.
  explicit TipContacts(int triangles);

  /// Tool @p q's tip contacts, deepest first (but for a fold's near face,
  /// which takes its far face's place), at most out.size() of them,
  /// into @p out; @returns how many. A triangle with a vertex in @p owner
  /// (per compliance vertex: the tool holding it, or −1) is left out, and
  /// one whose point another tool's jaws may take: tissue between open
  /// jaws is not pushed. @p previous_owner (per triangle: the tool whose tip
  /// touched it last tick) keeps a contact within 5 % of r outside the tip
  /// (hysteresis). @p kept are the tool's points of the last tick (its
  /// `out` then, `touched` set by the solve): they come first, where they
  /// still are within reach; @p kept must not alias @p out.
  int find(const TipQuery& q, DeformedSurface& surface, std::span<const int> owner,
           std::span<const int> previous_owner, std::span<const TipCandidate> kept,
           std::span<TipCandidate> out);

 private:
  struct Ranked {
    double depth;
    int index;  // into found_
  };
  /// The candidate of point @p point of triangle @p tri, at distance @p d from
  /// the axis point @p on_segment; false: not a point the tip can push.
  bool make_candidate(const TipQuery& q, DeformedSurface& surface, int tri,
                      const std::array<double, 3>& weights, const Eigen::Vector3d& point,
                      const Eigen::Vector3d& on_segment, double distance, bool active,
                      TipCandidate& candidate) const;
  std::vector<TipCandidate> found_;
  std::vector<Ranked> ranked_;  // found_'s depths, to sort
};

}  // namespace palpate::detail
