#include "palpate/runtime/tool_contact.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <span>

#include "palpate/core/error.hpp"
#include "palpate/runtime/contact/background_loads.hpp"
#include "palpate/runtime/contact/contact_episodes.hpp"
#include "palpate/runtime/contact/contact_rows.hpp"
#include "palpate/runtime/contact/contact_solution.hpp"
#include "palpate/runtime/contact/deformed_surface.hpp"
#include "palpate/runtime/contact/feedback_limits.hpp"
#include "palpate/runtime/contact/grasp_state.hpp"
#include "palpate/runtime/contact/jaw_grasp.hpp"
#include "palpate/runtime/contact/local_model.hpp"
#include "palpate/runtime/contact/tip_contacts.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/solve/active_set.hpp"

namespace palpate {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

}  // namespace

struct ToolContactEngine::Impl {
  const SurfaceModel& model;
  // Warped compliance (docs/model/warped.md, "Large rotations: warped compliance"):
  // null for the linear model.
  const RotationField* warping = nullptr;
  ContactSettings settings;
  SolverLimits limits;
  detail::ActiveSet active_set;
  int per_tool_cap = 0;

  struct Tool {
    ToolGeometry geometry;
    bool alive = false;  // a pose was taken and the watchdog has not ramped it out
    ToolPoseInput pose;
    Matrix3d rotation = Matrix3d::Identity();
    double last_pose_s = 0;
    bool has_sequence = false;
    double scale = 1;  // watchdog ramp, 1 → 0
    bool in_watchdog = false;
    std::vector<detail::TipCandidate> tips;  // this tick's tip contacts, deepest first
    int tip_count = 0;
    std::vector<detail::TipCandidate> kept;  // last tick's, while the search reads them
    ToolOutput out;
    ToolOutput pending;    // solve()'s events, until answer()
    bool answered = true;  // answer() since the last solve()
    bool has_output = false;
    double last_output_s = 0;
    detail::ContactEpisodes episodes;  // its touch and leave events
  };
  std::vector<Tool> tools;

  // The drawn surface as the last solve's loads deform it.
  detail::DeformedSurface surface;

  detail::GraspState grasps;  // what every tool's jaws hold, and which vertices this solve
  // Scratch, sized once.
  detail::TipContacts tip_search;

  // The last successful solve: every tool's contact points, their loads,
  // the tools' raw wrenches.
  detail::ContactSolution solution;
  // Known loads that are not the tools' (set_background_loads): they deform
  // the surface with the tools' loads and every row's imposed displacement
  // discounts them.
  detail::BackgroundLoads background;
  // The background as the surface has it: taken at each solve's end with
  // the tools' loads, so the surface the next tick's contacts are found on
  // is the one the last solve left: its tools' forces balance the
  // background it discounted. The latest background with those forces is
  // a surface no solve produced; finding contacts on it made a tool
  // pressing the rest beside a served region wander (1–4 contacts, never
  // settling, in bench/hybrid_tick_bench's contact loop at the 16 mm ball).
  detail::BackgroundLoads surface_background;
  detail::LoadColumns background_columns;  // both backgrounds' G^{b v}
  char message[256] = {};
  mutable char problem[256] = {};  // why check() refused the last pose it refused

  /// Writes the reason for a refused pose into `problem` (cut to fit).
  template <typename... Args>
  void explain(fmt::format_string<Args...> format, Args&&... args) const {
    const auto written =
        fmt::format_to_n(problem, sizeof problem - 1, format, std::forward<Args>(args)...);
    *written.out = '\0';
  }

  // The constraint set being built, a row per held point and tip point,
  // with what the local model needs of each; the active set holds the
  // factor of the stored solution when `factored` (the last solve
  // succeeded): the local model is read off it.
  detail::ContactRows constraints;
  detail::LocalModel linearization;
  bool factored = false;

  Impl(const SurfaceModel& m, std::vector<ToolGeometry> geometries, const ContactSettings& s,
       const SolverLimits& l, const RotationField* w)
      : model(m),
        warping(w),
        settings(s),
        limits(l),
        active_set(m, l),
        per_tool_cap(per_tool_capacity(s, l, static_cast<int>(geometries.size()))),
        surface(m, w),
        grasps(static_cast<int>(geometries.size()), per_tool_cap, l.max_constraints,
               m.compliance_vertex_count(), m.surface.triangle_count()),
        tip_search(m.surface.triangle_count() + per_tool_cap),
        solution(static_cast<int>(geometries.size()), l.max_constraints,
                 m.compliance_vertex_count(), m.surface.triangle_count()),
        constraints(l.max_constraints, static_cast<int>(geometries.size()), surface, background),
        linearization(std::max(1, l.max_constraints), m.compliance_vertex_count()) {
    for (auto& g : geometries) {
      Tool tool;
      tool.geometry = std::move(g);
      tool.tips.resize(static_cast<std::size_t>(per_tool_cap));
      tool.kept.resize(static_cast<std::size_t>(per_tool_cap));
      tools.push_back(std::move(tool));
    }
    surface.set_loads(0, solution.load_indices().data(), solution.load_forces().data(), 0);
  }

  /// Contacts a tool may have: its share of the solve's constraints, at most
  /// ContactSettings::max_contacts_per_tool, for 1 to 64 @p tools.
  static int per_tool_capacity(const ContactSettings& s, const SolverLimits& l, int tools) {
    PALPATE_DEMAND(tools >= 1 && tools <= 64);
    const int cap = std::min(s.max_contacts_per_tool, l.max_constraints / tools);
    PALPATE_DEMAND(cap >= 1);
    return cap;
  }

  /// How far from a tool's segment its candidate vertices lie at rest, m.
  double search_radius(const ToolGeometry& g) const {
    const double wedge = g.jaw_length_m * std::tan(0.5 * g.max_jaw_angle_rad);
    return std::max(g.tip_radius_m, wedge + g.tip_radius_m) + settings.search_margin_m +
           solution.max_displacement_m() + background.reach_m(surface.max_softness());
  }

  /// The distinct surface triangles around tool @p tool's candidate
  /// vertices (those within search_radius of its segment at rest), in the
  /// order met: a view the caller may rewrite.
  std::span<int> triangles_near(const Tool& tool) {
    const ToolGeometry& g = tool.geometry;
    return surface.triangles_around(surface.vertices_near(
        tool.pose.position_m, tool.rotation.col(2), detail::reach_length(g), search_radius(g)));
  }

  static detail::JawsAtClosing jaws_of(const Tool& tool, double opening) {
    return {tool.pose.position_m, tool.rotation, &tool.geometry, opening};
  }

  /// Grasp state machine of tool @p t for its new jaw angle (before contacts).
  void update_grasp(int t, ToolOutput& out) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    const auto step = grasps.step(t, tool.pose.jaw_angle_rad, tool.geometry);
    if (step == detail::GraspState::Step::kReleased) push_event(out, ToolEventKind::kRelease);
    if (step != detail::GraspState::Step::kClosing) return;
    surface.next_epoch();
    const std::span<const int> near = triangles_near(tool);
    if (grasps.pick_up(t, jaws_of(tool, grasps.opening_rad(t)), near, surface, solution.points()))
      push_event(out, ToolEventKind::kGrasp);
  }

  static void push_event(ToolOutput& out, ToolEventKind kind) {
    if (out.event_count < static_cast<int>(out.events.size()))
      out.events[static_cast<std::size_t>(out.event_count++)] = kind;
  }

  /// Tool @p t's tip contacts (docs/tools.md, "Tip contacts"), its
  /// @p had points of the last tick kept where they still touch.
  void find_tips(int t, int had) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    std::swap(tool.tips, tool.kept);
    const int room = std::max(0, per_tool_cap - static_cast<int>(grasps.held(t).size()));
    const detail::TipQuery query{t,
                                 &tool.geometry,
                                 tool.pose.position_m,
                                 tool.rotation,
                                 tool.pose.jaw_angle_rad,
                                 grasps.holding(t),
                                 search_radius(tool.geometry)};
    tool.tip_count = tip_search.find(query, surface, grasps.owner(), solution.triangle_owner(),
                                     {tool.kept.data(), static_cast<std::size_t>(had)},
                                     {tool.tips.data(), static_cast<std::size_t>(room)});
  }

  /// Every living tool's contacts at its latest pose, one solve for all.
  /// On failure the previous solution stays.
  RequestStatus find_contacts_and_solve() {
    // Held vertices first: they win a vertex over any tip.
    for (int t = 0; t < static_cast<int>(tools.size()); ++t)
      if (tools[static_cast<std::size_t>(t)].alive) grasps.claim(t);
    surface.next_epoch();
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      Tool& tool = tools[static_cast<std::size_t>(t)];
      // Ramping out: the last contacts, scaled down, not found again (the
      // scaled-back tissue would leave the frozen tip and come back).
      if (tool.alive && tool.in_watchdog) continue;
      const int had = tool.tip_count;
      tool.tip_count = 0;
      if (tool.alive) find_tips(t, had);
    }
    return solve_all();
  }

  /// Builds, solves (with adhesion release) and stores every tool's constraints.
  RequestStatus solve_all() {
    constraints.begin();
    for (int t = 0; t < static_cast<int>(tools.size()); ++t)
      if (tools[static_cast<std::size_t>(t)].alive)
        constraints.add_held(row_tool(t), grasps.held(t));
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      if (tool.alive)
        constraints.add_tips(row_tool(t),
                             {tool.tips.data(), static_cast<std::size_t>(tool.tip_count)});
    }
    const RequestStatus status =
        active_set.solve(constraints.rows(), settings.max_iterations,
                         settings.incremental_active_set ? detail::ActiveSetMethod::kIncremental
                                                         : detail::ActiveSetMethod::kRefactor);
    factored = status == RequestStatus::kOk;
    grasps.unclaim();
    if (status != RequestStatus::kOk) {
      const std::size_t length = strnlen(active_set.message(), sizeof message - 1);
      std::memcpy(message, active_set.message(), length);
      message[length] = '\0';
      return status;
    }
    store_solution();
    return RequestStatus::kOk;
  }

  /// Tool @p t as its rows need it (ContactRows::add_held, add_tips).
  detail::ContactRows::Tool row_tool(int t) const {
    const Tool& tool = tools[static_cast<std::size_t>(t)];
    return {t, &tool.geometry, tool.pose.position_m, tool.rotation, tool.scale, tool.in_watchdog};
  }

  /// The solve's active rows as the stored solution (ContactSolution); the
  /// surface deformed by its loads from the next tick on.
  void store_solution() {
    solution.begin();
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      constraints.solved(t, tool.alive && !tool.in_watchdog, tool.pose.position_m, tool.rotation);
    }
    for (int b = 0; b < constraints.count(); ++b) {
      const bool active = constraints.row(b).state == detail::ActiveRow::kActive;
      if (constraints.tip(b) >= 0) {  // kept next tick as touching or not, sliding or not
        detail::TipCandidate& tip = tools[static_cast<std::size_t>(constraints.tool(b))]
                                        .tips[static_cast<std::size_t>(constraints.tip(b))];
        tip.touched = active;
        // Sticking: its three components imposed, no slip (a frictionless
        // point's normal row never sticks, so it is never kept).
        const detail::ActiveRow& row = constraints.row(b);
        const bool stuck = active && row.kind == ConstraintKind::kDisplacement && !row.slipped;
        tip.stuck = stuck ? tip.stuck + 1 : 0;
        constraints.local(b).material = tip.stuck >= detail::kMaterialAfter;
      }
      if (!active) continue;
      const Tool& tool = tools[static_cast<std::size_t>(constraints.tool(b))];
      const ContactPoint& point =
          solution.add(active_set, constraints, b, tool.pose.position_m, tool.rotation, background);
      detail::LocalRow& l = constraints.local(b);
      l.position = point.position_m;
      l.force = point.force_n;
      l.material_force = solution.material_force(solution.count() - 1);
    }
    solution.gather_loads();
    // The surface moves under these and the background's (set_background).
    surface.set_loads(solution.load_count(), solution.load_indices().data(),
                      solution.load_forces().data(), solution.load_energy_j());
    if (background.count() > 0 || surface_background.count() > 0)
      surface_background.copy_from(background);
  }

  /// Tool @p t's contact wrench linearized about its pose (LocalContactModel,
  /// docs/tools.md "The local model"), from the factor of the stored solve.
  void local_model(int t, LocalContactModel& local) {
    const Tool& tool = tools[static_cast<std::size_t>(t)];
    local.valid = true;
    local.position_m = tool.pose.position_m;
    local.orientation = tool.pose.orientation;
    local.holding = tool.alive && grasps.holding(t);
    const detail::ContactSolution::RawWrench& raw = solution.wrench(t);
    local.force_n = tool.alive ? raw.force_n : Vector3d::Zero();
    local.torque_nm = tool.alive ? raw.torque_nm : Vector3d::Zero();
    local.stiffness.setZero();
    if (!tool.alive || raw.contacts == 0) return;
    local.stiffness = linearization.stiffness(constraints.rows(), constraints.local_rows(), t,
                                              tool.pose.position_m, tool.scale, active_set);
  }

  /// The feedback of tool @p t at @p now_s: its contact wrench and @p added
  /// (a wrench from beside its contacts: ToolContactEngine::answer) through
  /// the device's limits together (FeedbackLimits); state events.
  /// @p ending: its session ends (a pending leave is sent now).
  void make_output(int t, double now_s, ToolOutput& out, const ToolWrench& added = {},
                   bool ending = false) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    // The local model of this tick's solve; the last one's when it failed
    // (its pose is its own, so it stays right about where it was made).
    if (factored)
      local_model(t, out.local);
    else
      out.local = tool.out.local;
    const bool pushed =
        tool.alive && (added.force_n.squaredNorm() > 0 || added.torque_nm.squaredNorm() > 0);
    const detail::ContactSolution::RawWrench& raw = solution.wrench(t);
    const Vector3d raw_force = pushed ? Vector3d(raw.force_n + added.force_n) : raw.force_n;
    const Vector3d raw_torque = pushed ? Vector3d(raw.torque_nm + added.torque_nm) : raw.torque_nm;
    if (pushed && factored) {  // F₀, τ₀ as felt: before the limits, with the added wrench
      out.local.force_n += added.force_n;
      out.local.torque_nm += added.torque_nm;
    }
    // The device's force and slew limits (nothing felt once ramped out).
    const ToolGeometry& g = tool.geometry;
    const detail::FeedbackLimits::Sent sent =
        detail::FeedbackLimits(g.force_limit_n, g.max_force_rate_n_per_s)
            .limit(raw_force, raw_torque, raw.grip_n,
                   {tool.has_output, tool.out.force_n, now_s - tool.last_output_s}, tool.alive);
    out.force_n = sent.force_n;
    out.torque_nm = sent.torque_nm;
    out.grip_n = sent.grip_n;
    out.contacts = tool.alive ? raw.contacts : 0;
    out.held = tool.alive ? static_cast<int>(grasps.held(t).size()) : 0;
    out.force_limited = sent.limited;
    out.watchdog = tool.in_watchdog;
    out.sequence = tool.pose.sequence;
    out.send_time_ns = tool.pose.send_time_ns;
    const ToolState state = grasps.holding(t) && tool.alive ? ToolState::kGrasping
                            : out.contacts > 0              ? ToolState::kTouching
                                                            : ToolState::kFree;
    if (const auto event = tool.episodes.step(state, now_s, ending)) push_event(out, *event);
    out.state = state;
    tool.out = out;
    tool.has_output = true;
    tool.last_output_s = now_s;
  }
};

ToolContactEngine::ToolContactEngine(const SurfaceModel& model, std::vector<ToolGeometry> tools,
                                     const ContactSettings& settings, const SolverLimits& limits,
                                     const RotationField* warping)
    : impl_(std::make_unique<Impl>(model, std::move(tools), settings, limits, warping)) {}
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
  const Eigen::Vector3d& box_min = s.surface.box_min();
  const Eigen::Vector3d& box_max = s.surface.box_max();
  if ((pose.position_m.array() < (box_min - margin).array()).any() ||
      (pose.position_m.array() > (box_max + margin).array()).any()) {
    s.explain(
        "tool '{}' at ({:.4g}, {:.4g}, {:.4g}) m is more than {:.4g} m outside the "
        "organ's box ({:.4g}, {:.4g}, {:.4g})-({:.4g}, {:.4g}, {:.4g}) m",
        id, pose.position_m.x(), pose.position_m.y(), pose.position_m.z(), margin_m, box_min.x(),
        box_min.y(), box_min.z(), box_max.x(), box_max.y(), box_max.z());
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
  const RequestStatus status = solve(t, pose, now_s);
  answer(t, now_s);
  return status;
}

RequestStatus ToolContactEngine::solve(int t, const ToolPoseInput& pose, double now_s) {
  Impl& s = *impl_;
  s.surface.next_tick();
  auto& tool = s.tools.at(static_cast<std::size_t>(t));
  ToolOutput& out = tool.pending;
  out = ToolOutput{};
  tool.answered = false;
  if (tool.in_watchdog || !tool.alive) {
    if (tool.in_watchdog || tool.has_sequence) Impl::push_event(out, ToolEventKind::kResumed);
    s.constraints.forget_drag(t);  // no drag from before
    tool.in_watchdog = false;
    tool.scale = 1;
  }
  tool.alive = true;
  s.grasps.new_pose(t, tool.pose.jaw_angle_rad, tool.has_sequence);
  tool.pose = pose;
  tool.has_sequence = true;
  tool.rotation = pose.orientation.toRotationMatrix();
  tool.last_pose_s = now_s;

  s.update_grasp(t, out);
  return s.find_contacts_and_solve();
}

const ToolOutput& ToolContactEngine::answer(int t, double now_s, const ToolWrench& added) {
  Impl& s = *impl_;
  auto& tool = s.tools.at(static_cast<std::size_t>(t));
  PALPATE_DEMAND(!tool.answered);  // one answer per solve()
  tool.answered = true;
  s.make_output(t, now_s, tool.pending, added);
  return tool.out;
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
  for (int t = 0; t < static_cast<int>(s.tools.size()); ++t) {
    auto& tool = s.tools[static_cast<std::size_t>(t)];
    if (tool.alive && tool.scale == 0) {
      s.grasps.let_go(t);
      tool.alive = false;
    }
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
  const bool had_contacts =
      tool.alive && (s.solution.wrench(t).contacts > 0 || s.grasps.holding(t));
  s.grasps.forget(t);  // lets go; its jaws' history too
  tool.alive = false;
  tool.in_watchdog = false;
  tool.scale = 1;
  tool.has_sequence = false;  // its next pose starts a new session, not a resumed one
  s.constraints.forget_drag(t);
  tool.tip_count = 0;
  // The others feel the tissue it let go of.
  if (had_contacts) s.find_contacts_and_solve();
  ToolOutput out;
  s.make_output(t, now_s, out, {}, /*ending=*/true);  // a touching tool leaves first,
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
bool ToolContactEngine::in_session(int tool) const {
  const auto& t = impl_->tools.at(static_cast<std::size_t>(tool));
  return t.alive && !t.in_watchdog;
}
void ToolContactEngine::reserve_background_loads(int count) {
  Impl& m = *impl_;
  if (m.warping != nullptr)
    throw InputError("a warped contact engine takes no background loads (they are linear)");
  m.background_columns.reserve(m.model, count);
  m.background.reserve(m.model, count, m.background_columns);
  m.surface_background.reserve(m.model, count, m.background_columns);
  m.surface.set_background(&m.surface_background);
}

void ToolContactEngine::set_background_loads(std::span<const int> indices,
                                             std::span<const double> forces_n, double energy_j) {
  impl_->background.set(indices, forces_n, energy_j);
}

void ToolContactEngine::set_background_loads(std::span<const int> indices,
                                             std::span<const double> forces_n,
                                             std::span<const double> displacements_m) {
  impl_->background.set(indices, forces_n, displacements_m);
}

void ToolContactEngine::set_triangle_hidden(int triangle, bool hidden) {
  impl_->surface.set_hidden(triangle, hidden);
}
std::span<const ContactPoint> ToolContactEngine::contact_points() const {
  return impl_->solution.points();
}
std::span<const int> ToolContactEngine::contact_indices() const {
  return impl_->solution.load_indices();
}
std::span<const double> ToolContactEngine::contact_forces() const {
  return impl_->solution.load_forces();
}
std::span<const int> ToolContactEngine::contact_tools() const {
  return impl_->solution.load_tools();
}
std::uint64_t ToolContactEngine::solves() const { return impl_->active_set.solves(); }
ToolContactEngine::SolveTimes ToolContactEngine::solve_times() const {
  const detail::ActiveSet& a = impl_->active_set;
  return {a.solves() - a.later_solves(), a.later_solves(), a.first_seconds(), a.later_seconds()};
}

}  // namespace palpate
