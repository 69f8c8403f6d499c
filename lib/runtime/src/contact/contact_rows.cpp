#include "palpate/runtime/contact/contact_rows.hpp"

#include <Eigen/Dense>

namespace palpate::detail {

using Eigen::Matrix3d;
using Eigen::Vector3d;

ContactRows::ContactRows(int capacity, int tools, DeformedSurface& surface,
                         BackgroundLoads& background)
    : surface_(surface),
      background_(background),
      compliance_count_(surface.compliance_count()),
      drag_(static_cast<std::size_t>(tools)) {
  const auto k = static_cast<std::size_t>(capacity);
  rows_.resize(k);
  tool_.resize(k);
  tip_.resize(k);
  point_.resize(k);
  rotation_.assign(k, Matrix3d::Identity());
  world_normal_.assign(k, Vector3d::Zero());
  local_.resize(k);
}

void ContactRows::solved(int tool, bool drags, const Vector3d& hinge_m, const Matrix3d& rotation) {
  Drag& d = drag_[static_cast<std::size_t>(tool)];
  d.drags = drags;
  d.hinge_m = hinge_m;
  d.rotation = rotation;
}

void ContactRows::add_held(const Tool& tool, std::span<const HeldPoint> held) {
  for (const HeldPoint& point : held) {
    const Vector3d lever = tool.rotation * point.local;  // it turns with the jaws
    add(tool, -1, point, ConstraintKind::kDisplacement,
        tool.scale * (tool.hinge_m + lever - point.rest), Vector3d::Zero(), lever, 0.0);
  }
}

void ContactRows::add_tips(const Tool& tool, std::span<const TipCandidate> tips) {
  const ToolGeometry& g = *tool.geometry;
  const Drag& solved = drag_[static_cast<std::size_t>(tool.index)];
  for (int c = 0; c < static_cast<int>(tips.size()); ++c) {
    const TipCandidate& tip = tips[static_cast<std::size_t>(c)];
    Vector3d u = tool.scale * (tip.target - tip.rest);
    // Friction: the tissue sticks to the tip, so the point found where
    // the surface is now is taken along with the tool's motion at it
    // since the last solve, in the contact's plane (along the normal the
    // tip's push decides); the active set lets it slip back onto the
    // cone's edge (docs/tools.md, "Friction").
    if (g.friction > 0 && solved.drags && !tool.ramping_out) {
      const Vector3d was = solved.hinge_m + solved.rotation * (tool.rotation.transpose() *
                                                               (tip.target - tool.hinge_m));
      const Vector3d moved = tip.target - was;
      u += moved - tip.normal * tip.normal.dot(moved);
    }
    // The tip's surface point moves as the point of the axis it is
    // pushed from (its normal frozen).
    const Vector3d lever = tip.target - g.tip_radius_m * tip.normal - tool.hinge_m;
    if (g.friction > 0)
      add(tool, c, tip, ConstraintKind::kDisplacement, u, tip.normal, lever, tip.depth);
    else
      add(tool, c, tip, ConstraintKind::kNormalDisplacement, Vector3d(tip.normal.dot(u), 0, 0),
          tip.normal, lever, tip.depth);
    LocalRow& l = local_[static_cast<std::size_t>(count_ - 1)];
    l.target = tip.target;
    l.material = false;  // kept on its triangle next tick: set after the solve
    l.radius = g.tip_radius_m;
    l.distance = g.tip_radius_m - tip.depth;
    if (!tip.active) rows_[static_cast<std::size_t>(count_ - 1)].state = ActiveRow::kDormant;
  }
}

// A point on its vertices, a fixed one as −1 (its share goes to the attachment).
void ContactRows::add(const Tool& tool, int tip, const SurfacePoint& point, ConstraintKind kind,
                      Vector3d value, const Vector3d& normal, const Vector3d& lever, double depth) {
  // The background loads move the point by H u_b already: the tools'
  // forces make the rest (linear engines only: set_background_loads).
  if (background_.count() > 0) {
    const Vector3d moved = background_.at_point(point, compliance_count_);
    if (kind == ConstraintKind::kDisplacement) value -= moved;
    if (kind == ConstraintKind::kNormalDisplacement) value.x() -= normal.dot(moved);
  }
  const auto b = static_cast<std::size_t>(count_++);
  LocalRow& l = local_[b];
  l.tool = tool.index;
  l.tip = tip >= 0;
  l.lever = lever;
  l.normal = normal;
  l.rotation = Matrix3d::Identity();
  for (int i = 0; i < point.count && l.tip; ++i)
    l.corners[static_cast<std::size_t>(i)] =
        surface_.deformed(point.vertices[static_cast<std::size_t>(i)]);
  tool_[b] = tool.index;
  tip_[b] = tip;
  point_[b] = &point;
  ActiveRow& row = rows_[b];
  row.count = point.count;
  for (std::size_t i = 0; i < 3; ++i) {
    const int v = static_cast<int>(i) < point.count ? point.vertices[i] : -1;
    row.index[i] = v < compliance_count_ ? v : -1;
    row.weights[i] = static_cast<int>(i) < point.count ? point.weights[i] : 0.0;
  }
  row.kind = kind;
  row.value = value;
  row.normal = normal;
  world_normal_[b] = normal;
  if (surface_.warped()) {
    // Into the point's material frame (docs/model/warped.md, "Large rotations:
    // warped compliance"): d̂ = R̃⁻¹ d; a normal n̂ = R̃ᵀ n / s, δ̂ = δ / s.
    const Matrix3d Rt = surface_.point_rotation(point);
    rotation_[b] = Rt;
    l.rotation = Rt;
    if (kind == ConstraintKind::kDisplacement) row.value = Rt.inverse() * value;
    if (normal.squaredNorm() > 0) {
      const Vector3d n = Rt.transpose() * normal;
      const double scale = n.norm();
      row.normal = n / scale;
      if (kind == ConstraintKind::kNormalDisplacement) row.value.x() = value.x() / scale;
    }
  }
  row.tip = tip >= 0;
  row.friction = tool.geometry->friction;
  row.depth = row.tip ? depth : 0.0;
  row.join_gap_m = 1e-3 * tool.geometry->tip_radius_m;
  row.state = ActiveRow::kActive;
  row.slipped = false;
}

}  // namespace palpate::detail
