#pragma once
/// @file
/// A haptic device's handle held by a human hand, simulated: what the
/// rendering of palpated's answers is tested and measured against
/// (docs/model/rendering.md, "Rendering between answers: the local model and
/// passivity"; tests/runtime/haptics/passivity_test.cpp).
///
/// The handle is a mass m_d with viscous damping b_d (the device's own
/// friction, to ground). The hand grasps it rigidly and is an impedance: a
/// mass m_h moving with the handle, pulled towards a set point s(t) (where
/// the hand means to be; a scripted trajectory) by a spring k_h and a
/// damper b_h. The rendered force F acts on the handle:
///
///     (m_d + m_h) ẍ = F − b_d ẋ + k_h (s − x) + b_h (ṡ − ẋ)        (SI)
///
/// the lumped second-order grasp model of N. Hogan, "Controlling impedance
/// at the man/machine interface" (IEEE ICRA 1989), as identified for hands
/// holding a stylus or handle by, among others, K. J. Kuchenbecker, J. G.
/// Park and G. Niemeyer, "Characterizing the human wrist for improved
/// haptic interaction" (ASME IMECE 2003) and M. J. Fu and M. C. Çavuşoğlu,
/// "Human-arm-and-hand-dynamic model with variability analyses for a
/// stylus-based haptic interface" (IEEE Trans. Systems, Man and
/// Cybernetics B 42(6), 2012). Those models span about m_h 0.1–1 kg,
/// k_h 100–1000 N/m and b_h 2–10 N·s/m with the grip force. The defaults
/// below are one relaxed grasp in that range, at its light and little
/// damped end (m_h = 0.2 kg, k_h = 300 N/m, b_h = 3 N·s/m), where a
/// delayed rendering goes unstable first: the hand's damping is what
/// dissipates the energy an active rendering gives. The device's defaults
/// (m_d = 0.1 kg, b_d = 0.2 N·s/m) are a desktop device's handle; none of
/// them is fitted to one subject or one device.
///
/// Translation only: the hand holds the handle's orientation (the caller's;
/// a torque is not simulated). Frames: the model frame, as the poses and
/// forces the renderer takes and gives.
///
/// The force is held over each device tick, as a real device's DAC holds
/// its output (zero-order hold), and the hand's set point moves linearly
/// across the tick. Between two ticks the equation is integrated by
/// classical Runge–Kutta (4th order) in sub-steps: its only stiffness is
/// the hand's (ω = √(k_h / (m_d + m_h)) ≈ 32 rad/s at the defaults, ω h ≈
/// 2·10⁻³ per sub-step at 4 kHz), so the integration error is far below
/// round-off's scale of any measure taken (checked against the closed
/// form, tests/runtime/haptics/simulated_device_test.cpp). A contact's stiffness is
/// not integrated here: it enters through the rendered force, sampled at
/// the device's rate, which is the point.
///
/// Allocation-free.

#include <Eigen/Core>

namespace palpate {

/// The device's handle (SI).
struct DeviceDynamics {
  double mass_kg = 0.1;
  double damping_n_s_per_m = 0.2;  ///< to ground
};

/// The hand holding the handle, an impedance towards its set point (SI).
struct HandImpedance {
  double mass_kg = 0.2;
  double stiffness_n_per_m = 300;
  double damping_n_s_per_m = 3;
};

struct SimulatedDeviceSettings {
  DeviceDynamics device;
  HandImpedance hand;
  double tick_s = 0.00025;  ///< the device's servo period (4 kHz)
  int substeps = 4;         ///< Runge–Kutta steps per tick
};

class SimulatedDevice {
 public:
  /// The handle at rest at @p position_m (model frame, m), the hand's set
  /// point there. @throws InputError for a mass that is not positive, a
  /// negative stiffness or damping, a tick that is not positive, or fewer
  /// than one sub-step.
  explicit SimulatedDevice(const SimulatedDeviceSettings& settings = {},
                           const Eigen::Vector3d& position_m = Eigen::Vector3d::Zero());

  /// Puts the handle at @p position_m moving at @p velocity_m_per_s, the
  /// hand's set point at @p set_point_m (the work is kept).
  void place(const Eigen::Vector3d& position_m, const Eigen::Vector3d& velocity_m_per_s,
             const Eigen::Vector3d& set_point_m);

  /// One device tick: @p force_n (on the handle, N) held for the tick while
  /// the set point moves linearly from where it was to @p set_point_m.
  void step(const Eigen::Vector3d& force_n, const Eigen::Vector3d& set_point_m);

  const Eigen::Vector3d& position_m() const { return position_; }
  const Eigen::Vector3d& velocity_m_per_s() const { return velocity_; }
  const Eigen::Vector3d& set_point_m() const { return set_point_; }
  double time_s() const { return time_s_; }
  double tick_s() const { return settings_.tick_s; }
  const SimulatedDeviceSettings& settings() const { return settings_; }

  /// The work the rendered forces did on the handle since construction,
  /// ∫ F·ẋ dt, J: exact for a force held over each tick (F · Δx). Its
  /// opposite is the energy the rendered environment took from the hand:
  /// a passive rendering keeps it ≤ the energy it was given to store.
  double work_j() const { return work_j_; }
  /// The energy the handle and the hand store: ½ (m_d + m_h) |ẋ|² +
  /// ½ k_h |x − s|², J.
  double stored_energy_j() const;

 private:
  SimulatedDeviceSettings settings_;
  Eigen::Vector3d position_, velocity_, set_point_;
  double time_s_ = 0;
  double work_j_ = 0;
};

}  // namespace palpate
