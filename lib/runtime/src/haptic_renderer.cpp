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
    if (const double change = (force - previous_force_).norm(); change > step) {
      force = previous_force_ + (force - previous_force_) * (step / change);
      out.limited = true;
    }
  }
  // Passivity: E = −Σ (F·v + τ·ω) Δt must stay ≥ 0.
  if (free && force.squaredNorm() == 0) energy_j_ = 0;
  if (dt > 0) {
    const Vector3d v = (position_m - previous_position_) / dt;
    const Vector3d w = rotation_vector(orientation, previous_orientation_) / dt;
    double energy = energy_j_ - (force.dot(v) + torque.dot(w)) * dt;
    if (settings_.passivity && energy < 0) {
      const double speed2 = v.squaredNorm();
      if (speed2 > settings_.min_speed_m_per_s * settings_.min_speed_m_per_s) {
        const double alpha = std::min(settings_.max_damping_n_s_per_m, -energy / (speed2 * dt));
        force -= alpha * v;
        energy += alpha * speed2 * dt;
        out.damping = alpha;
      }
      const double spin2 = w.squaredNorm();
      if (energy < 0 &&
          spin2 > settings_.min_angular_speed_rad_per_s * settings_.min_angular_speed_rad_per_s) {
        const double beta =
            std::min(settings_.max_angular_damping_nm_s_per_rad, -energy / (spin2 * dt));
        torque -= beta * w;
        energy += beta * spin2 * dt;
      }
    }
    energy_j_ = energy;
  }
  out.force_n = force;
  out.torque_nm = torque;
  out.energy_j = energy_j_;
  has_previous_ = true;
  previous_s_ = now_s;
  previous_position_ = position_m;
  previous_orientation_ = orientation;
  previous_force_ = force;
  return out;
}

}  // namespace palpate
