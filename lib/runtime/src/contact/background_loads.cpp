#include "palpate/runtime/contact/background_loads.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "palpate/core/error.hpp"

namespace palpate::detail {

void LoadColumns::reserve(const SurfaceModel& model, int count) {
  model_ = &model;
  capacity_ = std::max(count, 0);
  const auto n = static_cast<std::size_t>(model.compliance_vertex_count());
  index_.resize(static_cast<std::size_t>(capacity_));
  count_ = 0;
  rows_ = std::make_unique_for_overwrite<double[]>(9 * static_cast<std::size_t>(capacity_) * n);
  epoch_.assign(n, 0);
  epoch_now_ = 1;
}

Eigen::Map<const Eigen::MatrixX3d> LoadColumns::at(int v, std::span<const int> indices) {
  const auto count = static_cast<Eigen::Index>(indices.size());
  if (count != count_ || !std::equal(indices.begin(), indices.end(), index_.begin())) {
    count_ = static_cast<int>(count);
    std::copy(indices.begin(), indices.end(), index_.begin());
    if (++epoch_now_ == 0) {  // after 2³² sets: every vertex is gathered again
      std::fill(epoch_.begin(), epoch_.end(), 0);
      epoch_now_ = 1;
    }
  }
  const auto slot = static_cast<std::size_t>(v);
  double* column = rows_.get() + 9 * static_cast<std::size_t>(capacity_) * slot;
  Eigen::Map<Eigen::MatrixX3d> block(column, 3 * count, 3);
  if (epoch_[slot] != epoch_now_) {
    // G^{b v} down the columns of v, the loads' rows in their order.
    for (Eigen::Index j = 0; j < count; ++j)
      block.middleRows<3>(3 * j) = model_->G_block(indices[static_cast<std::size_t>(j)], v);
    epoch_[slot] = epoch_now_;
  }
  return {column, 3 * count, 3};
}

void BackgroundLoads::reserve(const SurfaceModel& model, int count, LoadColumns& columns) {
  model_ = &model;
  columns_ = &columns;
  const int n = model.compliance_vertex_count();
  const auto loads = static_cast<std::size_t>(std::max(count, 0));
  index_.resize(loads);
  force_.resize(3 * loads);
  displacement_.resize(3 * loads);
  has_displacement_ = false;
  count_ = 0;
  softness_.resize(static_cast<std::size_t>(n));
  for (int v = 0; v < n; ++v)
    softness_[static_cast<std::size_t>(v)] = std::sqrt(model.G_block(v, v).norm());
  u_.assign(static_cast<std::size_t>(n), Eigen::Vector3d::Zero());
  u_epoch_.assign(static_cast<std::size_t>(n), 0);
  u_drift_.assign(static_cast<std::size_t>(n), 0.0);
  forget_all();
}

void BackgroundLoads::forget_all() {
  std::fill(u_epoch_.begin(), u_epoch_.end(), 0);
  epoch_ = 1;
  drift_ = 0;
}

void BackgroundLoads::set(std::span<const int> indices, std::span<const double> forces_n,
                          double energy_j) {
  replace(indices, forces_n, energy_j, {});
}

void BackgroundLoads::set(std::span<const int> indices, std::span<const double> forces_n,
                          std::span<const double> displacements_m) {
  if (displacements_m.size() != forces_n.size())
    throw InputError(fmt::format(
        "{} background displacements for {} forces; one per force (u_b = G f_b) is accepted",
        displacements_m.size(), forces_n.size()));
  double energy = 0;
  for (std::size_t i = 0; i < forces_n.size(); ++i) energy += forces_n[i] * displacements_m[i];
  replace(indices, forces_n, energy, displacements_m);
}

void BackgroundLoads::replace(std::span<const int> indices, std::span<const double> forces_n,
                              double energy_j, std::span<const double> displacements_m) {
  if (indices.size() > index_.size() || forces_n.size() != 3 * indices.size())
    throw InputError(fmt::format(
        "{} background loads with {} forces; at most {} (reserve_background_loads), 3 forces "
        "each, are accepted",
        indices.size(), forces_n.size(), index_.size()));
  for (const int v : indices)
    if (v < 0 || v >= static_cast<int>(u_.size()))
      throw InputError(fmt::format("background load on compliance vertex {}; 0..{} are accepted", v,
                                   static_cast<int>(u_.size()) - 1));
  const bool same = static_cast<int>(indices.size()) == count_ &&
                    std::equal(indices.begin(), indices.end(), index_.begin());
  if (!same) {
    forget_all();
  } else if (has_displacement_ && !displacements_m.empty()) {
    // The change's energy: |G_v Δf| ≤ √‖G^{vv}‖ √(Δfᵀ G Δf), with
    // G Δf = Δu_b at the loads. The u_b given carry the round-off of a solve:
    // a millionth of the loads' own spread is added for it.
    double change = 0;
    for (std::size_t i = 0; i < forces_n.size(); ++i)
      change += (forces_n[i] - force_[i]) * (displacements_m[i] - displacement_[i]);
    drift_ +=
        (1 + 1e-6) * std::sqrt(std::max(change, 0.0)) + 1e-6 * std::sqrt(std::max(energy_j, 0.0));
  } else {
    // |G_v Δf| ≤ Σ_j ‖G^{vj}‖ |Δf_j| ≤ √‖G^{vv}‖ Σ_j √‖G^{jj}‖ |Δf_j|
    // (G symmetric positive definite: ‖G^{vj}‖² ≤ ‖G^{vv}‖ ‖G^{jj}‖).
    double change = 0;
    for (std::size_t j = 0; j < indices.size(); ++j)
      change += softness_[static_cast<std::size_t>(indices[j])] *
                (Eigen::Map<const Eigen::Vector3d>(&forces_n[3 * j]) -
                 Eigen::Map<const Eigen::Vector3d>(&force_[3 * j]))
                    .norm();
    drift_ += (1 + 1e-6) * change;
  }
  count_ = static_cast<int>(indices.size());
  std::copy(indices.begin(), indices.end(), index_.begin());
  std::copy(forces_n.begin(), forces_n.end(), force_.begin());
  has_displacement_ = !displacements_m.empty();
  std::copy(displacements_m.begin(), displacements_m.end(), displacement_.begin());
  energy_j_ = std::max(energy_j, 0.0);
  if (++epoch_ == 0) forget_all();  // after 2³² sets: the bounds start again
}

void BackgroundLoads::copy_from(const BackgroundLoads& other) {
  const auto n = static_cast<std::size_t>(other.count_);
  replace({other.index_.data(), n}, {other.force_.data(), 3 * n}, other.energy_j_,
          other.has_displacement_ ? std::span<const double>{other.displacement_.data(), 3 * n}
                                  : std::span<const double>{});
}

const Eigen::Vector3d& BackgroundLoads::at(int v) {
  const auto slot = static_cast<std::size_t>(v);
  if (u_epoch_[slot] != epoch_) {
    // u_b = Σ_j G^{v b_j} f_j = (G^{b v})ᵀ f_b.
    u_[slot].noalias() =
        columns_->at(v, {index_.data(), static_cast<std::size_t>(count_)}).transpose() *
        Eigen::Map<const Eigen::VectorXd>(force_.data(), 3 * static_cast<Eigen::Index>(count_));
    u_epoch_[slot] = epoch_;
    u_drift_[slot] = drift_;
  }
  return u_[slot];
}

}  // namespace palpate::detail
