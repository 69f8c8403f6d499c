#pragma once
/// @file
/// What a haptic device renders between palpated's answers, at its own rate
/// (docs/pliers.md, "Rendering at the device's rate"; the physics in
/// docs/model/rendering.md, "Rendering between answers: the local model and
/// passivity").
///
/// palpated answers each pose of a tool with the contact wrench at that pose
/// and its local model (LocalContactModel): w(q) ≈ w₀ + K (x − x₀, θ). The
/// device's loop, 1 to 10 kHz, evaluates that model at the device's own
/// pose between two answers, so that a motion is felt at once instead of one
/// round trip later, and the force it renders is a function of where the
/// hand is rather than a force held while the hand moves (which injects
/// energy: the device buzzes on a stiff contact). Then, in order:
///  1. a touching tool's contacts only push: F is kept from pointing against
///     F₀ (its component against F₀ removed); a holding one may pull;
///  2. age: an answer is rendered for hold_s after it came, then scaled
///     linearly to zero over ramp_s, as palpated's watchdog ramps a tool
///     whose poses stop (a daemon that dies or hangs leaves the hand free);
///  3. the device's limits as palpated applies them: |F| ≤ force_limit
///     (the torque scaled with it), then |ΔF| ≤ max_force_rate · Δt per call
///     (on this force: the controller's damping below is not slewed, and
///     |F| ≤ force_limit holds for the sum);
///  4. passivity: a time-domain passivity observer sums the energy the
///     rendered environment has taken from the hand. The device holds each
///     wrench until the next call (its DAC's zero-order hold), so the
///     interval just past cost E −= F_{k−1}·(x_k − x_{k−1}) + τ_{k−1}·θ_k:
///     the wrench rendered then, against the motion made since. The
///     controller predicts the next interval's motion as the last one's;
///     when the wrench chosen now would make E negative over it (the
///     environment would give back more than it was given: a delayed or
///     switching model does), it adds the damping −α v (and −β ω) that
///     dissipates exactly the excess, α ≤ max_damping (Hannaford and Ryu,
///     IEEE Trans. Robotics and Automation 18(1), 2002); "negative" means
///     below what the contact still stores, E_ref = ½ F_n²/k_n with the
///     answer's normal stiffness (RenderSettings::reference_energy). What a touch
///     stored is dropped whenever the tool is free (it never pays for the
///     next touch); a debt (E < 0, the controller held by max_damping or
///     the hand too slow to damp) is kept until motion pays it back.
/// Without a local model (an answer from an older palpated, or
/// local_model = false) it renders the answer's own force, held: what
/// ToolClient::force_to_render() did.
///
/// Not thread-safe: one thread (the device's servo loop) drives it.
/// Allocation-free.

#include <Eigen/Geometry>
#include <cstdint>

#include "palpate/runtime/tool_geometry.hpp"
#include "palpate/runtime/tool_state.hpp"

namespace palpate {

/// How the renderer renders (docs/pliers.md).
struct RenderSettings {
  /// Evaluate the local model at the device's pose; false: hold the
  /// answer's fed-back force (what the device got before the local model).
  bool local_model = true;
  /// An answer is rendered as it is for hold_s after it came, then scaled to
  /// zero over ramp_s, s (palpated's watchdog: 50 and 250 ms).
  double hold_s = 0.05;
  double ramp_s = 0.25;
  /// The passivity observer and controller.
  bool passivity = true;
  /// The controller keeps E above what the contact stores now, as a spring
  /// of the answer's normal stiffness, E_ref = ½ F_n²/k_n, rather than
  /// above zero (reference energy following: J.-H. Ryu, C. Preusche,
  /// B. Hannaford and G. Hirzinger, "Time domain passivity control with
  /// reference energy following", IEEE Trans. Control Systems Technology
  /// 13(5), 2005). Without it, a held answer may spend on an oscillation
  /// about the pressed pose all the energy the press stored before the
  /// controller acts (tests/runtime/haptics/passivity_test.cpp).
  bool reference_energy = true;
  /// Most damping the controller may add: a device's own stable limit.
  double max_damping_n_s_per_m = 50;
  double max_angular_damping_nm_s_per_rad = 0.05;
  /// Speeds under these are taken as standing still (no damping is sized
  /// on them: the velocity of a quantized encoder is noise there), m/s, rad/s.
  double min_speed_m_per_s = 1e-4;
  double min_angular_speed_rad_per_s = 1e-3;
};

/// One answer of palpated for a tool, as the renderer takes it.
struct RenderAnswer {
  std::uint64_t sequence = 0;  ///< of the pose it answers
  /// The local model; not valid: render fed_back_force held.
  LocalContactModel model;
  /// What palpated fed back (after its limits), N and N·m.
  Eigen::Vector3d fed_back_force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d fed_back_torque_nm = Eigen::Vector3d::Zero();
  /// The device's limits palpated applies to the tool ([[tools]]).
  double force_limit_n = 8;
  double max_force_rate_n_per_s = 500;
};

/// What palpated sends of tool output @p output of a tool @p tool: the
/// answer the renderer takes (in process: tests and benchmarks).
RenderAnswer render_answer(const ToolOutput& output, const ToolGeometry& tool);

/// What to render now.
struct RenderedWrench {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();    ///< on the hand, model frame
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();  ///< about the hinge
  bool limited = false;                                 ///< the force or slew limit acted
  double damping = 0;  ///< α the passivity controller added this call, N·s/m
  /// E through this call (the interval just past), J: ≥ 0 while passive,
  /// but for one tick's misprediction of the motion or damping out of reach.
  double energy_j = 0;
  double answer_age_s = -1;  ///< since the answer rendered came; −1: none
  double scale = 0;          ///< the age ramp, 1 → 0
};

class HapticRenderer {
 public:
  explicit HapticRenderer(const RenderSettings& settings = {});

  /// Takes an answer that arrived at @p received_s (seconds, the clock of
  /// render()). An answer to an older pose than the one held is ignored
  /// (false); a late one that is newer is taken.
  bool take(const RenderAnswer& answer, double received_s);
  /// Forgets the answer and the observer's energy (palpated lost, a new
  /// session): zero until the next answer.
  void reset();

  /// The wrench to render at @p now_s for the device at hinge @p position_m,
  /// orientation @p orientation (tool → model). Call once per device tick.
  RenderedWrench render(double now_s, const Eigen::Vector3d& position_m,
                        const Eigen::Quaterniond& orientation);

  bool has_answer() const { return has_answer_; }
  const RenderAnswer& answer() const { return answer_; }
  const RenderSettings& settings() const { return settings_; }

  /// The local model's wrench at a pose, before limits: w₀ + K (x − x₀, θ)
  /// with θ the rotation vector of R R₀ᵀ; a touching tool's force kept from
  /// pointing against F₀.
  static void evaluate(const LocalContactModel& model, const Eigen::Vector3d& position_m,
                       const Eigen::Quaterniond& orientation, Eigen::Vector3d& force_n,
                       Eigen::Vector3d& torque_nm);

 private:
  /// E_ref for @p force rendered now (RenderSettings::reference_energy), J.
  double reference_energy(const Eigen::Vector3d& force) const;

  RenderSettings settings_;
  RenderAnswer answer_;
  bool has_answer_ = false;
  double received_s_ = 0;
  // The previous call: its time, pose and what it rendered.
  bool has_previous_ = false;
  double previous_s_ = 0;
  Eigen::Vector3d previous_position_ = Eigen::Vector3d::Zero();
  Eigen::Quaterniond previous_orientation_ = Eigen::Quaterniond::Identity();
  Eigen::Vector3d previous_force_ = Eigen::Vector3d::Zero();    // rendered, damping included
  Eigen::Vector3d previous_limited_ = Eigen::Vector3d::Zero();  // after the limits, before it
  Eigen::Vector3d previous_torque_ = Eigen::Vector3d::Zero();
  double energy_j_ = 0;
};

}  // namespace palpate
