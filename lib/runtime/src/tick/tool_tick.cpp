#include "palpate/runtime/tool_tick.hpp"

#include <algorithm>

#include "palpate/core/error.hpp"

namespace palpate {

namespace {

/// The engine's buffers allow max_constraints points on up to 3 vertices each.
std::size_t record_capacity(const SolverLimits& limits) {
  return 3 * static_cast<std::size_t>(std::max(1, limits.max_constraints));
}

}  // namespace

ToolTick::ToolTick(const SurfaceModel& model, std::vector<ToolGeometry> tools,
                   const ContactSettings& settings, const SolverLimits& limits,
                   const RotationField* warping, HybridRegion* region)
    : model_(model), engine_(model, std::move(tools), settings, limits, warping), region_(region) {
  const auto count = static_cast<std::size_t>(engine_.tool_count());
  blades_.assign(count, Blade{});
  blade_live_.assign(count, 0);
  region_tips_.reserve(count);
  region_tip_tools_.reserve(count);
  record_vertices_.resize(record_capacity(limits));
  record_forces_.resize(3 * record_capacity(limits));
  if (region_ == nullptr) return;
  if (warping != nullptr)
    throw InputError("a served cut region is linear: it takes no warped contact engine");
  for (int t = 0; t < model_.surface.triangle_count(); ++t)
    engine_.set_triangle_hidden(t, region_->covers_rest_triangle(t));
  engine_.reserve_background_loads(static_cast<int>(region_->interface_vertices().size()));
}

RegionTip ToolTick::tip_of(int tool) const {
  const ToolGeometry& g = engine_.tool(tool);
  const ToolPoseInput& pose = engine_.pose(tool);
  const double length = g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0;
  return RegionTip{pose.position_m,
                   pose.position_m + length * (pose.orientation * Eigen::Vector3d::UnitZ()),
                   g.tip_radius_m};
}

RequestStatus ToolTick::update(int tool, const ToolPoseInput& pose, double now_s) {
  cut_tetrahedra_ = 0;
  region_stepped_ = false;
  const RequestStatus status = engine_.solve(tool, pose, now_s);
  if (region_ == nullptr) {
    engine_.answer(tool, now_s);
    return status;
  }
  step_region(tool, now_s);
  // The region's push on this tool's tip (its torque about the tip's base,
  // the hinge), added before the device's limits.
  ToolWrench push;
  {  // region_tip_tools_ are the tips of the region's last step
    const auto at = std::find(region_tip_tools_.begin(), region_tip_tools_.end(), tool);
    if (at != region_tip_tools_.end()) {
      const int tip = static_cast<int>(at - region_tip_tools_.begin());
      push.force_n = region_->tip_force_n(tip);
      push.torque_nm = region_->tip_torque_nm(tip);
    }
  }
  engine_.answer(tool, now_s, push);
  return status;
}

void ToolTick::step_region(int tool, double now_s) {
  HybridRegion& region = *region_;
  const ToolGeometry& g = engine_.tool(tool);
  const auto slot = static_cast<std::size_t>(tool);
  const bool live = g.cutting && engine_.pose(tool).jaw_angle_rad <= g.grasp_angle_rad;
  if (live) {
    // The edge on the region at rest; it cuts what it swept since its last
    // live pose (or what it lies in, on the first).
    const RegionTip edge = tip_of(tool);
    const Blade now{region.rest_point_of(edge.base_m), region.rest_point_of(edge.end_m)};
    const Blade before = blade_live_[slot] != 0 ? blades_[slot] : now;
    blades_[slot] = now;
    cut_tetrahedra_ = region.cut(before, now);
    if (cut_tetrahedra_ > 0)
      for (int t = 0; t < model_.surface.triangle_count(); ++t)
        engine_.set_triangle_hidden(t, region.covers_rest_triangle(t));
  }
  blade_live_[slot] = live ? 1 : 0;
  // The region's clock follows the poses: the time since its last step (a
  // 1 ms tick the first time). A pose at the same time steps nothing: the
  // last step's tips and pushes stand.
  const double tick_s = region_time_s_ < 0 ? 1e-3 : now_s - region_time_s_;
  if (tick_s <= 0) return;
  region_time_s_ = now_s;
  region_tips_.clear();
  region_tip_tools_.clear();
  for (int t = 0; t < engine_.tool_count(); ++t) {
    if (!engine_.in_session(t)) continue;
    region_tips_.push_back(tip_of(t));
    region_tip_tools_.push_back(t);
  }
  region.advance(tick_s, engine_.contact_indices(), engine_.contact_forces(), region_tips_);
  region_stepped_ = true;
  // The tools meet the rest as the region pushes it, from the next tick on.
  const Eigen::VectorXd& push = region.interface_force_n();
  const Eigen::VectorXd& moved = region.interface_displacement_m();
  engine_.set_background_loads(region.interface_compliance_indices(),
                               {push.data(), static_cast<std::size_t>(push.size())},
                               {moved.data(), static_cast<std::size_t>(moved.size())});
}

std::uint64_t ToolTick::watchdog(double now_s) { return engine_.watchdog(now_s); }

bool ToolTick::end(int tool, double now_s) { return engine_.end(tool, now_s); }

ToolTick::Record ToolTick::make_record(int tool, double now_s, std::uint64_t compute_ns) {
  const ToolOutput& out = engine_.output(tool);
  const ToolPoseInput& pose = engine_.pose(tool);
  ToolTickRecord& tick = record_;
  tick = ToolTickRecord{};
  tick.time_s = now_s;
  tick.tool = tool;
  tick.sequence = out.sequence;
  tick.send_time_ns = out.send_time_ns;
  for (int d = 0; d < 3; ++d) {
    tick.position_m[d] = pose.position_m[d];
    tick.force_n[d] = out.force_n[d];
    tick.torque_nm[d] = out.torque_nm[d];
  }
  tick.orientation_wxyz[0] = pose.orientation.w();
  tick.orientation_wxyz[1] = pose.orientation.x();
  tick.orientation_wxyz[2] = pose.orientation.y();
  tick.orientation_wxyz[3] = pose.orientation.z();
  tick.jaw_angle_rad = pose.jaw_angle_rad;
  tick.grip_n = out.grip_n;
  tick.state = out.state;
  tick.watchdog = out.watchdog;
  tick.force_limited = out.force_limited;
  tick.held = static_cast<std::uint32_t>(out.held);
  tick.compute_ns = compute_ns;
  // This tool's contacts, by mesh vertex id.
  const auto indices = engine_.contact_indices();
  const auto forces = engine_.contact_forces();
  const auto tools_of = engine_.contact_tools();
  std::size_t m = 0;
  for (std::size_t c = 0; c < indices.size() && m < record_vertices_.size(); ++c) {
    if (tools_of[c] != tool) continue;
    record_vertices_[m] = model_.surface.vertex_ids[static_cast<std::size_t>(indices[c])];
    std::copy_n(&forces[3 * c], 3, &record_forces_[3 * m]);
    ++m;
  }
  return {tick, {record_vertices_.data(), m}, {record_forces_.data(), 3 * m}};
}

void ToolTick::record(int tool, double now_s, std::uint64_t compute_ns, SessionRecorder& recorder) {
  const Record r = make_record(tool, now_s, compute_ns);
  recorder.record(r.tick, r.vertex_ids, r.forces_n);
  const ToolOutput& out = engine_.output(tool);
  for (int e = 0; e < out.event_count; ++e)
    recorder.record_event(now_s, tool, out.events[static_cast<std::size_t>(e)], out.sequence);
}

}  // namespace palpate
