#include "palpate/runtime/tool_contact.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "palpate/core/error.hpp"

namespace palpate {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

/// Closest point to @p x on the segment [a, a + length·axis] (axis unit).
Vector3d closest_on_segment(const Vector3d& a, const Vector3d& axis, double length,
                            const Vector3d& x) {
  const double t = std::clamp((x - a).dot(axis), 0.0, length);
  return a + t * axis;
}

/// A tip contact found this tick.
struct TipCandidate {
  int index;  // compliance index
  double
      depth;  // r − distance to the tip's axis segment, m (negative: within the hysteresis shell)
  Vector3d normal;  // unit: the direction the tip pushes the vertex (the organ's inward normal)
  Vector3d target;  // the vertex's position put back on the tip's surface, m
};

struct HeldVertex {
  int index;
  Vector3d local;  // position in the tool frame, on the jaws' mid-plane x = 0
  double side;     // sign of x before the squeeze: which jaw carries it
};

}  // namespace

struct ToolContactEngine::Impl {
  const SurfaceModel& model;
  ContactSettings settings;
  SolverLimits limits;
  ConstraintSolver solver;
  int per_tool_cap = 0;

  struct Tool {
    ToolGeometry geometry;
    bool alive = false;  // a pose was taken and the watchdog has not ramped it out
    ToolPoseInput pose;
    Matrix3d rotation = Matrix3d::Identity();
    double last_pose_s = 0;
    bool has_sequence = false;
    double previous_jaw = 0;
    bool has_previous_jaw = false;
    double scale = 1;  // watchdog ramp, 1 → 0
    bool in_watchdog = false;
    std::vector<HeldVertex> held;
    std::vector<TipCandidate> tips;  // this tick's tip contacts
    int tip_count = 0;
    Vector3d raw_force = Vector3d::Zero(), raw_torque = Vector3d::Zero();
    double raw_grip = 0;
    int contacts = 0;
    ToolOutput out;
    bool has_output = false;
    double last_output_s = 0;
    ToolState shown_state = ToolState::kFree;
  };
  std::vector<Tool> tools;

  // Per compliance vertex.
  std::vector<Vector3d> rest;           // rest positions
  std::vector<Vector3d> vertex_normal;  // outward, area weighted
  std::vector<int> owner;               // tool constraining it this tick, or -1
  std::vector<int> previous_tip_owner;  // tool whose tip touched it last tick, or -1
  Vector3d box_min, box_max;

  // Scratch, sized once.
  std::vector<int> candidates;
  std::vector<Vector3d> candidate_position;  // deformed, under the previous solve's forces
  std::vector<double> candidate_depth;

  // The last successful solve: every tool's constraints.
  int count = 0;
  std::vector<int> indices;       // compliance index per constraint
  std::vector<int> tool_of;       // tool per constraint
  std::vector<int> tip_of;        // index into tools[tool_of].tips, or -1 for a held vertex
  std::vector<double> forces;     // 3 per constraint, on the organ
  std::vector<double> positions;  // 3 per constraint, deformed
  std::vector<double> normals;    // 3 per constraint: sliding normal, or zero
  double max_displacement = 0;    // over the constraints, m
  std::uint64_t solve_count = 0;
  char message[256] = {};
  mutable char problem[256] = {};  // why check() refused the last pose it refused

  /// Writes the reason for a refused pose into `problem` (cut to fit).
  template <typename... Args>
  void explain(fmt::format_string<Args...> format, Args&&... args) const {
    const auto written =
        fmt::format_to_n(problem, sizeof problem - 1, format, std::forward<Args>(args)...);
    *written.out = '\0';
  }

  // The constraint set being built.
  int building = 0;
  std::vector<int> b_index, b_tool, b_tip;
  std::vector<ConstraintKind> b_kind;
  std::vector<double> b_value, b_normal;
  std::vector<char> released;  // per built constraint: dropped for adhesion

  Impl(const SurfaceModel& m, std::vector<ToolGeometry> geometries, const ContactSettings& s,
       const SolverLimits& l)
      : model(m), settings(s), limits(l), solver(m, l) {
    const int n = m.compliance_vertex_count();
    const int t = static_cast<int>(geometries.size());
    PALPATE_DEMAND(t >= 1 && t <= 64);
    per_tool_cap = std::min(settings.max_contacts_per_tool, limits.max_constraints / t);
    PALPATE_DEMAND(per_tool_cap >= 1);
    for (auto& g : geometries) {
      Tool tool;
      tool.geometry = std::move(g);
      tool.held.reserve(static_cast<std::size_t>(per_tool_cap));
      tool.tips.resize(static_cast<std::size_t>(n));
      tools.push_back(std::move(tool));
    }
    rest.resize(static_cast<std::size_t>(n));
    vertex_normal.resize(static_cast<std::size_t>(n));
    box_min = Vector3d::Constant(std::numeric_limits<double>::infinity());
    box_max = -box_min;
    const DrawnSurface& surface = m.surface;
    for (int v = 0; v < surface.vertex_count(); ++v) {
      const Vector3d x = surface.rest_position(v);
      if (v < n) rest[static_cast<std::size_t>(v)] = x;
      box_min = box_min.cwiseMin(x);
      box_max = box_max.cwiseMax(x);
    }
    // A vertex without a normal (in no triangle of non-zero area) pushes along z.
    const Eigen::MatrixX3d surface_normals = vertex_normals(surface);
    for (int v = 0; v < n; ++v)
      vertex_normal[static_cast<std::size_t>(v)] =
          surface_normals.row(v).squaredNorm() > 0 ? Vector3d(surface_normals.row(v).transpose())
                                                   : Vector3d::UnitZ();
    owner.assign(static_cast<std::size_t>(n), -1);
    previous_tip_owner.assign(static_cast<std::size_t>(n), -1);
    candidates.resize(static_cast<std::size_t>(n));
    candidate_position.resize(static_cast<std::size_t>(n));
    candidate_depth.resize(static_cast<std::size_t>(n));
    const auto k = static_cast<std::size_t>(limits.max_constraints);
    indices.resize(k);
    tool_of.resize(k);
    tip_of.resize(k);
    forces.resize(3 * k);
    positions.resize(3 * k);
    normals.resize(3 * k);
    b_index.resize(k);
    b_tool.resize(k);
    b_tip.resize(k);
    b_kind.resize(k);
    b_value.resize(3 * k);
    b_normal.resize(3 * k);
    released.resize(k);
  }

  /// Deformed position of compliance vertex @p j under the last solve's forces.
  Vector3d deformed(int j) const {
    Vector3d u = Vector3d::Zero();
    for (int c = 0; c < count; ++c)
      u.noalias() += model.G_block(j, indices[static_cast<std::size_t>(c)]) *
                     Eigen::Map<const Vector3d>(&forces[3 * static_cast<std::size_t>(c)]);
    return rest[static_cast<std::size_t>(j)] + u;
  }

  /// Longest reach of a tool from its hinge along z, and its radius of interest.
  static double reach_length(const ToolGeometry& g) {
    return std::max(g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0, g.jaw_length_m);
  }
  double tip_length(const ToolGeometry& g) const {
    return g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0;
  }

  /// Vertices near tool @p t with their deformed positions; returns their count.
  int gather_candidates(const Tool& tool) {
    const ToolGeometry& g = tool.geometry;
    const Vector3d axis = tool.rotation.col(2);
    const double length = reach_length(g);
    const double wedge = g.jaw_length_m * std::tan(0.5 * g.max_jaw_angle_rad);
    const double radius = std::max(g.tip_radius_m, wedge + g.tip_radius_m) +
                          settings.search_margin_m + max_displacement;
    const double radius2 = radius * radius;
    int n = 0;
    const int vertices = model.compliance_vertex_count();
    for (int j = 0; j < vertices; ++j) {
      const Vector3d& x = rest[static_cast<std::size_t>(j)];
      if ((x - closest_on_segment(tool.pose.position_m, axis, length, x)).squaredNorm() <= radius2)
        candidates[static_cast<std::size_t>(n++)] = j;
    }
    for (int c = 0; c < n; ++c)
      candidate_position[static_cast<std::size_t>(c)] =
          deformed(candidates[static_cast<std::size_t>(c)]);
    return n;
  }

  /// Is the deformed point @p x between the jaws of @p tool opened at @p angle?
  static bool between_jaws(const Tool& tool, const Vector3d& x, double angle) {
    const ToolGeometry& g = tool.geometry;
    if (g.jaw_length_m <= 0) return false;
    const Vector3d local = tool.rotation.transpose() * (x - tool.pose.position_m);
    return local.z() >= 0 && local.z() <= g.jaw_length_m &&
           std::abs(local.y()) <= 0.5 * g.jaw_width_m + g.tip_radius_m &&
           std::abs(local.x()) <= local.z() * std::tan(0.5 * angle) + g.tip_radius_m;
  }

  /// Grasp state machine of tool @p t for its new jaw angle (before contacts).
  void update_grasp(int t, ToolOutput& out) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    const ToolGeometry& g = tool.geometry;
    const double jaw = tool.pose.jaw_angle_rad;
    if (!tool.held.empty()) {
      if (jaw >= g.release_angle_rad) {
        tool.held.clear();
        push_event(out, ToolEventKind::kRelease);
      }
      return;
    }
    const bool closing = tool.has_previous_jaw && tool.previous_jaw > g.grasp_angle_rad &&
                         jaw <= g.grasp_angle_rad && g.jaw_length_m > 0;
    if (!closing) return;
    const int n = gather_candidates(tool);
    // The tissue between the jaws as they were, and what the tip touched.
    for (int c = 0; c < n && static_cast<int>(tool.held.size()) < per_tool_cap; ++c) {
      const int j = candidates[static_cast<std::size_t>(c)];
      const Vector3d& x = candidate_position[static_cast<std::size_t>(c)];
      const bool touched = previous_tip_owner[static_cast<std::size_t>(j)] == t;
      if (!touched && !between_jaws(tool, x, tool.previous_jaw)) continue;
      if (owner_held_elsewhere(j, t)) continue;
      Vector3d local = tool.rotation.transpose() * (x - tool.pose.position_m);
      const double side = local.x() >= 0 ? 1.0 : -1.0;
      local.x() = 0;  // squeezed between the closed jaws
      local.z() = std::clamp(local.z(), 0.0, g.jaw_length_m);
      tool.held.push_back({j, local, side});
    }
    if (!tool.held.empty()) push_event(out, ToolEventKind::kGrasp);
  }

  bool owner_held_elsewhere(int j, int t) const {
    for (int other = 0; other < static_cast<int>(tools.size()); ++other) {
      if (other == t) continue;
      for (const auto& h : tools[static_cast<std::size_t>(other)].held)
        if (h.index == j) return true;
    }
    return false;
  }

  static void push_event(ToolOutput& out, ToolEventKind kind) {
    if (out.event_count < static_cast<int>(out.events.size()))
      out.events[static_cast<std::size_t>(out.event_count++)] = kind;
  }

  /// Tip contacts of tool @p t among its candidates (gathered just before).
  void find_tips(int t, int n) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    const ToolGeometry& g = tool.geometry;
    const Vector3d axis = tool.rotation.col(2);
    const double r = g.tip_radius_m;
    const double shell = 0.05 * r;  // a contact stays while within 5 % of r outside the tip
    const bool jaws_open = g.jaw_length_m > 0 && tool.pose.jaw_angle_rad > g.grasp_angle_rad;
    int found = 0;
    for (int c = 0; c < n; ++c) {
      const int j = candidates[static_cast<std::size_t>(c)];
      if (owner[static_cast<std::size_t>(j)] >= 0) continue;
      const Vector3d& x = candidate_position[static_cast<std::size_t>(c)];
      const Vector3d q = closest_on_segment(tool.pose.position_m, axis, tip_length(g), x);
      const double distance = (x - q).norm();
      const bool was = previous_tip_owner[static_cast<std::size_t>(j)] == t;
      if (!(distance < r || (was && distance < r + shell))) continue;
      // Tissue between open jaws is not pushed: it may be grasped.
      if (jaws_open && tool.held.empty() && between_jaws(tool, x, tool.pose.jaw_angle_rad) && !was)
        continue;
      // Put back on the tip's surface at the nearest point, pushed along the
      // tip's surface normal there. That normal's tangent plane bounds the
      // tip (it is convex): a vertex whose free position is inside the tip
      // is on the push side of it, so a sliding contact never finds itself
      // pulling while the tissue would spring into the tip (no flicker).
      const Vector3d normal = distance > 1e-9 * r
                                  ? Vector3d((x - q) / distance)
                                  : Vector3d(-vertex_normal[static_cast<std::size_t>(j)]);
      const Vector3d target = q + r * normal;
      tool.tips[static_cast<std::size_t>(found++)] = {j, r - distance, normal, target};
    }
    // Keep the deepest.
    if (found > per_tool_cap - static_cast<int>(tool.held.size())) {
      const int keep = std::max(0, per_tool_cap - static_cast<int>(tool.held.size()));
      std::nth_element(
          tool.tips.begin(), tool.tips.begin() + keep, tool.tips.begin() + found,
          [](const TipCandidate& a, const TipCandidate& b) { return a.depth > b.depth; });
      found = keep;
    }
    tool.tip_count = found;
    for (int c = 0; c < found; ++c)
      owner[static_cast<std::size_t>(tool.tips[static_cast<std::size_t>(c)].index)] = t;
  }

  /// Every living tool's contacts at its latest pose, one solve for all.
  /// On failure the previous solution stays.
  RequestStatus find_contacts_and_solve() {
    // Held vertices first: they win a vertex over any tip.
    for (int t = 0; t < static_cast<int>(tools.size()); ++t)
      if (tools[static_cast<std::size_t>(t)].alive)
        for (const auto& h : tools[static_cast<std::size_t>(t)].held)
          owner[static_cast<std::size_t>(h.index)] = t;
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      Tool& tool = tools[static_cast<std::size_t>(t)];
      if (tool.alive && tool.in_watchdog) {
        // Ramping out: the last contacts, scaled down, not found again (the
        // scaled-back tissue would leave the frozen tip and come back).
        for (int c = 0; c < tool.tip_count; ++c)
          owner[static_cast<std::size_t>(tool.tips[static_cast<std::size_t>(c)].index)] = t;
        continue;
      }
      tool.tip_count = 0;
      if (tool.alive) find_tips(t, gather_candidates(tool));
    }
    return solve_all();
  }

  /// Builds, solves (with adhesion release) and stores every tool's constraints.
  RequestStatus solve_all() {
    building = 0;
    auto add = [&](int index, int t, int tip, ConstraintKind kind, const Vector3d& value,
                   const Vector3d& normal) {
      const auto b = static_cast<std::size_t>(building++);
      b_index[b] = index;
      b_tool[b] = t;
      b_tip[b] = tip;
      b_kind[b] = kind;
      Eigen::Map<Vector3d>{&b_value[3 * b]} = value;
      Eigen::Map<Vector3d>{&b_normal[3 * b]} = normal;
      released[b] = 0;
    };
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      if (!tool.alive) continue;
      for (const auto& h : tool.held) {
        const Vector3d target = tool.pose.position_m + tool.rotation * h.local;
        add(h.index, t, -1, ConstraintKind::kDisplacement,
            tool.scale * (target - rest[static_cast<std::size_t>(h.index)]), Vector3d::Zero());
      }
    }
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      if (!tool.alive) continue;
      for (int c = 0; c < tool.tip_count; ++c) {
        const TipCandidate& tip = tool.tips[static_cast<std::size_t>(c)];
        const Vector3d u = tool.scale * (tip.target - rest[static_cast<std::size_t>(tip.index)]);
        if (tool.geometry.friction > 0)
          add(tip.index, t, c, ConstraintKind::kDisplacement, u, tip.normal);
        else
          add(tip.index, t, c, ConstraintKind::kNormalDisplacement,
              Vector3d(tip.normal.dot(u), 0, 0), tip.normal);
      }
    }

    RequestStatus status = RequestStatus::kOk;
    const int iterations = std::max(1, settings.max_iterations);
    for (int iteration = 0; iteration < iterations; ++iteration) {
      int k = 0;
      for (int b = 0; b < building; ++b) k += released[static_cast<std::size_t>(b)] ? 0 : 1;
      status = solver.begin(static_cast<std::size_t>(k));
      for (int b = 0; b < building && status == RequestStatus::kOk; ++b) {
        const auto bb = static_cast<std::size_t>(b);
        if (released[bb]) continue;
        status =
            solver.add(model.surface.vertex_ids[static_cast<std::size_t>(b_index[bb])],
                       static_cast<std::int32_t>(b_kind[bb]), &b_value[3 * bb], &b_normal[3 * bb]);
      }
      if (status == RequestStatus::kOk) status = solver.solve();
      ++solve_count;
      if (status != RequestStatus::kOk) break;
      // The last allowed solve stands as solved: the contacts stored are
      // exactly its constraints, and their forces its forces (changing the
      // set now would pair each force with another vertex).
      if (iteration + 1 == iterations) break;
      // Adhesion: a tip contact whose force pulls the tissue towards the
      // tool lets go. Friction: a sticking one whose tangential force
      // exceeds friction × normal force slides.
      bool any = false;
      const auto f = solver.forces();
      int j = 0;
      for (int b = 0; b < building; ++b) {
        const auto bb = static_cast<std::size_t>(b);
        if (released[bb]) continue;
        if (b_tip[bb] >= 0) {
          const Eigen::Map<const Vector3d> n(&b_normal[3 * bb]);
          const Vector3d fc = f.segment<3>(3 * j);
          const double normal_force = fc.dot(n);
          if (b_kind[bb] == ConstraintKind::kDisplacement &&
              (normal_force < 0 ||
               (fc - normal_force * n).norm() >
                   tools[static_cast<std::size_t>(b_tool[bb])].geometry.friction * normal_force)) {
            // Outside the friction cone (a pull included): it slides first.
            b_kind[bb] = ConstraintKind::kNormalDisplacement;
            b_value[3 * bb] = n.dot(Eigen::Map<const Vector3d>(&b_value[3 * bb]));
            b_value[3 * bb + 1] = b_value[3 * bb + 2] = 0;
            any = true;
          } else if (normal_force < 0) {
            released[bb] = 1;  // a sliding contact that pulls: adhesion, let go
            any = true;
          }
        }
        ++j;
      }
      if (!any) break;
    }
    for (auto& o : owner) o = -1;  // cleared sparsely below would be cheaper; n is small
    if (status != RequestStatus::kOk) {
      const std::size_t length = strnlen(solver.message(), sizeof message - 1);
      std::memcpy(message, solver.message(), length);
      message[length] = '\0';
      return status;
    }
    store_solution();
    return RequestStatus::kOk;
  }

  void store_solution() {
    std::fill(previous_tip_owner.begin(), previous_tip_owner.end(), -1);
    const auto f = solver.forces();
    const auto u = solver.displacements();
    count = 0;
    max_displacement = 0;
    for (auto& tool : tools) {
      tool.raw_force.setZero();
      tool.raw_torque.setZero();
      tool.raw_grip = 0;
      tool.contacts = 0;
    }
    for (int b = 0; b < building; ++b) {
      const auto bb = static_cast<std::size_t>(b);
      if (released[bb]) continue;
      const auto c = static_cast<std::size_t>(count);
      indices[c] = b_index[bb];
      tool_of[c] = b_tool[bb];
      tip_of[c] = b_tip[bb];
      const Vector3d force = f.segment<3>(3 * count);
      const Vector3d displacement = u.segment<3>(3 * count);
      Eigen::Map<Vector3d>{&forces[3 * c]} = force;
      const Vector3d position = rest[static_cast<std::size_t>(b_index[bb])] + displacement;
      Eigen::Map<Vector3d>{&positions[3 * c]} = position;
      const bool sliding = b_kind[bb] == ConstraintKind::kNormalDisplacement;
      for (int d = 0; d < 3; ++d)
        normals[3 * c + static_cast<std::size_t>(d)] =
            sliding ? b_normal[3 * bb + static_cast<std::size_t>(d)] : 0.0;
      max_displacement = std::max(max_displacement, displacement.norm());
      Tool& tool = tools[static_cast<std::size_t>(b_tool[bb])];
      tool.raw_force -= force;  // the organ pushes the tool back
      tool.raw_torque += (position - tool.pose.position_m).cross(-force);
      if (b_tip[bb] < 0)
        tool.raw_grip += 0.5 * std::abs(force.dot(tool.rotation.col(0)));
      else
        previous_tip_owner[static_cast<std::size_t>(b_index[bb])] = b_tool[bb];
      ++tool.contacts;
      ++count;
    }
  }

  /// The feedback of tool @p t at @p now_s: clamp, slew limit, state events.
  void make_output(int t, double now_s, ToolOutput& out) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    const ToolGeometry& g = tool.geometry;
    Vector3d target = tool.raw_force;
    bool limited = false;
    if (const double magnitude = target.norm(); magnitude > g.force_limit_n) {
      target *= g.force_limit_n / magnitude;
      limited = true;
    }
    const Vector3d previous = tool.has_output ? tool.out.force_n : Vector3d::Zero();
    const double dt = tool.has_output ? std::clamp(now_s - tool.last_output_s, 0.0, 0.01) : 0.001;
    const double step = g.max_force_rate_n_per_s * dt;
    Vector3d force = target;
    if (const double change = (target - previous).norm(); change > step) {
      force = previous + (target - previous) * (step / change);
      limited = true;
    }
    if (!tool.alive) {  // ramped out: nothing left to feel
      force.setZero();
      limited = false;
    }
    const double raw = tool.raw_force.norm();
    const double torque_scale = raw > 0 ? std::min(1.0, force.norm() / raw) : 0.0;
    out.force_n = force;
    out.torque_nm = tool.raw_torque * torque_scale;
    out.grip_n = tool.raw_grip * torque_scale;
    out.contacts = tool.alive ? tool.contacts : 0;
    out.held = tool.alive ? static_cast<int>(tool.held.size()) : 0;
    out.force_limited = limited;
    out.watchdog = tool.in_watchdog;
    out.sequence = tool.pose.sequence;
    out.send_time_ns = tool.pose.send_time_ns;
    const ToolState state = !tool.held.empty() && tool.alive ? ToolState::kGrasping
                            : out.contacts > 0               ? ToolState::kTouching
                                                             : ToolState::kFree;
    if (state != tool.shown_state) {
      if (state == ToolState::kTouching && tool.shown_state == ToolState::kFree)
        push_event(out, ToolEventKind::kTouch);
      if (state == ToolState::kFree && tool.shown_state == ToolState::kTouching)
        push_event(out, ToolEventKind::kLeave);
    }
    out.state = state;
    tool.shown_state = state;
    tool.out = out;
    tool.has_output = true;
    tool.last_output_s = now_s;
  }
};

ToolContactEngine::ToolContactEngine(const SurfaceModel& model, std::vector<ToolGeometry> tools,
                                     const ContactSettings& settings, const SolverLimits& limits)
    : impl_(std::make_unique<Impl>(model, std::move(tools), settings, limits)) {}
ToolContactEngine::~ToolContactEngine() = default;

int ToolContactEngine::tool_count() const { return static_cast<int>(impl_->tools.size()); }

int ToolContactEngine::tool_index(std::string_view id) const {
  for (std::size_t t = 0; t < impl_->tools.size(); ++t)
    if (impl_->tools[t].geometry.id == id) return static_cast<int>(t);
  return -1;
}

const ToolGeometry& ToolContactEngine::tool(int index) const {
  return impl_->tools.at(static_cast<std::size_t>(index)).geometry;
}

PoseProblem ToolContactEngine::check(int t, ToolPoseInput& pose) const {
  const Impl& s = *impl_;
  const auto& tool = s.tools.at(static_cast<std::size_t>(t));
  const std::string& id = tool.geometry.id;
  const auto& q = pose.orientation.coeffs();
  if (!pose.position_m.allFinite() || !q.allFinite() || !std::isfinite(pose.jaw_angle_rad)) {
    s.explain("pose of tool '{}' has a non-finite position, orientation or jaw angle", id);
    return PoseProblem::kNonFinite;
  }
  const double norm = q.norm();
  if (!(norm > 0.9 && norm < 1.1)) {
    s.explain(
        "orientation of tool '{}' is a quaternion of norm {:.3g}; accepted: a unit "
        "quaternion (norm within 0.9-1.1, normalized here)",
        id, norm);
    return PoseProblem::kBadQuaternion;
  }
  pose.orientation.normalize();
  const double max_jaw = tool.geometry.max_jaw_angle_rad;
  if (!(pose.jaw_angle_rad >= 0 && pose.jaw_angle_rad <= max_jaw + 1e-9)) {
    s.explain("jaw angle {:.4g}° of tool '{}' is {} its limit; accepted: 0° to {:.4g}°",
              in_degrees(pose.jaw_angle_rad), id, pose.jaw_angle_rad < 0 ? "under" : "over",
              in_degrees(max_jaw));
    return PoseProblem::kBadJawAngle;
  }
  const double margin_m = s.settings.workspace_margin_m;
  const Eigen::Vector3d margin = Eigen::Vector3d::Constant(margin_m);
  if ((pose.position_m.array() < (s.box_min - margin).array()).any() ||
      (pose.position_m.array() > (s.box_max + margin).array()).any()) {
    s.explain(
        "tool '{}' at ({:.4g}, {:.4g}, {:.4g}) m is more than {:.4g} m outside the "
        "organ's box ({:.4g}, {:.4g}, {:.4g})-({:.4g}, {:.4g}, {:.4g}) m",
        id, pose.position_m.x(), pose.position_m.y(), pose.position_m.z(), margin_m, s.box_min.x(),
        s.box_min.y(), s.box_min.z(), s.box_max.x(), s.box_max.y(), s.box_max.z());
    return PoseProblem::kOutOfWorkspace;
  }
  // A pose not newer than the last one is stale, unless the watchdog fired
  // since (a restarted client counts again from 1).
  if (tool.alive && !tool.in_watchdog && tool.has_sequence && pose.sequence <= tool.pose.sequence) {
    s.explain("pose {} of tool '{}' is not newer than pose {} already taken", pose.sequence, id,
              tool.pose.sequence);
    return PoseProblem::kStale;
  }
  return PoseProblem::kNone;
}

const char* ToolContactEngine::problem_message() const { return impl_->problem; }

RequestStatus ToolContactEngine::update(int t, const ToolPoseInput& pose, double now_s) {
  Impl& s = *impl_;
  auto& tool = s.tools.at(static_cast<std::size_t>(t));
  ToolOutput out;
  if (tool.in_watchdog || !tool.alive) {
    if (tool.in_watchdog || tool.has_sequence) Impl::push_event(out, ToolEventKind::kResumed);
    tool.in_watchdog = false;
    tool.scale = 1;
  }
  tool.alive = true;
  tool.has_previous_jaw = tool.has_sequence;
  tool.previous_jaw = tool.pose.jaw_angle_rad;
  tool.pose = pose;
  tool.has_sequence = true;
  tool.rotation = pose.orientation.toRotationMatrix();
  tool.last_pose_s = now_s;

  s.update_grasp(t, out);
  const RequestStatus status = s.find_contacts_and_solve();
  s.make_output(t, now_s, out);
  return status;
}

std::uint64_t ToolContactEngine::watchdog(double now_s) {
  Impl& s = *impl_;
  std::uint64_t changed = 0;
  std::array<ToolOutput, 64> outs{};
  for (int t = 0; t < static_cast<int>(s.tools.size()); ++t) {
    auto& tool = s.tools[static_cast<std::size_t>(t)];
    if (!tool.alive) continue;
    const double silent = now_s - tool.last_pose_s - s.settings.watchdog_timeout_s;
    if (silent <= 0) continue;
    if (!tool.in_watchdog) {
      tool.in_watchdog = true;
      Impl::push_event(outs[static_cast<std::size_t>(t)], ToolEventKind::kWatchdog);
    }
    tool.scale = std::clamp(1 - silent / s.settings.watchdog_ramp_s, 0.0, 1.0);
    changed |= std::uint64_t{1} << t;
  }
  if (changed == 0) return 0;
  // A tool ramped to zero lets go of everything and is forgotten.
  for (auto& tool : s.tools)
    if (tool.alive && tool.scale == 0) {
      tool.held.clear();
      tool.alive = false;
    }
  s.find_contacts_and_solve();
  for (int t = 0; t < static_cast<int>(s.tools.size()); ++t)
    if (changed >> t & 1) s.make_output(t, now_s, outs[static_cast<std::size_t>(t)]);
  return changed;
}

bool ToolContactEngine::end(int t, double now_s) {
  Impl& s = *impl_;
  auto& tool = s.tools.at(static_cast<std::size_t>(t));
  if (!tool.alive && !tool.has_sequence) return false;
  const bool had_contacts = tool.alive && (tool.contacts > 0 || !tool.held.empty());
  tool.held.clear();
  tool.alive = false;
  tool.in_watchdog = false;
  tool.scale = 1;
  tool.has_sequence = false;  // its next pose starts a new session, not a resumed one
  tool.has_previous_jaw = false;
  tool.tip_count = 0;
  // The others feel the tissue it let go of.
  if (had_contacts) s.find_contacts_and_solve();
  ToolOutput out;
  s.make_output(t, now_s, out);                       // a touching tool leaves first,
  Impl::push_event(tool.out, ToolEventKind::kEnded);  // then its session ends
  return true;
}

const ToolOutput& ToolContactEngine::output(int t) const {
  return impl_->tools.at(static_cast<std::size_t>(t)).out;
}
const ToolPoseInput& ToolContactEngine::pose(int t) const {
  return impl_->tools.at(static_cast<std::size_t>(t)).pose;
}
const char* ToolContactEngine::solver_message() const { return impl_->message; }
std::span<const int> ToolContactEngine::contact_indices() const {
  return {impl_->indices.data(), static_cast<std::size_t>(impl_->count)};
}
std::span<const double> ToolContactEngine::contact_forces() const {
  return {impl_->forces.data(), 3 * static_cast<std::size_t>(impl_->count)};
}
std::span<const int> ToolContactEngine::contact_tools() const {
  return {impl_->tool_of.data(), static_cast<std::size_t>(impl_->count)};
}
std::span<const double> ToolContactEngine::contact_normals() const {
  return {impl_->normals.data(), 3 * static_cast<std::size_t>(impl_->count)};
}
std::span<const double> ToolContactEngine::contact_positions() const {
  return {impl_->positions.data(), 3 * static_cast<std::size_t>(impl_->count)};
}
std::uint64_t ToolContactEngine::solves() const { return impl_->solve_count; }

}  // namespace palpate
