#pragma once
/// @file
/// What a tool's device is sent of its contact wrench (internal to the
/// runtime; the contact engine's step 5, docs/tools.md "One tick"): the
/// force clamped to the device's force limit, then moved from the force
/// sent last towards it by at most the slew limit times the interval; the
/// torque and the grip scaled by what the force kept of itself.

#include <Eigen/Core>

namespace palpate::detail {

/// The device's limits on one tool's feedback, applied to one output:
///
///     F* = F · min(1, F_max / |F|)                      (force limit)
///     F  = F⁻ + (F* − F⁻) · min(1, ṙ Δt / |F* − F⁻|)   (slew limit)
///     τ  = τ_raw s,  g = g_raw s,   s = min(1, |F| / |F_raw|)  (0 when F_raw = 0)
///
/// with F⁻ the force sent at the last output and Δt the time since,
/// clamped to [0, 10 ms] (1 ms, from F⁻ = 0, before a first output). Pure:
/// it keeps no state between outputs (the caller keeps F⁻ and its time) and
/// allocates nothing.
class FeedbackLimits {
 public:
  /// The longest interval the slew limit grants, s (a tool silent for
  /// longer moves no faster than after 10 ms).
  static constexpr double kMaxInterval_s = 0.01;
  /// The interval taken before a first output, s.
  static constexpr double kFirstInterval_s = 0.001;

  /// What the tool was sent at its last output, and how long ago.
  struct Last {
    bool sent = false;  ///< false: no output yet (F⁻ = 0, Δt = 1 ms)
    Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  ///< F⁻, on the tool, N
    double since_s = 0;  ///< the time since, s (any sign: clamped to [0, 10 ms])
  };

  /// What the device is sent.
  struct Sent {
    Eigen::Vector3d force_n = Eigen::Vector3d::Zero();    ///< F, N
    Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();  ///< τ, N·m (about the hinge)
    double grip_n = 0;                                    ///< g, N
    bool limited = false;                                 ///< the force or the slew limit changed F
  };

  /// @p force_limit_n: the device's largest force, N; @p max_force_rate_n_per_s:
  /// how fast the force sent may change, N/s (ToolGeometry's; both > 0, as
  /// the daemon's configuration checks).
  FeedbackLimits(double force_limit_n, double max_force_rate_n_per_s)
      : force_limit_n_(force_limit_n), max_force_rate_n_per_s_(max_force_rate_n_per_s) {}

  /// The feedback of the raw wrench @p raw_force_n (N, on the tool),
  /// @p raw_torque_nm (N·m about the hinge) and grip @p raw_grip_n (N)
  /// after @p last. @p felt false (a tool the watchdog ramped out): nothing
  /// is sent, F = 0 and not limited (τ and g scale with it to zero).
  Sent limit(const Eigen::Vector3d& raw_force_n, const Eigen::Vector3d& raw_torque_nm,
             double raw_grip_n, const Last& last, bool felt = true) const;

 private:
  double force_limit_n_;
  double max_force_rate_n_per_s_;
};

}  // namespace palpate::detail
