#include "palpate/runtime/haptic_renderer.hpp"

#include <algorithm>
#include <cmath>

namespace palpate {

using Eigen::Quaterniond;
using Eigen::Vector3d;

namespace {

/// The rotation vector θ of @p R R₀ᵀ (|θ| ≤ π), for two unit quaternions.
Vector3d rotation_vector(const Quaterniond& to, const Quaterniond& from) {
  Quaterniond d = to * from.conjugate();
  if (d.w() < 0) d.coeffs() = -d.coeffs();  // the short way round
  const Eigen::AngleAxisd aa(d.normalized());
  return aa.angle() * aa.axis();
}

}  // namespace

RenderAnswer render_answer(const ToolOutput& output, const ToolGeometry& tool) {
  RenderAnswer a;
  a.sequence = output.sequence;
  a.model = output.local;
  a.fed_back_force_n = output.force_n;
  a.fed_back_torque_nm = output.torque_nm;
  a.force_limit_n = tool.force_limit_n;
  a.max_force_rate_n_per_s = tool.max_force_rate_n_per_s;
  return a;
}

HapticRenderer::HapticRenderer(const RenderSettings& settings) : settings_(settings) {}

bool HapticRenderer::take(const RenderAnswer& answer, double received_s) {
  if (has_answer_ && answer.sequence < answer_.sequence) return false;
  answer_ = answer;
  has_answer_ = true;
  received_s_ = received_s;
  return true;
}

void HapticRenderer::reset() {
  has_answer_ = false;
  has_previous_ = false;
  previous_force_.setZero();
  previous_limited_.setZero();
  previous_torque_.setZero();
  energy_j_ = 0;
}

void HapticRenderer::evaluate(const LocalContactModel& model, const Vector3d& position_m,
                              const Quaterniond& orientation, Vector3d& force_n,
                              Vector3d& torque_nm) {
  Eigen::Matrix<double, 6, 1> q;
  q << position_m - model.position_m, rotation_vector(orientation, model.orientation);
  const Eigen::Matrix<double, 6, 1> w = model.stiffness * q;
  force_n = model.force_n + w.head<3>();
  torque_nm = model.torque_nm + w.tail<3>();
  // Contacts that only push never pull the tool in.
  if (!model.holding) {
    const double f0 = model.force_n.norm();
    if (f0 > 0) {
      const Vector3d along = model.force_n / f0;
      const double against = force_n.dot(along);
      if (against < 0) force_n -= against * along;
    } else {
      force_n.setZero();
      torque_nm.setZero();
    }
  }
}

double HapticRenderer::reference_energy(const Vector3d& force) const {
  // E_ref = ½ F_n² / k_n: what a spring of the answer's normal stiffness
  // stores at the force rendered (Ryu, Preusche, Hannaford and Hirzinger
  // 2005). A contact that stiffens as it deepens (a tip's area grows) stores
  // more, U = ∫ F dx ≥ ½ F²/k: E_ref never asks more than a passive organ
  // gives. At most ½ F_n × 10 mm, for a normal stiffness near zero; none
  // without one (no model, or none along the force).
  if (!settings_.reference_energy || !has_answer_ || !answer_.model.valid) return 0;
  const LocalContactModel& model = answer_.model;
  const double f0 = model.force_n.norm();
  if (!(f0 > 0)) return 0;
  const Vector3d n = model.force_n / f0;
  const double k_n = -n.dot(model.stiffness.topLeftCorner<3, 3>() * n);
  const double f_n = std::max(0.0, force.dot(n));
  constexpr double kDeepest = 0.01;  // m
  return k_n > 0 ? 0.5 * f_n * std::min(f_n / k_n, kDeepest) : 0.0;
}

RenderedWrench HapticRenderer::render(double now_s, const Vector3d& position_m,
                                      const Quaterniond& orientation) {
  RenderedWrench out;
  const double dt = has_previous_ ? std::clamp(now_s - previous_s_, 0.0, 0.01) : 0.0;
  Vector3d force = Vector3d::Zero(), torque = Vector3d::Zero();
  bool free = true;
  if (has_answer_) {
    const double age = std::max(0.0, now_s - received_s_);
    out.answer_age_s = age;
    out.scale = age <= settings_.hold_s ? 1.0
                : settings_.ramp_s > 0
                    ? std::clamp(1 - (age - settings_.hold_s) / settings_.ramp_s, 0.0, 1.0)
                    : 0.0;
    const LocalContactModel& model = answer_.model;
    if (settings_.local_model && model.valid) {
      evaluate(model, position_m, orientation, force, torque);
      free = model.force_n.squaredNorm() == 0 && model.stiffness.squaredNorm() == 0;
    } else {
      force = answer_.fed_back_force_n;
      torque = answer_.fed_back_torque_nm;
      free = force.squaredNorm() == 0;
    }
    force *= out.scale;
    torque *= out.scale;
    // The device's limits, as palpated applies them.
    if (const double magnitude = force.norm(); magnitude > answer_.force_limit_n) {
      const double shrink = answer_.force_limit_n / magnitude;
      force *= shrink;
      torque *= shrink;
      out.limited = true;
    }
    const double step = answer_.max_force_rate_n_per_s * dt;
    if (const double change = (force - previous_limited_).norm(); change > step) {
      force = previous_limited_ + (force - previous_limited_) * (step / change);
      out.limited = true;
    }
  }
  // The slew limit paces the model's force, not the controller's damping:
  // damping slewed from one call to the next would add up, −α Σ v, into a
  // spring of α/Δt (200 kN/m at 50 N·s/m and 4 kHz) that throws the hand.
  previous_limited_ = force;
  // Passivity (Hannaford and Ryu 2002), on the energy that flowed: the
  // wrench of the previous call was held until now (the device's
  // zero-order hold), so over the last interval the environment took
  //   ΔE = −(F_{k−1}·(x_k − x_{k−1}) + τ_{k−1}·θ_k)
  // from the hand. (Pairing the new wrench with the past motion instead
  // credits a force that grows as the hand presses in with work it never
  // did: a held answer's step, the controller's own damping.)
  Vector3d dx = Vector3d::Zero(), dtheta = Vector3d::Zero();
  if (has_previous_) {
    dx = position_m - previous_position_;
    dtheta = rotation_vector(orientation, previous_orientation_);
    energy_j_ -= previous_force_.dot(dx) + previous_torque_.dot(dtheta);
  }
  // Free: what the touch stored is gone with it; a debt is still owed.
  if (free && force.squaredNorm() == 0) energy_j_ = std::min(energy_j_, 0.0);
  out.energy_j = energy_j_;
  // The controller: the wrench chosen now is held until the next call. With
  // the next interval's motion predicted as the last one's (v = Δx/Δt), the
  // least damping −α v (then −β ω) that keeps the predicted E ≥ E_ref.
  if (settings_.passivity && dt > 0) {
    const Vector3d v = dx / dt, w = dtheta / dt;
    double predicted = energy_j_ - (force.dot(dx) + torque.dot(dtheta)) - reference_energy(force);
    if (predicted < 0) {
      const double speed2 = v.squaredNorm();
      if (speed2 > settings_.min_speed_m_per_s * settings_.min_speed_m_per_s) {
        const double alpha = std::min(settings_.max_damping_n_s_per_m, -predicted / (speed2 * dt));
        force -= alpha * v;
        predicted += alpha * speed2 * dt;
        out.damping = alpha;
      }
      const double spin2 = w.squaredNorm();
      if (predicted < 0 &&
          spin2 > settings_.min_angular_speed_rad_per_s * settings_.min_angular_speed_rad_per_s) {
        const double beta =
            std::min(settings_.max_angular_damping_nm_s_per_rad, -predicted / (spin2 * dt));
        torque -= beta * w;
      }
      // The device renders no more than its limit, damping included.
      if (const double magnitude = force.norm(); magnitude > answer_.force_limit_n) {
        force *= answer_.force_limit_n / magnitude;
        out.limited = true;
      }
    }
  }
  out.force_n = force;
  out.torque_nm = torque;
  out.energy_j = energy_j_;
  has_previous_ = true;
  previous_s_ = now_s;
  previous_position_ = position_m;
  previous_orientation_ = orientation;
  previous_force_ = force;
  previous_torque_ = torque;
  return out;
}

}  // namespace palpate
