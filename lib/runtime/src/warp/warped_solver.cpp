#include "palpate/runtime/warped_solver.hpp"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"
#include "palpate/runtime/solve/request_failure.hpp"

namespace palpate {

namespace {

SolverLimits unbounded(SolverLimits limits) {
  // The rotated values of a request the linear solver accepted: R̃⁻¹
  // lengthens a displacement by up to 1/sinc(|ω|/2), which is no new input.
  limits.max_displacement_m = std::numeric_limits<double>::infinity();
  limits.max_force_n = std::numeric_limits<double>::infinity();
  return limits;
}

}  // namespace

WarpedSolver::WarpedSolver(const SurfaceModel& model, const SolverLimits& limits,
                           const RotationField& field, const WarpingLimits& warping)
    : model_(model),
      field_(field),
      warping_(warping),
      linear_(model, limits),
      warped_(model, unbounded(limits)) {
  PALPATE_DEMAND(field.vertex_count() == model.compliance_vertex_count());
  const auto k = static_cast<std::size_t>(limits.max_constraints);
  point_count_.assign(k, 0);
  point_index_.assign(3 * k, -1);
  point_weight_.assign(3 * k, 0.0);
  kind_.assign(k, ConstraintKind::kForce);
  value_.assign(3 * k, 0.0);
  normal_.assign(3 * k, 0.0);
  rotation_.assign(9 * k, 0.0);
  force_.assign(3 * k, 0.0);
  displacement_.assign(3 * k, 0.0);
  const auto n3 = static_cast<std::size_t>(model.compliance_rows());
  const auto n = static_cast<Eigen::Index>(n3);
  u_hat_ = omega_ = fresh_ = field_u_ = field_omega_ = Eigen::VectorXd::Zero(n);
  point_mark_.assign(n3 / 3, 0);
  support_mark_.assign(n3 / 3, 0);
}

RequestStatus WarpedSolver::begin(std::size_t count) {
  solved_ = false;
  message_[0] = '\0';
  count_ = added_ = 0;
  const RequestStatus status = linear_.begin(count);
  if (status == RequestStatus::kOk) count_ = static_cast<int>(count);
  return status;
}

RequestStatus WarpedSolver::add(std::uint32_t vertex_id, std::int32_t kind, const double* value,
                                const double* normal) {
  const RequestStatus status = linear_.add(vertex_id, kind, value, normal);
  if (status != RequestStatus::kOk) return status;
  const auto j = static_cast<std::size_t>(added_++);
  point_count_[j] = 1;
  point_index_[3 * j] = model_.compliance_index_of_vertex[vertex_id];
  point_weight_[3 * j] = 1.0;
  kind_[j] = static_cast<ConstraintKind>(kind);
  const int values = kind_[j] == ConstraintKind::kNormalDisplacement ? 1 : 3;
  for (int d = 0; d < 3; ++d) {
    value_[3 * j + std::size_t(d)] = d < values ? value[d] : 0.0;
    normal_[3 * j + std::size_t(d)] = normal != nullptr ? normal[d] : 0.0;
  }
  return status;
}

RequestStatus WarpedSolver::add_point(std::span<const std::uint32_t> vertex_ids,
                                      std::span<const double> weights, std::int32_t kind,
                                      const double* value, const double* normal) {
  const RequestStatus status = linear_.add_point(vertex_ids, weights, kind, value, normal);
  if (status != RequestStatus::kOk) return status;
  const auto j = static_cast<std::size_t>(added_++);
  point_count_[j] = static_cast<int>(vertex_ids.size());
  for (std::size_t i = 0; i < vertex_ids.size(); ++i) {
    const std::int32_t index = model_.compliance_index_of_vertex[vertex_ids[i]];
    point_index_[3 * j + i] = index >= 0 ? index : -1;
    point_weight_[3 * j + i] = weights[i];
  }
  kind_[j] = static_cast<ConstraintKind>(kind);
  const int values = kind_[j] == ConstraintKind::kNormalDisplacement ? 1 : 3;
  for (int d = 0; d < 3; ++d) {
    value_[3 * j + std::size_t(d)] = d < values ? value[d] : 0.0;
    normal_[3 * j + std::size_t(d)] = normal != nullptr ? normal[d] : 0.0;
  }
  return status;
}

Eigen::Vector3d WarpedSolver::point_omega(const Eigen::VectorXd& omega, int j) const {
  const auto jj = static_cast<std::size_t>(j);
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
  for (int i = 0; i < point_count_[jj]; ++i) {
    const int a = point_index_[3 * jj + std::size_t(i)];
    if (a >= 0)  // a fixed vertex does not rotate
      w += point_weight_[3 * jj + std::size_t(i)] * omega.segment<3>(3 * a);
  }
  return w;
}

RequestStatus WarpedSolver::add_rotated(int j, const Eigen::Matrix3d& Rt) {
  const auto jj = static_cast<std::size_t>(j);
  const Eigen::Map<const Eigen::Vector3d> value(&value_[3 * jj]);
  Eigen::Vector3d v = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
  switch (kind_[jj]) {
    case ConstraintKind::kForce:
      v = Rt.transpose() * value;
      break;
    case ConstraintKind::kDisplacement:
      v = Rt.inverse() * value;
      break;
    case ConstraintKind::kNormalDisplacement: {
      const Eigen::Vector3d world =
          Eigen::Map<const Eigen::Vector3d>(&normal_[3 * jj]).normalized();
      n = Rt.transpose() * world;
      const double s = n.norm();
      n /= s;
      v[0] = value[0] / s;
      break;
    }
  }
  return warped_.add_surface_point(&point_index_[3 * jj], &point_weight_[3 * jj], point_count_[jj],
                                   kind_[jj], v.data(), n.data());
}

void WarpedSolver::gather_support() {
  // The distinct compliance vertices of the points, and what their ω reads.
  points_.clear();
  support_.clear();
  std::fill(point_mark_.begin(), point_mark_.end(), 0);
  std::fill(support_mark_.begin(), support_mark_.end(), 0);
  for (int j = 0; j < count_; ++j)
    for (int i = 0; i < point_count_[std::size_t(j)]; ++i) {
      const int a = point_index_[3 * std::size_t(j) + std::size_t(i)];
      if (a >= 0 && !point_mark_[std::size_t(a)]) {
        point_mark_[std::size_t(a)] = 1;
        points_.push_back(a);
        field_.support(a, support_mark_, support_);
      }
    }
}

void WarpedSolver::material_field_on_support(const ConstraintSolver& solver) {
  // û_s = Σ_l G^{s l} f̂_l over the loads: the field where ω reads it only.
  const auto loads = solver.load_indices();
  const auto forces = solver.load_forces();
  for (const int s : support_) {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (std::size_t l = 0; l < loads.size(); ++l)
      u += model_.G_block(s, loads[l]) * Eigen::Map<const Eigen::Vector3d>(&forces[3 * l]);
    u_hat_.segment<3>(3 * s) = u;
  }
}

RequestStatus WarpedSolver::solve() {
  last_ = nullptr;
  solved_ = false;
  iterations_ = 0;
  change_ = 0;
  RequestStatus status = linear_.solve();
  ++iterations_;
  if (status != RequestStatus::kOk) return status;  // message(): the linear solver's words
  last_ = &linear_;
  for (int j = 0; j < count_; ++j) {
    Eigen::Map<Eigen::Matrix3d> Rt(&rotation_[9 * std::size_t(j)]);
    Rt.setIdentity();
  }
  gather_support();
  for (const int a : points_) omega_.segment<3>(3 * a).setZero();
  for (;;) {
    material_field_on_support(*last_);
    change_ = 0;
    const double r = iterations_ == 1 ? 1.0 : warping_.relaxation;  // the first from ω = 0
    for (const int a : points_) {
      fresh_.segment<3>(3 * a) =
          field_.rotation_at(a, {u_hat_.data(), static_cast<std::size_t>(u_hat_.size())});
      const Eigen::Vector3d step = r * (fresh_.segment<3>(3 * a) - omega_.segment<3>(3 * a));
      change_ = std::max(change_, step.cwiseAbs().maxCoeff());
      omega_.segment<3>(3 * a) += step;
    }
    if (change_ <= warping_.tolerance_rad) break;
    if (iterations_ >= warping_.max_iterations) {
      return detail::fail(
          message_, RequestStatus::kIllConditioned,
          "the warped solve did not settle: the rotations still changed by {:.3g} rad after {} "
          "solves; impose smaller displacements or use the linear model",
          change_, iterations_);
    }
    if ((status = warped_.begin(std::size_t(count_))) != RequestStatus::kOk) break;
    for (int j = 0; j < count_ && status == RequestStatus::kOk; ++j) {
      const Eigen::Matrix3d Rt = integrated_rotation(point_omega(omega_, j));
      Eigen::Map<Eigen::Matrix3d> stored(&rotation_[9 * std::size_t(j)]);
      stored = Rt;
      status = add_rotated(j, Rt);
    }
    if (status == RequestStatus::kOk) status = warped_.solve();
    ++iterations_;
    if (status != RequestStatus::kOk)
      return detail::fail(message_, status, "the warped solve, after {} solves: {}", iterations_,
                          warped_.message());
    last_ = &warped_;
  }
  if (status != RequestStatus::kOk) return status;
  // Back to the world: f = R̃⁻ᵀ f̂ (a given force stays as given), x − p = R̃ û
  // with ω from the final field (fresh_), as surface_displacement() carries it.
  const auto f_hat = last_->forces();
  const auto u_point = last_->displacements();
  for (int j = 0; j < count_; ++j) {
    const auto jj = static_cast<std::size_t>(j);
    const Eigen::Map<const Eigen::Matrix3d> Rt(&rotation_[9 * jj]);
    Eigen::Map<Eigen::Vector3d> f(&force_[3 * jj]);
    if (kind_[jj] == ConstraintKind::kForce)
      f = Eigen::Map<const Eigen::Vector3d>(&value_[3 * jj]);
    else
      f = Rt.transpose().inverse() * f_hat.segment<3>(3 * j);
    Eigen::Map<Eigen::Vector3d> x(&displacement_[3 * jj]);
    x = integrated_rotation(point_omega(fresh_, j)) * u_point.segment<3>(3 * j);
  }
  solved_ = true;
  return RequestStatus::kOk;
}

Eigen::Vector3d WarpedSolver::total_force() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int j = 0; j < count_; ++j)
    sum += Eigen::Map<const Eigen::Vector3d>(&force_[3 * std::size_t(j)]);
  return sum;
}

void WarpedSolver::surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const {
  PALPATE_DEMAND(solved_ && u_m.size() == u_hat_.size());
  // The whole material field of the last solve, its rotations, then R̃ û.
  last_->surface_displacement(field_u_);
  field_.rotations({field_u_.data(), static_cast<std::size_t>(field_u_.size())},
                   {field_omega_.data(), static_cast<std::size_t>(field_omega_.size())});
  for (Eigen::Index v = 0; v < u_hat_.size() / 3; ++v)
    u_m.segment<3>(3 * v) =
        integrated_rotation(field_omega_.segment<3>(3 * v)) * field_u_.segment<3>(3 * v);
}

}  // namespace palpate
