#pragma once
/// @file
/// What a tool's jaws hold when they close (docs/tools.md, "Grasp"): points
/// of the organ's deformed surface triangles under the two jaw faces, each
/// a barycentric point on its triangle's vertices, kept in the tool frame
/// squeezed onto the jaws' mid-plane. The held area, not where the mesh
/// happens to have vertices, decides what follows the pliers. Internal to
/// the runtime layer.

#include <array>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/contact/surface_point.hpp"
#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::detail {

/// A surface point held by a tool's jaws, and where it is in the tool frame.
struct HeldPoint : SurfacePoint {
  Eigen::Vector3d local = Eigen::Vector3d::Zero();  ///< tool frame, on the mid-plane x = 0, m
  double side = 1;  ///< +1: the jaw on +x carries it; −1 the other
};

/// A set of barycentric rows over vertices kept linearly independent: a
/// point is kept only if the part of its weight vector (over the movable
/// vertices) orthogonal to those already kept has a norm of at least the
/// threshold. Imposed displacements at points whose rows are independent
/// make a non-singular reduced system (G is positive definite), and the
/// threshold bounds how close to singular it gets. Allocates nothing after
/// construction.
class IndependentRows {
 public:
  /// At most @p rows rows of at most 3 vertices each.
  explicit IndependentRows(int rows);
  void clear();
  /// Keeps the row (vertices[i] < 0: fixed, no unknown) if independent
  /// enough of the kept ones. @returns whether it was kept.
  bool add(std::span<const int> vertices, std::span<const double> weights, double threshold);
  int size() const { return rows_; }

 private:
  int capacity_;
  int rows_ = 0;
  int columns_ = 0;
  std::vector<int> column_vertex_;  // the vertex of each local column
  std::vector<double> basis_;       // orthonormal rows, capacity_ × 3·capacity_
  std::vector<double> row_;         // scratch, 3·capacity_
};

/// Where the jaws of a tool are and what is near them, for one closing.
struct JawsAtClosing {
  Eigen::Vector3d hinge;
  Eigen::Matrix3d rotation;  ///< tool frame → model frame
  const ToolGeometry* geometry;
  double opening_rad;  ///< the jaws' angle before they closed
};

/// Chooses the points held by jaws closing on the surface.
///
/// Candidates, in this order: the points the tip touched at the last tick,
/// then, for a grid of points on each of the two jaw faces as they were
/// open (4 along the jaw × 2 across, the faces alternating), the nearest
/// point of the candidate triangles. A candidate is held if it lies between
/// the open jaws (docs/tools.md), is not within 0.1 r of a point already
/// held, and its row is independent of theirs (IndependentRows, threshold
/// 0.5). The held points are then squeezed onto one plane between the faces:
/// the middle of the held tissue. Allocates nothing after construction.
class JawGrasp {
 public:
  /// At most @p capacity points per closing; @p triangle_vertices: 3 per
  /// drawn triangle; vertices from @p compliance_count on are fixed.
  JawGrasp(int capacity, int compliance_count);

  /// Is the point @p x (model frame) between the jaws opened at @p angle
  /// (within the tip's radius of their faces and sides, from the hinge to
  /// @p beyond_m past their ends)?
  static bool between(const JawsAtClosing& jaws, const Eigen::Vector3d& x, double angle,
                      double beyond_m = 0);

  /// @p triangles: candidate drawn triangles; @p corners: their deformed
  /// corners, 3 per triangle; @p triangle_vertices: the surface's, 3 per
  /// drawn triangle; @p rest: per drawn vertex; @p touched: what the tip
  /// touched (their `local` is ignored). Appends to @p held (whose capacity
  /// is at least the engine's) and returns how many were added.
  int choose(const JawsAtClosing& jaws, std::span<const int> triangles,
             std::span<const Eigen::Vector3d> corners, std::span<const int> triangle_vertices,
             std::span<const Eigen::Vector3d> rest, std::span<const HeldPoint> touched,
             std::vector<HeldPoint>& held, int capacity);

 private:
  bool keep(const JawsAtClosing& jaws, HeldPoint point, const Eigen::Vector3d& deformed,
            bool touched, std::vector<HeldPoint>& held, int capacity);

  int compliance_count_;
  IndependentRows rows_;
  std::vector<Eigen::Vector3d> held_positions_;  // deformed, of this closing's points
};

}  // namespace palpate::detail
