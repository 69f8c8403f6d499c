#include "palpate/runtime/contact/feedback_limits.hpp"

#include <algorithm>

namespace palpate::detail {

using Eigen::Vector3d;

FeedbackLimits::Sent FeedbackLimits::limit(const Vector3d& raw_force_n,
                                           const Vector3d& raw_torque_nm, double raw_grip_n,
                                           const Last& last, bool felt) const {
  Vector3d target = raw_force_n;
  bool limited = false;
  if (const double magnitude = target.norm(); magnitude > force_limit_n_) {
    target *= force_limit_n_ / magnitude;
    limited = true;
  }
  const Vector3d previous = last.sent ? last.force_n : Vector3d::Zero();
  const double dt = last.sent ? std::clamp(last.since_s, 0.0, kMaxInterval_s) : kFirstInterval_s;
  const double step = max_force_rate_n_per_s_ * dt;
  Vector3d force = target;
  if (const double change = (target - previous).norm(); change > step) {
    force = previous + (target - previous) * (step / change);
    limited = true;
  }
  if (!felt) {  // ramped out: nothing left to feel
    force.setZero();
    limited = false;
  }
  const double raw = raw_force_n.norm();
  const double torque_scale = raw > 0 ? std::min(1.0, force.norm() / raw) : 0.0;
  Sent sent;
  sent.force_n = force;
  sent.torque_nm = raw_torque_nm * torque_scale;
  sent.grip_n = raw_grip_n * torque_scale;
  sent.limited = limited;
  return sent;
}

}  // namespace palpate::detail
