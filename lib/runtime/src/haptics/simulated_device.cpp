#include "palpate/runtime/simulated_device.hpp"

#include <fmt/format.h>

#include "palpate/core/error.hpp"

namespace palpate {

using Eigen::Vector3d;

namespace {

void require(bool ok, const char* what, double value, const char* accepted) {
  if (!ok) throw InputError(fmt::format("simulated device: {} = {} ({})", what, value, accepted));
}

}  // namespace

SimulatedDevice::SimulatedDevice(const SimulatedDeviceSettings& settings,
                                 const Vector3d& position_m)
    : settings_(settings),
      position_(position_m),
      velocity_(Vector3d::Zero()),
      set_point_(position_m) {
  const DeviceDynamics& d = settings.device;
  const HandImpedance& h = settings.hand;
  require(d.mass_kg > 0, "device mass (kg)", d.mass_kg, "accepted: > 0");
  require(d.damping_n_s_per_m >= 0, "device damping (N·s/m)", d.damping_n_s_per_m, "accepted: ≥ 0");
  require(h.mass_kg >= 0, "hand mass (kg)", h.mass_kg, "accepted: ≥ 0");
  require(h.stiffness_n_per_m >= 0, "hand stiffness (N/m)", h.stiffness_n_per_m, "accepted: ≥ 0");
  require(h.damping_n_s_per_m >= 0, "hand damping (N·s/m)", h.damping_n_s_per_m, "accepted: ≥ 0");
  require(settings.tick_s > 0, "tick (s)", settings.tick_s, "accepted: > 0");
  require(settings.substeps >= 1, "sub-steps", settings.substeps, "accepted: ≥ 1");
}

void SimulatedDevice::place(const Vector3d& position_m, const Vector3d& velocity_m_per_s,
                            const Vector3d& set_point_m) {
  position_ = position_m;
  velocity_ = velocity_m_per_s;
  set_point_ = set_point_m;
}

double SimulatedDevice::stored_energy_j() const {
  const double mass = settings_.device.mass_kg + settings_.hand.mass_kg;
  return 0.5 * mass * velocity_.squaredNorm() +
         0.5 * settings_.hand.stiffness_n_per_m * (position_ - set_point_).squaredNorm();
}

void SimulatedDevice::step(const Vector3d& force_n, const Vector3d& set_point_m) {
  const double mass = settings_.device.mass_kg + settings_.hand.mass_kg;
  const double k = settings_.hand.stiffness_n_per_m, b_hand = settings_.hand.damping_n_s_per_m,
               b_device = settings_.device.damping_n_s_per_m;
  const double tick = settings_.tick_s, h = tick / settings_.substeps;
  // The set point moves linearly across the tick: s(τ) = s₀ + ṡ τ.
  const Vector3d s0 = set_point_, s_dot = (set_point_m - set_point_) / tick;
  // (m_d + m_h) ẍ = F − b_d ẋ + k_h (s − x) + b_h (ṡ − ẋ), F held.
  const auto acceleration = [&](double tau, const Vector3d& x, const Vector3d& v) -> Vector3d {
    return (force_n - b_device * v + k * (s0 + s_dot * tau - x) + b_hand * (s_dot - v)) / mass;
  };
  const Vector3d start = position_;
  Vector3d x = position_, v = velocity_;
  for (int i = 0; i < settings_.substeps; ++i) {
    const double tau = i * h;
    const Vector3d k1x = v, k1v = acceleration(tau, x, v);
    const Vector3d k2x = v + 0.5 * h * k1v,
                   k2v = acceleration(tau + 0.5 * h, x + 0.5 * h * k1x, v + 0.5 * h * k1v);
    const Vector3d k3x = v + 0.5 * h * k2v,
                   k3v = acceleration(tau + 0.5 * h, x + 0.5 * h * k2x, v + 0.5 * h * k2v);
    const Vector3d k4x = v + h * k3v, k4v = acceleration(tau + h, x + h * k3x, v + h * k3v);
    x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
  }
  position_ = x;
  velocity_ = v;
  set_point_ = set_point_m;
  // A force held over the tick does exactly F · Δx of work.
  work_j_ += force_n.dot(position_ - start);
  time_s_ += tick;
}

}  // namespace palpate
