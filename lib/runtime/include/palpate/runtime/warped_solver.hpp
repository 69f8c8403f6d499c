#pragma once
/// @file
/// Requests on a warped model (docs/model/warped.md, "Large rotations: warped
/// compliance"): the same constraints as ConstraintSolver, answered with the
/// compliance rotated into each surface point's local frame.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/rotation_field.hpp"

namespace palpate {

/// How a warped request iterates.
struct WarpingLimits {
  int max_iterations = 100;     ///< solves per request, the first one linear
  double tolerance_rad = 1e-9;  ///< largest change of ω between the last two solves
  /// ω ← ω + relaxation (ω_new − ω) after each solve: 1 is plain fixed point;
  /// ½ settles grasps that plain iteration sends into oscillation.
  double relaxation = 0.5;
};

/// The warped model: the linear model holds in a material frame, and each
/// surface point's material displacement û is carried to the world by its
/// neighbourhood's rotation, x − p = R̃(ω) û, with ω = S Ω û
/// (RotationField) and R̃ the integrated rotation (integrated_rotation). A
/// force f on a point is f̂ = R̃ᵀ f in the material frame (the same work).
/// So each constraint is rotated into its point's frame before the linear
/// solve, and its answer rotated back:
///
///   force f            → f̂ = R̃ᵀ f
///   displacement d     → d̂ = R̃⁻¹ d;                 force f = R̃⁻ᵀ f̂
///   normal (n, δ)      → n̂ = R̃ᵀ n / s, δ̂ = δ / s,   s = |R̃ᵀ n|; f = R̃⁻ᵀ f̂ ∥ n
///
/// (R̃ of a point on a triangle: from the weighted mean of its vertices'
/// ω.) The rotations depend on the answer: the request is solved by fixed
/// point, ω from the last solve's field (relaxed), until ω changes by less
/// than `tolerance_rad`. The first solve has ω = 0 and is the linear answer, with
/// the linear solver's checks and messages. Small loads: R̃ = I + O(|ω|), so
/// the warped answer tends to the linear one.
class WarpedSolver {
 public:
  /// @p model and @p field must outlive the solver.
  WarpedSolver(const SurfaceModel& model, const SolverLimits& limits, const RotationField& field,
               const WarpingLimits& warping = {});

  RequestStatus begin(std::size_t count);
  /// As ConstraintSolver::add; values in the world frame.
  RequestStatus add(std::uint32_t vertex_id, std::int32_t kind, const double* value,
                    const double* normal);
  /// As ConstraintSolver::add_point; values in the world frame.
  RequestStatus add_point(std::span<const std::uint32_t> vertex_ids,
                          std::span<const double> weights, std::int32_t kind, const double* value,
                          const double* normal);
  /// Solves by fixed point. When ω has not settled after max_iterations
  /// the request is refused as kIllConditioned, with the change left.
  RequestStatus solve();
  /// Explanation of the last status other than kOk (the linear solver's own
  /// for a refused constraint or first solve).
  const char* message() const { return message_[0] != '\0' ? message_.data() : linear_.message(); }

  int size() const { return count_; }
  /// World force at each constraint's point, 3k, N.
  std::span<const double> forces() const { return {force_.data(), 3 * std::size_t(count_)}; }
  /// World displacement x − p of each constraint's point, 3k, m.
  std::span<const double> displacements() const {
    return {displacement_.data(), 3 * std::size_t(count_)};
  }
  Eigen::Vector3d total_force() const;
  /// The last solve's loads on compliance vertices in the material frame
  /// (f̂_S = Hᵀ f̂_C: G f̂_S is the material field û; as
  /// ConstraintSolver::load_indices, load_forces).
  std::span<const int> load_indices() const { return last_->load_indices(); }
  std::span<const double> load_forces() const { return last_->load_forces(); }
  double condition_estimate() const {
    return last_ != nullptr ? last_->condition_estimate() : linear_.condition_estimate();
  }
  /// World displacement of every compliance vertex, R̃_v û_v, 3N_S, m.
  void surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const;
  /// ω from the last solve's field, 3 per compliance vertex, rad: valid at
  /// the vertices of the constraints' points (the only ones the fixed point
  /// reads), zero elsewhere.
  std::span<const double> rotations() const {
    return {fresh_.data(), static_cast<std::size_t>(fresh_.size())};
  }
  int iterations() const { return iterations_; }      ///< solves of the last request
  double rotation_change() const { return change_; }  ///< last max |Δω|, rad

 private:
  RequestStatus add_rotated(int j, const Eigen::Matrix3d& Rt);
  Eigen::Vector3d point_omega(const Eigen::VectorXd& omega, int j) const;
  void gather_support();
  void material_field_on_support(const ConstraintSolver& solver);

  const SurfaceModel& model_;
  const RotationField& field_;
  WarpingLimits warping_;
  ConstraintSolver linear_;  // the first solve: the request's own checks
  ConstraintSolver warped_;  // the next ones: rotated values, no bounds
  int count_ = 0;
  int added_ = 0;
  std::vector<int> point_count_, point_index_;  // 3 per constraint, −1 fixed
  std::vector<double> point_weight_;            // 3 per constraint
  std::vector<ConstraintKind> kind_;
  std::vector<double> value_, normal_;  // world, 3 per constraint
  std::vector<double> rotation_;        // R̃ per constraint, 9, column-major
  std::vector<double> force_, displacement_;
  // The points' compliance vertices and the vertices their ω reads; û on
  // those only (3N_S storage), ω relaxed and fresh at the points.
  std::vector<int> points_, support_;
  std::vector<char> point_mark_, support_mark_;
  Eigen::VectorXd u_hat_, omega_, fresh_;
  const ConstraintSolver* last_ = nullptr;         // the solver of the last solve
  mutable Eigen::VectorXd field_u_, field_omega_;  // surface_displacement()
  int iterations_ = 0;
  double change_ = 0;
  bool solved_ = false;
  std::array<char, 256> message_{};
};

}  // namespace palpate
