#pragma once
/// @file
/// Haptic tools on one organ: poses in, contacts on the deformed surface,
/// one solve for every tool together, force feedback out (docs/tools.md).
///
/// The tool frame: origin at the jaws' hinge, +z along the shaft towards the
/// tip, the jaws open in the x-z plane symmetrically about z.
///
/// Per pose of tool t (update):
///  1. Where the organ is: the surface near a tool is deformed by the loads
///     of the previous solve, x_v = rest_v + Σ_l G_vl f_l (fixed vertices
///     stay).
///  2. Grasp: when the jaw angle falls below grasp_angle, the surface
///     under the two jaw faces (and what the tip pressed) is held: points
///     of the deformed triangles, each with rows independent of the others'
///     (JawGrasp, lib/runtime/internal/palpate/runtime/contact/jaw_grasp.hpp). Each keeps its
///     position in the tool frame, squeezed between the faces onto one plane, and follows the tool
///     rigidly. Released when the jaws open past release_angle (hysteresis).
///  3. Tip contacts on triangles: for every deformed surface triangle near
///     the tip (a sphere or a capsule of radius r around the segment
///     hinge → hinge + tip_length·z), the closest points between the tip's
///     axis and the triangle; a triangle closer than r is penetrated, and its
///     closest point p = Σ w_i x_i (barycentric weights on its vertices) is
///     put back on the tip's surface along the normal from the axis to p:
///     fully while friction holds it ("stick"), along the normal only once
///     it slides (tangential motion free: the tool glides). A point on an
///     edge or a vertex is one point, found once; points within 0.05 r of a
///     deeper one (0.3 r with friction: a sticking point fixes three
///     components) are left out, their rows would be nearly the same. A
///     system still singular makes every sticking point slide.
///  4. One ConstraintSolver solve for all tools, each contact a row over its
///     triangle's vertices (ConstraintSolver::add_surface_point). A tip
///     contact whose solved force pulls the tissue towards the tool
///     (adhesion) is released; one whose tangential force exceeds
///     friction × normal force slides; the set is solved again (at most
///     max_iterations solves), editing the factorization of the previous
///     solve rather than refactoring (ContactSettings::incremental_active_set).
///  5. Feedback: the force on the tool is minus the sum of its contact
///     forces, clamped to the device's force limit and moved towards that
///     value at most max_force_rate·Δt per tick; torque about the hinge;
///     grip force from the held points (the squeeze of each face).
/// A tool whose poses stop (watchdog_timeout) has its imposed displacements
/// scaled from 1 to 0 over watchdog_ramp, then is dropped.
///
/// Not thread-safe: the caller serializes update() and watchdog(). Allocates
/// nothing after construction.

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/core/units.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/contact_point.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_geometry.hpp"
#include "palpate/runtime/tool_state.hpp"

namespace palpate {

class RotationField;  // palpate/runtime/rotation_field.hpp: a warped engine's rotations

/// A wrench on a tool from beside its contacts with the engine's surface (a
/// served cut region's push on its tip): N, and N·m about the hinge, in the
/// model frame, on the tool.
struct ToolWrench {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();
};

class ToolContactEngine {
 public:
  /// @p model must outlive the engine. Sizes every buffer for the tools.
  /// @p warping, when given (and outliving the engine), makes the engine
  /// warped (docs/model/warped.md, "Large rotations: warped compliance"): the
  /// surface is deformed to p + R̃(ω) û and every contact row is rotated into
  /// its point's frame, with ω from the previous tick's loads (as the
  /// deformation itself); null: the linear model.
  ToolContactEngine(const SurfaceModel& model, std::vector<ToolGeometry> tools,
                    const ContactSettings& settings, const SolverLimits& limits,
                    const RotationField* warping = nullptr);
  ~ToolContactEngine();
  ToolContactEngine(const ToolContactEngine&) = delete;
  ToolContactEngine& operator=(const ToolContactEngine&) = delete;

  int tool_count() const;
  /// Index of the tool named @p id, or -1.
  int tool_index(std::string_view id) const;
  const ToolGeometry& tool(int index) const;

  /// Checks a pose of tool @p tool before update(); normalizes its quaternion.
  PoseProblem check(int tool, ToolPoseInput& pose) const;
  /// Why check() refused the last pose it refused, one line: what, and what
  /// is accepted ("jaw angle 90° is over tool 'right''s limit of 75°").
  const char* problem_message() const;
  /// Takes a checked pose of @p tool received at @p now_s (seconds, any
  /// monotonic origin), solves every tool's contacts together and returns
  /// what tool @p tool feels. The RequestStatus is kOk unless the solve
  /// failed; then the previous contacts are kept and the output repeats the
  /// last one (solver_message() says why).
  RequestStatus update(int tool, const ToolPoseInput& pose, double now_s);
  /// update() in its two halves, for a caller that adds to what the tool
  /// feels a wrench it computes from this solve (ToolTick: a cut region's
  /// push on the tip, from the region stepped under these contacts). solve()
  /// takes the pose and solves every tool's contacts (contact_indices() and
  /// contact_forces() are this solve's); answer() then makes tool @p tool's
  /// output from its contact wrench plus @p added, through the device's
  /// force and slew limits together (and adds @p added to the local model's
  /// F₀, τ₀). update(t, p, now) is solve(t, p, now) then answer(t, now).
  /// Call answer() exactly once after each solve().
  RequestStatus solve(int tool, const ToolPoseInput& pose, double now_s);
  const ToolOutput& answer(int tool, double now_s, const ToolWrench& added = {});
  /// Ramps out tools whose poses stopped. @returns the tools whose output
  /// changed (their feedback should be sent), as a bit mask.
  std::uint64_t watchdog(double now_s);
  /// Ends tool @p tool's session at its client's word: it lets go of
  /// everything at once (no watchdog ramp), every other tool is solved
  /// again, and its output (no force) carries ToolEventKind::kEnded. Its
  /// next pose starts afresh (no kResumed). @returns false if the tool had
  /// no session (then nothing changed).
  bool end(int tool, double now_s);

  const ToolOutput& output(int tool) const;
  /// The last pose taken of @p tool.
  const ToolPoseInput& pose(int tool) const;
  /// True while tool @p tool's poses come: taken, and the watchdog not
  /// ramping it out.
  bool in_session(int tool) const;
  const char* solver_message() const;
  /// Hides drawn triangle @p triangle from the tools (or shows it again): a
  /// hidden triangle is inside the organ, covered by a served cut region
  /// (HybridRegion::covers_rest_triangle); contacts already on it stay
  /// until they leave. None is hidden at first.
  void set_triangle_hidden(int triangle, bool hidden);
  /// Room for @p count background loads (allocates: once, before the
  /// ticks). @throws InputError for a warped engine.
  void reserve_background_loads(int count);
  /// Known loads on compliance vertices that are not the tools' (3 forces
  /// each, N, on the organ; e.g. a served cut region's push f_Γ on the
  /// rest), with their energy f_bᵀ G f_b (J). From the next solve on every
  /// contact row's imposed displacement discounts H G f_b: the tools feel
  /// the organ as these loads have it. The surface the tools' contacts are
  /// found on is the one the last solve left, u = G (Hᵀ f_C + f_b) with the
  /// f_b of that solve: it takes these from the solve after the next.
  /// Replaces the previous ones; none at first. Allocates nothing.
  /// @throws InputError for more than reserved, a vertex out of range, or
  ///         a force count other than 3 per load.
  void set_background_loads(std::span<const int> indices, std::span<const double> forces_n,
                            double energy_j);
  /// The same with u_b = G_bb f_b at the loaded vertices (3 each, m): the
  /// energy is f_b · u_b, and from one call to the next on the same
  /// vertices, √((f_b − f_b⁻) · (u_b − u_b⁻)) bounds how far the change
  /// moves any vertex (per √‖G^{vv}‖), so a vertex far from the tools whose
  /// u_b was computed once needs no new one while it stays far. Without
  /// u_b, a looser bound from the forces alone is taken.
  void set_background_loads(std::span<const int> indices, std::span<const double> forces_n,
                            std::span<const double> displacements_m);

  /// The contact points of the last solve, all tools.
  std::span<const ContactPoint> contact_points() const;
  /// The same contacts as loads on compliance vertices (f_S = Hᵀ f_C, what
  /// the surface field u_S = G f_S needs), tool by tool: the vertex, the
  /// force on the organ there (3 per load, N), the tool of each. A vertex
  /// two tools load appears once for each. A warped engine's loads are the
  /// material forces f̂ (G f̂ is the material field û; the world's is R̃ û).
  std::span<const int> contact_indices() const;
  std::span<const double> contact_forces() const;
  std::span<const int> contact_tools() const;
  /// Solves since construction, and those that reused a cached factorization.
  std::uint64_t solves() const;
  /// Wall time in the contact solves since construction, for benchmarks:
  /// the first solve of each update, and the solves after a change of the
  /// contact set within an update (rows leaving, sliding or joining).
  struct SolveTimes {
    std::uint64_t first = 0, changed = 0;  ///< how many
    double first_s = 0, changed_s = 0;     ///< their total, s
  };
  SolveTimes solve_times() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate
