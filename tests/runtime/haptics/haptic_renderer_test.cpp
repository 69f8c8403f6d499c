// Rendering palpated's answers at the device's rate (HapticRenderer,
// docs/pliers.md "Rendering at the device's rate"): the local model
// evaluated at the device's pose, contacts that only push, the age ramp,
// the device's limits, late answers, and the passivity observer and
// controller on a passive wall and on an active (curl) field.

#include "palpate/runtime/haptic_renderer.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

namespace palpate {
namespace {

using Eigen::Quaterniond;
using Eigen::Vector3d;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

// Everything here is a few products of doubles: 1e-12 of the newtons.
constexpr double kTolerance = 1e-12;
constexpr double kDeviceTick = 0.00025;  // s, a 4 kHz device

/// A press: F₀ along +z at x₀, a coupled 6 × 6 stiffness (not symmetric:
/// a tilted contact with friction).
RenderAnswer press(std::uint64_t sequence = 1) {
  RenderAnswer a;
  a.sequence = sequence;
  a.model.valid = true;
  a.model.position_m = Vector3d(0.01, 0.02, 0.03);
  a.model.orientation = Quaterniond(Eigen::AngleAxisd(0.3, Vector3d(1, 2, 3).normalized()));
  a.model.force_n = Vector3d(0.1, -0.05, 1.2);
  a.model.torque_nm = Vector3d(0.002, 0.001, -0.0005);
  Matrix6d K = Matrix6d::Zero();
  K.topLeftCorner<3, 3>() << -80, 5, 10, 3, -90, -4, 12, -6, -400;
  K.topRightCorner<3, 3>() << 0.1, 0.2, -0.3, 0.05, 0.1, 0.2, -0.4, 0.3, 0.1;
  K.bottomLeftCorner<3, 3>() << 0.2, -0.1, 0.3, 0.1, 0.2, 0.05, -0.3, 0.1, 0.2;
  K.bottomRightCorner<3, 3>() << -0.01, 0.002, 0, 0.001, -0.012, 0.003, 0, 0.002, -0.005;
  a.model.stiffness = K;
  a.fed_back_force_n = Vector3d(0.1, -0.05, 1.1);  // palpated's slew limit was acting
  a.force_limit_n = 100;
  a.max_force_rate_n_per_s = 1e9;
  return a;
}

RenderSettings without_passivity() {
  RenderSettings s;
  s.passivity = false;
  return s;
}

TEST(HapticRenderer, NothingBeforeAnAnswer) {
  HapticRenderer r;
  const RenderedWrench w = r.render(0, Vector3d::Zero(), Quaterniond::Identity());
  EXPECT_EQ(w.force_n.norm(), 0.0);
  EXPECT_EQ(w.answer_age_s, -1);
}

TEST(HapticRenderer, TheLocalModelAtTheDevicesPose) {
  HapticRenderer r(without_passivity());
  const RenderAnswer a = press();
  r.take(a, 0);
  // At the answered pose: the answer's contact wrench (not the fed-back one).
  RenderedWrench w = r.render(0, a.model.position_m, a.model.orientation);
  w = r.render(kDeviceTick, a.model.position_m, a.model.orientation);
  EXPECT_LE((w.force_n - a.model.force_n).norm(), kTolerance);
  EXPECT_LE((w.torque_nm - a.model.torque_nm).norm(), kTolerance);
  // Moved 0.2 mm and turned 0.01 rad about x: w₀ + K (δx, θ).
  const Vector3d dx(0.0002, -0.0001, -0.0002), theta(0.01, 0, 0);
  const Quaterniond turned =
      Quaterniond(Eigen::AngleAxisd(0.01, Vector3d::UnitX())) * a.model.orientation;
  w = r.render(2 * kDeviceTick, a.model.position_m + dx, turned);
  Eigen::Matrix<double, 6, 1> q;
  q << dx, theta;
  const Eigen::Matrix<double, 6, 1> expected =
      (Eigen::Matrix<double, 6, 1>() << a.model.force_n, a.model.torque_nm).finished() +
      a.model.stiffness * q;
  EXPECT_LE((w.force_n - expected.head<3>()).norm(), kTolerance);
  EXPECT_LE((w.torque_nm - expected.tail<3>()).norm(), kTolerance);
  EXPECT_FALSE(w.limited);
}

TEST(HapticRenderer, ATouchingToolIsNeverPulledInAHoldingOneMayBe) {
  RenderAnswer a = press();
  HapticRenderer touching(without_passivity());
  touching.take(a, 0);
  // 5 mm out along the force: the linear model would pull (1.2 − 400·0.005 < 0).
  const Vector3d out = a.model.position_m + Vector3d(0, 0, 0.005);
  touching.render(0, out, a.model.orientation);
  const RenderedWrench w = touching.render(kDeviceTick, out, a.model.orientation);
  Vector3d linear, unused;
  a.model.holding = true;
  HapticRenderer::evaluate(a.model, out, a.model.orientation, linear, unused);
  ASSERT_LT(linear.dot(a.model.force_n), 0) << "the linear model pulls there";
  EXPECT_NEAR(w.force_n.dot(a.model.force_n.normalized()), 0, kTolerance);
  // Only the pulling component is taken away.
  const Vector3d along = a.model.force_n.normalized();
  EXPECT_LE((w.force_n - (linear - linear.dot(along) * along)).norm(), kTolerance);
  HapticRenderer holding(without_passivity());
  holding.take(a, 0);
  holding.render(0, out, a.model.orientation);
  EXPECT_LE((holding.render(kDeviceTick, out, a.model.orientation).force_n - linear).norm(),
            kTolerance);
}

TEST(HapticRenderer, WithoutALocalModelTheFedBackForceIsHeld) {
  RenderSettings s = without_passivity();
  s.local_model = false;
  HapticRenderer r(s);
  const RenderAnswer a = press();
  r.take(a, 0);
  r.render(0, Vector3d::Zero(), Quaterniond::Identity());
  const RenderedWrench w = r.render(kDeviceTick, Vector3d(0.05, 0, 0), Quaterniond::Identity());
  EXPECT_LE((w.force_n - a.fed_back_force_n).norm(), kTolerance);
  RenderAnswer old = a;
  old.model.valid = false;  // an older palpated's answer
  HapticRenderer r2(without_passivity());
  r2.take(old, 0);
  r2.render(0, Vector3d::Zero(), Quaterniond::Identity());
  EXPECT_LE((r2.render(kDeviceTick, Vector3d(0.05, 0, 0), Quaterniond::Identity()).force_n -
             a.fed_back_force_n)
                .norm(),
            kTolerance);
}

TEST(HapticRenderer, AnAnswerIsHeldThenRampedOut) {
  RenderSettings s = without_passivity();
  HapticRenderer r(s);
  const RenderAnswer a = press();
  r.take(a, 1.0);
  const auto at = [&](double t) { return r.render(t, a.model.position_m, a.model.orientation); };
  at(1.0);
  EXPECT_NEAR(at(1.0 + s.hold_s).scale, 1.0, kTolerance);
  const RenderedWrench half = at(1.0 + s.hold_s + 0.5 * s.ramp_s);
  EXPECT_NEAR(half.scale, 0.5, kTolerance);
  EXPECT_LE((half.force_n - 0.5 * a.model.force_n).norm(), kTolerance);
  EXPECT_EQ(at(1.0 + s.hold_s + s.ramp_s).force_n.norm(), 0.0);
  EXPECT_EQ(at(5.0).force_n.norm(), 0.0);
}

TEST(HapticRenderer, ALateAnswerIsTakenAnOlderOneIsNot) {
  HapticRenderer r(without_passivity());
  EXPECT_TRUE(r.take(press(10), 0));
  EXPECT_FALSE(r.take(press(9), 0.001)) << "answers an older pose";
  RenderAnswer late = press(12);
  late.model.force_n = Vector3d(0, 0, 2);
  EXPECT_TRUE(r.take(late, 0.004)) << "newer, however late it came";
  EXPECT_EQ(r.answer().sequence, 12u);
}

TEST(HapticRenderer, TheDevicesForceAndSlewLimits) {
  RenderAnswer a = press();
  a.force_limit_n = 0.5;
  a.max_force_rate_n_per_s = 400;  // 0.1 N per 4 kHz tick
  HapticRenderer r(without_passivity());
  r.take(a, 0);
  RenderedWrench w = r.render(0, a.model.position_m, a.model.orientation);
  EXPECT_EQ(w.force_n.norm(), 0.0) << "the first call sets the clock";
  for (int i = 1; i <= 4; ++i) {
    w = r.render(i * kDeviceTick, a.model.position_m, a.model.orientation);
    EXPECT_NEAR(w.force_n.norm(), 0.1 * i, 1e-12);
    EXPECT_TRUE(w.limited);
  }
  w = r.render(10 * kDeviceTick, a.model.position_m, a.model.orientation);
  EXPECT_NEAR(w.force_n.norm(), 0.5, 1e-12);
  EXPECT_LE((w.force_n - 0.5 * a.model.force_n.normalized()).norm(), 1e-12);
  // The torque is scaled with the clamped force.
  EXPECT_LE((w.torque_nm - a.model.torque_nm * (0.5 / a.model.force_n.norm())).norm(), 1e-12);
}

/// A wall at z = 0 along +z, stiffness k, answered at z₀ = −1 mm; the
/// device moves along z by @p path(t) for 2 s at 4 kHz after a free answer.
struct Wall {
  double k = 500;
  RenderAnswer free() const {
    RenderAnswer a;
    a.sequence = 1;
    a.model.valid = true;
    a.force_limit_n = 100;
    a.max_force_rate_n_per_s = 1e9;
    return a;
  }
  RenderAnswer wall() const {
    RenderAnswer a = free();
    a.sequence = 2;
    a.model.position_m = Vector3d(0, 0, -0.001);
    a.model.force_n = Vector3d(0, 0, k * 0.001);
    a.model.stiffness(2, 2) = -k;
    return a;
  }
};

TEST(HapticRenderer, APassiveWallNeedsNoDamping) {
  // Pressed in and out through the wall's surface at 3 Hz: the rendered
  // force is a function of where the hand is (a potential's gradient), so
  // the environment gives back only what it took, but for the device's
  // zero-order hold: a force held over each tick while the hand moves
  // into the wall lags it, which gives back ½ k Σ Δx² more than it took
  // (J. E. Colgate and G. G. Schenkel, "Passivity of a class of
  // sampled-data systems: application to haptic interfaces", Journal of
  // Robotic Systems 14(1), 1997): at 500 N/m and 4 kHz, about the stored
  // energy of the last 0.15 mm. The controller takes back that much and no
  // more: kept above zero, as the hand leaves the wall; kept above the
  // energy the wall stores (the reference), as the leak arises, and a tick
  // late (it compares the next tick's energy with the reference of this
  // one): 5 % more.
  const Wall wall;
  for (const bool reference : {false, true}) {
    RenderSettings s;
    s.reference_energy = reference;
    HapticRenderer r(s);
    double least = 0, damped = 0, deepest = 0, hold_leak = 0;
    RenderAnswer answer = wall.free();
    Vector3d previous = Vector3d(0, 0, 0.001);
    for (int i = 0; i <= 8000; ++i) {
      const double t = i * kDeviceTick;
      // palpated answers at 1 kHz: the same model, again and again.
      if (i == 100) answer = wall.wall();
      if (i % 4 == 0) {
        ++answer.sequence;
        r.take(answer, t);
      }
      const double z = 0.001 - 0.0025 * std::sin(2 * std::numbers::pi * 3 * std::max(0.0, t - 0.1));
      const RenderedWrench w = r.render(t, Vector3d(0, 0, z), Quaterniond::Identity());
      if (std::min(z, previous.z()) < 0)
        hold_leak += 0.5 * wall.k * (z - previous.z()) * (z - previous.z());
      least = std::min(least, w.energy_j);
      damped += w.damping * (z - previous.z()) * (z - previous.z()) / kDeviceTick;  // α v² Δt
      previous.z() = z;
      deepest = std::max(deepest, w.force_n.z());
    }
    SCOPED_TRACE(reference ? "above the reference" : "above zero");
    EXPECT_GT(hold_leak, 0);
    EXPECT_GE(least, -hold_leak);
    if (!reference) {
      EXPECT_NEAR(deepest, wall.k * 0.0015, 0.01) << "pressed 1.5 mm in";
      EXPECT_LE(damped, hold_leak * (1 + 1e-9));
    } else {
      EXPECT_GT(damped, 0.5 * hold_leak);
      EXPECT_LE(damped, hold_leak * 1.05);
    }
  }
}

TEST(HapticRenderer, TheEnergyIsTheWorkOfEachWrenchOverTheTickItWasHeld) {
  // The device holds each rendered wrench until the next call: the energy
  // the environment took is −Σ F_k·(x_{k+1} − x_k). A held answer whose
  // force steps up as the hand presses in (palpated's answers coming
  // 1 ms apart) must not be credited with the step: the hand moved
  // against the smaller force. Checked against that sum, computed here
  // from what was rendered.
  RenderSettings s = without_passivity();
  s.local_model = false;
  HapticRenderer r(s);
  double expected = 0;
  Vector3d force = Vector3d::Zero(), previous = Vector3d::Zero();
  RenderAnswer a = Wall{}.free();
  for (int i = 0; i <= 400; ++i) {
    const double t = i * kDeviceTick;
    const Vector3d x(0.0002 * std::sin(7.0 * t), 0, -0.02 * t);  // pressing in at 20 mm/s
    if (i % 4 == 0) {  // an answer every 1 ms: the force at the pose it answers
      ++a.sequence;
      a.fed_back_force_n = Vector3d(0.1 * x.x(), 0, -1000 * x.z());
      r.take(a, t);
    }
    const RenderedWrench w = r.render(t, x, Quaterniond::Identity());
    if (i > 0) expected -= force.dot(x - previous);
    EXPECT_NEAR(w.energy_j, expected, 1e-12 * std::abs(expected) + 1e-15) << i;
    force = w.force_n;
    previous = x;
  }
  EXPECT_GT(expected, 0.0019) << "2 mm pressed into 1000 N/m: ½ k x² = 2 mJ";
}

TEST(HapticRenderer, AnEnergyDebtOutlivesTheContactUntilTheHandPaysIt) {
  // The controller could not act (no damping allowed): the held force of a
  // contact the hand leaves pushes it out and gives energy. Free again, that
  // debt is kept (what a touch stored is dropped, what it gave is not), and
  // the controller takes it back from the next motion.
  RenderSettings s;
  s.local_model = false;
  s.max_damping_n_s_per_m = 0;
  HapticRenderer r(s);
  RenderAnswer a = Wall{}.free();
  a.fed_back_force_n = Vector3d(0, 0, 2);
  r.take(a, 0);
  double t = 0;
  for (int i = 0; i < 20; ++i, t += kDeviceTick)  // 2 N held while the hand leaves at 40 mm/s
    r.render(t, Vector3d(0, 0, 0.00001 * i), Quaterniond::Identity());
  const double debt = r.render(t, Vector3d(0, 0, 0.0002), Quaterniond::Identity()).energy_j;
  // The first call renders nothing (its slew limit has no time yet): 2 N
  // over the last 0.19 mm.
  EXPECT_NEAR(debt, -2 * 0.00019, 1e-12);
  RenderAnswer free = Wall{}.free();
  free.sequence = 2;
  r.take(free, t);
  t += kDeviceTick;
  EXPECT_NEAR(r.render(t, Vector3d(0, 0, 0.0002), Quaterniond::Identity()).energy_j, debt, 1e-15)
      << "free, the debt stays";
  // Now allowed to damp: the next motion pays it back, and no more.
  RenderSettings damping = s;
  damping.max_damping_n_s_per_m = 50;
  HapticRenderer paying(damping);
  paying.take(a, 0);
  t = 0;
  for (int i = 0; i < 20; ++i, t += kDeviceTick) {
    // The same exit, but the controller damps it: E never falls below what
    // one tick's misprediction of the motion costs (none, here: the hand
    // moves steadily).
    const RenderedWrench w = paying.render(t, Vector3d(0, 0, 0.00001 * i), Quaterniond::Identity());
    EXPECT_GE(w.energy_j, -1e-12) << i;
  }
}

TEST(HapticRenderer, TheControllersDampingIsNotSlewedIntoASpring) {
  // A held 2 N pushes a hand that trembles (0.5 mm at 20 Hz, up to
  // 63 mm/s) as it leaves at 40 mm/s: the controller damps, α ≤ 50 N·s/m,
  // so the rendered force stays within α |v| of the held 2 N (v: the
  // controller's estimate, the last tick's mean).
  // Slewing from the damped force of the last call would add each call's
  // damping to the last (−α Σ v: a spring of α/Δt) up to the force limit.
  RenderSettings s;
  s.local_model = false;
  HapticRenderer r(s);
  RenderAnswer a = Wall{}.free();
  a.fed_back_force_n = Vector3d(0, 0, 2);
  a.max_force_rate_n_per_s = 500;  // palpated's default: 0.125 N per 4 kHz tick
  a.force_limit_n = 100;
  double largest = 0, most_damping = 0;
  for (int i = 0; i < 400; ++i) {
    const double t = i * kDeviceTick;
    if (i % 4 == 0) {  // palpated answers at 1 kHz, the same force
      ++a.sequence;
      r.take(a, t);
    }
    const auto z = [](double time) {
      return 0.04 * time + 0.0005 * std::sin(2 * std::numbers::pi * 20 * time);
    };
    const RenderedWrench w = r.render(t, Vector3d(0, 0, z(t)), Quaterniond::Identity());
    const double speed =
        std::abs(z(t) - z(t - kDeviceTick)) / kDeviceTick;  // the controller's estimate
    if (t > 0.005)
      largest = std::max(largest, (w.force_n - a.fed_back_force_n).norm() - 50 * speed);
    most_damping = std::max(most_damping, w.damping);
  }
  EXPECT_GT(most_damping, 0) << "the held force gives energy: the controller acts";
  EXPECT_LE(largest, 1e-9);
}

TEST(HapticRenderer, AnActiveFieldIsMadePassiveAndWithoutTheObserverItGivesEnergy) {
  // A curl field F = c (−y, x, 0) (a local model whose stiffness is not
  // symmetric) does work on a hand that circles: 2π c r² per turn. Without
  // the observer the environment gives energy turn after turn; with it, E
  // never goes below zero and the controller damps.
  const double c = 200, radius = 0.001;
  RenderAnswer a;
  a.sequence = 1;
  a.model.valid = true;
  a.model.holding = true;  // may pull
  a.model.stiffness(0, 1) = -c;
  a.model.stiffness(1, 0) = c;
  a.force_limit_n = 100;
  a.max_force_rate_n_per_s = 1e9;
  double energy[2] = {0, 0}, least[2] = {0, 0}, damped[2] = {0, 0};
  for (const bool passivity : {false, true}) {
    RenderSettings s;
    s.passivity = passivity;
    HapticRenderer r(s);
    a.sequence = 0;
    for (int i = 0; i <= 8000; ++i) {  // 2 s, 4 turns
      const double t = i * kDeviceTick, phase = 2 * std::numbers::pi * 2 * t;
      if (i % 4 == 0) {  // palpated answers at 1 kHz
        ++a.sequence;
        r.take(a, t);
      }
      const RenderedWrench w =
          r.render(t, Vector3d(radius * std::cos(phase), radius * std::sin(phase), 0),
                   Quaterniond::Identity());
      energy[passivity] = w.energy_j;
      least[passivity] = std::min(least[passivity], w.energy_j);
      damped[passivity] = std::max(damped[passivity], w.damping);
    }
  }
  const double per_turn = 2 * std::numbers::pi * c * radius * radius;
  EXPECT_LT(energy[false], -3.5 * per_turn) << "four turns, each giving 2π c r²";
  EXPECT_EQ(damped[false], 0.0);
  // The controller keeps the energy it predicts for the next tick ≥ 0; the
  // hand's motion turns within the tick by a = r ω² (0.16 m/s²), which
  // mispredicts at most |F| a Δt² = 0.2 N · 0.16 m/s² · (0.25 ms)² = 2·10⁻⁹ J.
  EXPECT_GE(least[true], -2e-9);
  EXPECT_GT(damped[true], 0.0);
  EXPECT_LE(damped[true], RenderSettings{}.max_damping_n_s_per_m);
}

}  // namespace
}  // namespace palpate
