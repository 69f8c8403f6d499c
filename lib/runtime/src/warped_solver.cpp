#include "palpate/runtime/warped_solver.hpp"

#include <fmt/format.h>

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"

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
  u_hat_ = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(n3));
  omega_.assign(n3, 0.0);
  omega_next_.assign(n3, 0.0);
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

Eigen::Vector3d WarpedSolver::point_omega(int j) const {
  const auto jj = static_cast<std::size_t>(j);
  Eigen::Vector3d w = Eigen::Vector3d::Zero();
  for (int i = 0; i < point_count_[jj]; ++i) {
    const int a = point_index_[3 * jj + std::size_t(i)];
    if (a >= 0)  // a fixed vertex does not rotate
      w += point_weight_[3 * jj + std::size_t(i)] *
           Eigen::Map<const Eigen::Vector3d>(&omega_[3 * std::size_t(a)]);
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
  return warped_.add_surface_point(&point_index_[3 * jj], &point_weight_[3 * jj],
                                   point_count_[jj], kind_[jj], v.data(), n.data());
}

RequestStatus WarpedSolver::solve() {
  solved_ = false;
  iterations_ = 0;
  change_ = 0;
  RequestStatus status = linear_.solve();
  ++iterations_;
  if (status != RequestStatus::kOk) {  // the linear solver's own words
    const auto end =
        fmt::format_to_n(message_.data(), message_.size() - 1, "{}", linear_.message());
    *end.out = '\0';
    return status;
  }
  const ConstraintSolver* last = &linear_;
  for (int j = 0; j < count_; ++j) {
    Eigen::Map<Eigen::Matrix3d> Rt(&rotation_[9 * std::size_t(j)]);
    Rt.setIdentity();
  }
  std::fill(omega_.begin(), omega_.end(), 0.0);
  for (;;) {
    last->surface_displacement(u_hat_);
    field_.rotations({u_hat_.data(), std::size_t(u_hat_.size())}, omega_next_);
    change_ = 0;
    const double r = iterations_ == 1 ? 1.0 : warping_.relaxation;  // the first from ω = 0
    for (std::size_t i = 0; i < omega_.size(); ++i) {
      const double step = r * (omega_next_[i] - omega_[i]);
      change_ = std::max(change_, std::abs(step));
      omega_[i] += step;
    }
    if (change_ <= warping_.tolerance_rad) break;
    if (iterations_ >= warping_.max_iterations) {
      const auto end = fmt::format_to_n(
          message_.data(), message_.size() - 1,
          "the warped solve did not settle: the rotations still changed by {:.3g} rad after {} "
          "solves; impose smaller displacements or use the linear model",
          change_, iterations_);
      *end.out = '\0';
      return RequestStatus::kIllConditioned;
    }
    if ((status = warped_.begin(std::size_t(count_))) != RequestStatus::kOk) break;
    for (int j = 0; j < count_ && status == RequestStatus::kOk; ++j) {
      const Eigen::Matrix3d Rt = integrated_rotation(point_omega(j));
      Eigen::Map<Eigen::Matrix3d> stored(&rotation_[9 * std::size_t(j)]);
      stored = Rt;
      status = add_rotated(j, Rt);
    }
    if (status == RequestStatus::kOk) status = warped_.solve();
    ++iterations_;
    if (status != RequestStatus::kOk) {
      const auto end = fmt::format_to_n(message_.data(), message_.size() - 1,
                                        "the warped solve, after {} solves: {}", iterations_,
                                        warped_.message());
      *end.out = '\0';
      return status;
    }
    last = &warped_;
  }
  if (status != RequestStatus::kOk) return status;
  // Back to the world: f = R̃⁻ᵀ f̂ (a given force stays as given), x − p = R̃ û.
  const auto f_hat = last->forces();
  const auto u_point = last->displacements();
  for (int j = 0; j < count_; ++j) {
    const auto jj = static_cast<std::size_t>(j);
    const Eigen::Map<const Eigen::Matrix3d> Rt(&rotation_[9 * jj]);
    Eigen::Map<Eigen::Vector3d> f(&force_[3 * jj]);
    if (kind_[jj] == ConstraintKind::kForce)
      f = Eigen::Map<const Eigen::Vector3d>(&value_[3 * jj]);
    else
      f = Rt.transpose().inverse() * f_hat.segment<3>(3 * j);
    // With the final ω, as surface_displacement() carries the field.
    Eigen::Map<Eigen::Vector3d> x(&displacement_[3 * jj]);
    x = integrated_rotation(point_omega(j)) * u_point.segment<3>(3 * j);
  }
  solved_ = true;
  return RequestStatus::kOk;
}

Eigen::Vector3d WarpedSolver::total_force() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int j = 0; j < count_; ++j) sum += Eigen::Map<const Eigen::Vector3d>(&force_[3 * std::size_t(j)]);
  return sum;
}

void WarpedSolver::surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const {
  PALPATE_DEMAND(solved_ && u_m.size() == u_hat_.size());
  // û of the last solve is in u_hat_ (the field the final ω came from).
  for (Eigen::Index v = 0; v < u_hat_.size() / 3; ++v)
    u_m.segment<3>(3 * v) =
        integrated_rotation(Eigen::Map<const Eigen::Vector3d>(&omega_[3 * std::size_t(v)])) *
        u_hat_.segment<3>(3 * v);
}

}  // namespace palpate
