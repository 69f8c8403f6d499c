#include "palpate/runtime/contact/contact_solution.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "palpate/core/error.hpp"

namespace palpate::detail {

using Eigen::Matrix3d;
using Eigen::Vector3d;

ContactSolution::ContactSolution(int tools, int max_points, int compliance_count, int triangles)
    : compliance_count_(compliance_count) {
  PALPATE_DEMAND(tools >= 1 && max_points >= 0);
  const auto k = static_cast<std::size_t>(max_points);
  points_.resize(k);
  material_force_.assign(k, Vector3d::Zero());
  wrench_.resize(static_cast<std::size_t>(tools));
  load_index_.resize(3 * k);
  load_tool_.resize(3 * k);
  load_force_.resize(9 * k);
  load_slot_.assign(static_cast<std::size_t>(compliance_count), -1);
  triangle_owner_.assign(static_cast<std::size_t>(triangles), -1);
}

void ContactSolution::begin() {
  // Forget last tick's tip contacts' triangles (for the hysteresis shell).
  for (int c = 0; c < count_; ++c) {
    const ContactPoint& old = points_[static_cast<std::size_t>(c)];
    if (!old.held) triangle_owner_[static_cast<std::size_t>(old.triangle)] = -1;
  }
  count_ = 0;
  max_displacement_ = 0;
  load_energy_ = 0;
  for (RawWrench& w : wrench_) {
    w.force_n.setZero();
    w.torque_nm.setZero();
    w.grip_n = 0;
    w.contacts = 0;
  }
}

const ContactPoint& ContactSolution::add(const ActiveSet& solve, const ContactRows& rows, int b,
                                         const Vector3d& hinge_m, const Matrix3d& tool_rotation,
                                         BackgroundLoads& background) {
  const auto c = static_cast<std::size_t>(count_);
  const int t = rows.tool(b);
  RawWrench& tool = wrench_[static_cast<std::size_t>(t)];
  ContactPoint& point = points_[c];
  point.tool = t;
  point.held = rows.tip(b) < 0;
  // A held point and a tip's point are both a point of a triangle.
  const auto take = [&point](const SurfacePoint& from) {
    point.triangle = from.triangle;
    point.vertex_count = from.count;
    point.vertices = from.vertices;
    point.weights = from.weights;
    return from.rest;
  };
  const Vector3d at_rest = take(rows.point(b));
  // Warped: the solve's force and displacement are the material ones;
  // the world's are f = R̃⁻ᵀ f̂ and R̃ û. The loads stay material.
  material_force_[c] = solve.force(b);
  const Matrix3d& Rt = rows.rotation(b);
  point.force_n =
      rows.warped() ? Vector3d(Rt.transpose().inverse() * material_force_[c]) : material_force_[c];
  const Vector3d displacement =
      rows.warped() ? Vector3d(Rt * solve.displacement(b)) : Vector3d(solve.displacement(b));
  point.position_m = at_rest + displacement;
  if (background.count() > 0)
    point.position_m += background.at_point(rows.point(b), compliance_count_);
  point.normal = rows.row(b).kind == ConstraintKind::kNormalDisplacement ? rows.world_normal(b)
                                                                         : Vector3d::Zero();
  max_displacement_ = std::max(max_displacement_, displacement.norm());
  load_energy_ += material_force_[c].dot(solve.displacement(b));
  tool.force_n -= point.force_n;  // the organ pushes the tool back
  tool.torque_nm += (point.position_m - hinge_m).cross(-point.force_n);
  if (point.held) {
    tool.grip_n += 0.5 * std::abs(point.force_n.dot(tool_rotation.col(0)));
  } else {
    triangle_owner_[static_cast<std::size_t>(point.triangle)] = t;
  }
  ++tool.contacts;
  ++count_;
  return point;
}

void ContactSolution::gather_loads() {
  load_count_ = 0;
  for (int t = 0; t < static_cast<int>(wrench_.size()); ++t) {
    const int first = load_count_;
    for (int c = 0; c < count_; ++c) {
      const ContactPoint& point = points_[static_cast<std::size_t>(c)];
      if (point.tool != t) continue;
      for (int i = 0; i < point.vertex_count; ++i) {
        const int v = point.vertices[static_cast<std::size_t>(i)];
        if (v >= compliance_count_) continue;  // the attachment takes it
        int& slot = load_slot_[static_cast<std::size_t>(v)];
        if (slot < first) {
          slot = load_count_++;
          load_index_[static_cast<std::size_t>(slot)] = v;
          load_tool_[static_cast<std::size_t>(slot)] = t;
          Eigen::Map<Vector3d>{&load_force_[3 * static_cast<std::size_t>(slot)]}.setZero();
        }
        Eigen::Map<Vector3d>{&load_force_[3 * static_cast<std::size_t>(slot)]} +=
            point.weights[static_cast<std::size_t>(i)] *
            material_force_[static_cast<std::size_t>(c)];
      }
    }
  }
  for (int l = 0; l < load_count_; ++l)
    load_slot_[static_cast<std::size_t>(load_index_[static_cast<std::size_t>(l)])] = -1;
}

}  // namespace palpate::detail
