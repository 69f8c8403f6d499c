#include "palpate/runtime/contact/grasp_state.hpp"

#include <algorithm>

#include "palpate/core/error.hpp"

namespace palpate::detail {

GraspState::GraspState(int tools, int per_tool_capacity, int max_points, int compliance_count,
                       int triangles)
    : capacity_(per_tool_capacity),
      compliance_count_(compliance_count),
      jaws_(static_cast<std::size_t>(tools)),
      grasp_(std::max(1, max_points), compliance_count) {
  PALPATE_DEMAND(tools >= 1 && per_tool_capacity >= 1);
  for (auto& j : jaws_) j.held.reserve(static_cast<std::size_t>(per_tool_capacity));
  owner_.assign(static_cast<std::size_t>(compliance_count), -1);
  triangles_.resize(static_cast<std::size_t>(triangles));
  corners_.resize(3 * static_cast<std::size_t>(triangles));
  touched_.reserve(static_cast<std::size_t>(max_points));
}

void GraspState::new_pose(int tool, double last_jaw_rad, bool continuing) {
  Jaws& j = jaws_[static_cast<std::size_t>(tool)];
  j.has_previous_jaw = continuing;
  j.previous_jaw = last_jaw_rad;
  j.widest_jaw =
      continuing && j.held.empty() ? std::max(j.widest_jaw, j.previous_jaw) : j.previous_jaw;
}

GraspState::Step GraspState::step(int tool, double jaw_rad, const ToolGeometry& g) {
  Jaws& j = jaws_[static_cast<std::size_t>(tool)];
  if (!j.held.empty()) {
    if (jaw_rad >= g.release_angle_rad) {
      j.held.clear();
      return Step::kReleased;
    }
    return Step::kNone;
  }
  const bool closing = j.has_previous_jaw && j.previous_jaw > g.grasp_angle_rad &&
                       jaw_rad <= g.grasp_angle_rad && g.jaw_length_m > 0 && !g.cutting;
  return closing ? Step::kClosing : Step::kNone;
}

double GraspState::opening_rad(int tool) const {
  const Jaws& j = jaws_[static_cast<std::size_t>(tool)];
  return std::max(j.widest_jaw, j.previous_jaw);
}

bool GraspState::pick_up(int tool, const JawsAtClosing& jaws, std::span<const int> near_triangles,
                         DeformedSurface& surface, std::span<const ContactPoint> last_points) {
  // The triangles near the jaws that this tool may hold: not wholly fixed,
  // no vertex of a point another tool holds.
  std::size_t near = 0;
  for (const int tri : near_triangles) {
    const int* corner = surface.corners(tri);
    int fixed = 0;
    bool elsewhere = false;
    for (int i = 0; i < 3; ++i) {
      if (corner[i] >= compliance_count_)
        ++fixed;
      else
        elsewhere |= held_elsewhere(corner[i], tool);
    }
    if (fixed == 3 || elsewhere) continue;
    triangles_[near++] = tri;
  }
  surface.deform_corners({triangles_.data(), near});
  for (std::size_t k = 0; k < near; ++k)
    for (int i = 0; i < 3; ++i)
      corners_[3 * k + static_cast<std::size_t>(i)] =
          surface.deformed(surface.corners(triangles_[k])[i]);
  // What the tip pressed at the last solve.
  touched_.clear();
  for (const ContactPoint& point : last_points) {
    if (point.tool != tool || point.held) continue;
    HeldPoint h{};
    h.triangle = point.triangle;
    h.count = point.vertex_count;
    h.vertices = point.vertices;
    h.weights = point.weights;
    for (int i = 0; i < h.count; ++i)
      h.rest += h.weights[static_cast<std::size_t>(i)] *
                surface.rest(h.vertices[static_cast<std::size_t>(i)]);
    touched_.push_back(h);
  }
  std::vector<HeldPoint>& held = jaws_[static_cast<std::size_t>(tool)].held;
  grasp_.choose(jaws, {triangles_.data(), near}, {corners_.data(), 3 * near},
                surface.triangle_vertices(), surface.rest(), touched_, held, capacity_);
  return !held.empty();
}

void GraspState::claim(int tool) {
  for (const auto& h : held(tool))
    for (int i = 0; i < h.count; ++i)
      if (h.vertices[static_cast<std::size_t>(i)] < compliance_count_)
        owner_[static_cast<std::size_t>(h.vertices[static_cast<std::size_t>(i)])] = tool;
}

void GraspState::unclaim() {
  for (const Jaws& j : jaws_)
    for (const auto& h : j.held)
      for (int i = 0; i < h.count; ++i)
        if (h.vertices[static_cast<std::size_t>(i)] < compliance_count_)
          owner_[static_cast<std::size_t>(h.vertices[static_cast<std::size_t>(i)])] = -1;
}

void GraspState::let_go(int tool) { jaws_[static_cast<std::size_t>(tool)].held.clear(); }

void GraspState::forget(int tool) {
  Jaws& j = jaws_[static_cast<std::size_t>(tool)];
  j.held.clear();
  j.has_previous_jaw = false;
  j.widest_jaw = 0;
}

bool GraspState::held_elsewhere(int vertex, int tool) const {
  for (int other = 0; other < static_cast<int>(jaws_.size()); ++other) {
    if (other == tool) continue;
    for (const auto& h : jaws_[static_cast<std::size_t>(other)].held)
      for (int i = 0; i < h.count; ++i)
        if (h.vertices[static_cast<std::size_t>(i)] == vertex) return true;
  }
  return false;
}

}  // namespace palpate::detail
