// The simulated haptic device (SimulatedDevice): a handle held by a hand
// modelled as a mass-spring-damper towards its set point, the force held
// over each tick. Against closed forms: the free decay of the
// mass-spring-damper, a constant force's steady state, the lag behind a set
// point moving at constant speed; the work of the rendered force against
// the energy stored when nothing dissipates.

#include "palpate/runtime/simulated_device.hpp"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>

#include "palpate/core/error.hpp"
#include "support/expect_error.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;

// Runge–Kutta's error on an oscillator is (ω h)⁵/120 of phase per step: at
// ω h ≈ 2·10⁻³ (ω = 32 rad/s, four 62.5 µs steps per 4 kHz tick) 3·10⁻¹⁶
// rad, 5·10⁻¹² over the 16,000 steps of 1 s; round-off adds about as much.
// On 10 mm that is under 10⁻¹³ m: 10⁻¹¹ m (10⁻⁹ of the motion) is the bound.
constexpr double kPositionTolerance = 1e-11;  // m

double mass(const SimulatedDeviceSettings& s) { return s.device.mass_kg + s.hand.mass_kg; }
double damping(const SimulatedDeviceSettings& s) {
  return s.device.damping_n_s_per_m + s.hand.damping_n_s_per_m;
}

TEST(SimulatedDevice, FreeDecayIsTheClosedFormOfTheMassSpringDamper) {
  // Released 10 mm (−5 and 2 mm on the other axes) from the hand's set
  // point with 0.1 m/s along x, no force: each axis is the underdamped
  //   x(t) = e^{−ζωt} (x₀ cos ω_d t + (v₀ + ζω x₀)/ω_d sin ω_d t).
  const SimulatedDeviceSettings s;
  const double k = s.hand.stiffness_n_per_m;
  const double omega = std::sqrt(k / mass(s)), zeta = damping(s) / (2 * std::sqrt(k * mass(s))),
               omega_d = omega * std::sqrt(1 - zeta * zeta);
  ASSERT_LT(zeta, 0.5) << "the defaults are well underdamped: the test sees oscillations";
  const Vector3d set_point(0.02, 0.03, 0.04), x0(0.01, -0.005, 0.002), v0(0.1, 0, 0);
  SimulatedDevice device(s);
  device.place(set_point + x0, v0, set_point);
  double worst = 0;
  const int ticks = static_cast<int>(std::lround(1.0 / s.tick_s));  // 1 s, 5 periods
  for (int i = 1; i <= ticks; ++i) {
    device.step(Vector3d::Zero(), set_point);
    const double t = i * s.tick_s, decay = std::exp(-zeta * omega * t);
    const Vector3d expected = decay * (x0 * std::cos(omega_d * t) +
                                       (v0 + zeta * omega * x0) / omega_d * std::sin(omega_d * t));
    worst = std::max(worst, (device.position_m() - set_point - expected).norm());
  }
  EXPECT_LE(worst, kPositionTolerance);
  EXPECT_NEAR(device.time_s(), 1.0, 1e-12);
  EXPECT_EQ(device.work_j(), 0.0) << "no force, no work";
}

TEST(SimulatedDevice, AConstantForceSettlesWhereTheHandsSpringBalancesIt) {
  // 3 N down: x → s + F/k_h, 10 mm below the set point. After 3 s the
  // transient has decayed by e^{−ζω·3 s} = e^{−16} (ζω = 5.3 s⁻¹): 10⁻⁹ m left.
  const SimulatedDeviceSettings s;
  SimulatedDevice device(s);
  const Vector3d force(0, 0, -3);
  for (int i = 0; i < static_cast<int>(std::lround(3.0 / s.tick_s)); ++i)
    device.step(force, Vector3d::Zero());
  const Vector3d expected = force / s.hand.stiffness_n_per_m;
  EXPECT_LE((device.position_m() - expected).norm(), 1e-8);
  EXPECT_LE(device.velocity_m_per_s().norm(), 1e-6);
  // A constant force's work is F·Δx whatever the path (the ticks' F·Δx
  // telescope; 12,000 terms of round-off): 3 N over 10 mm.
  EXPECT_NEAR(device.work_j(), force.dot(device.position_m()), 1e-13);
  EXPECT_NEAR(device.work_j(), 0.03, 1e-7);
}

TEST(SimulatedDevice, WithoutDampingTheForcesWorkIsTheEnergyStored) {
  // Nothing dissipates: the work of a force held tick by tick (here one
  // that changes every tick) is the kinetic energy plus the hand spring's.
  SimulatedDeviceSettings s;
  s.device.damping_n_s_per_m = 0;
  s.hand.damping_n_s_per_m = 0;
  SimulatedDevice device(s);
  double largest = 0;
  for (int i = 0; i < 4000; ++i) {  // 1 s
    const Vector3d force(std::sin(0.01 * i), 0.5 * std::cos(0.003 * i), -1);
    device.step(force, Vector3d::Zero());
    largest = std::max(largest, device.stored_energy_j());
    // Each step's error is Runge–Kutta's, of order (ω h)⁵ of the energy.
    EXPECT_NEAR(device.work_j(), device.stored_energy_j(), 1e-12 * largest + 1e-15) << i;
  }
  EXPECT_GT(largest, 1e-3) << "the force did work worth checking";
}

TEST(SimulatedDevice, TheHandDragsTheHandleBehindASetPointMovingSteadily) {
  // The set point moves at V = 20 mm/s along y: in steady state the handle
  // moves at V too and the hand's spring pulls against the device's own
  // damping, k_h (s − x) = b_d V (the hand's damper, on ṡ − ẋ, is idle).
  const SimulatedDeviceSettings s;
  SimulatedDevice device(s);
  const Vector3d speed(0, 0.02, 0);
  Vector3d set_point = Vector3d::Zero();
  for (int i = 0; i < static_cast<int>(std::lround(3.0 / s.tick_s)); ++i) {
    set_point += speed * s.tick_s;
    device.step(Vector3d::Zero(), set_point);
  }
  const Vector3d lag = speed * s.device.damping_n_s_per_m / s.hand.stiffness_n_per_m;
  EXPECT_LE((set_point - device.position_m() - lag).norm(), 1e-9);  // the transient's e^{−16}
  EXPECT_LE((device.velocity_m_per_s() - speed).norm(), 1e-7);
}

TEST(SimulatedDevice, SettingsAreChecked) {
  using testing::expect_error;
  SimulatedDeviceSettings s;
  s.device.mass_kg = 0;
  expect_error<InputError>([&] { SimulatedDevice d(s); }, {"device mass (kg) = 0", "> 0"});
  s = {};
  s.hand.damping_n_s_per_m = -1;
  expect_error<InputError>([&] { SimulatedDevice d(s); }, {"hand damping", "≥ 0"});
  s = {};
  s.tick_s = 0;
  expect_error<InputError>([&] { SimulatedDevice d(s); }, {"tick (s) = 0"});
  s = {};
  s.substeps = 0;
  expect_error<InputError>([&] { SimulatedDevice d(s); }, {"sub-steps = 0"});
}

}  // namespace
}  // namespace palpate
