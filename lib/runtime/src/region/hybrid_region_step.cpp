// The served region's time stepping (docs/model/hybrid-serving.md, "The hybrid model as
// served"): a tick's steps, u_Γ⁰ from the rest's loads, the implicit step
// (the served one) and the explicit substeps (its baseline) with their
// proven bound, and the push on the rest. The rest of HybridRegion (its
// surface, the interface faces, cuts, queries) is in hybrid_region.cpp.

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"
#include "palpate/runtime/hybrid_region.hpp"
#include "palpate/runtime/region/hybrid_region_limits.hpp"
#include "palpate/runtime/region/region_implicit_step.hpp"

namespace palpate {

using Eigen::Vector3d;

using detail::kRegionMaxAdvanceS;
using detail::kRegionWhat;

void HybridRegion::advance(double tick_s, std::span<const int> rest_indices,
                           std::span<const double> rest_forces_n, std::span<const RegionTip> tips) {
  if (!(tick_s > 0) || !std::isfinite(tick_s))
    throw InputError(
        fmt::format("{}: tick of {} s; a finite duration > 0 is accepted", kRegionWhat, tick_s));
  if (tips.size() > static_cast<std::size_t>(settings_.max_tips))
    throw InputError(fmt::format("{}: {} tips; at most {} (max_tips) are accepted", kRegionWhat,
                                 tips.size(), settings_.max_tips));
  if (rest_forces_n.size() != 3 * rest_indices.size())
    throw InputError(
        fmt::format("{}: {} rest forces for {} loaded vertices; 3 per vertex are "
                    "accepted",
                    kRegionWhat, rest_forces_n.size(), rest_indices.size()));
  for (const int l : rest_indices)
    if (l < 0 || l >= model_ref_.compliance_vertex_count())
      throw InputError(fmt::format("{}: a rest load on compliance vertex {}; 0..{} are accepted",
                                   kRegionWhat, l, model_ref_.compliance_vertex_count() - 1));

  offset_from_rest_loads(rest_indices, rest_forces_n);
  if (settings_.integrator == RegionIntegrator::kImplicit) {
    // The whole steps nearest to the time owed: a tick a little short or
    // long of Δt still takes one step.
    pending_s_ = std::min(pending_s_ + tick_s, kRegionMaxAdvanceS);
    substeps_ = static_cast<int>(std::floor(pending_s_ / substep_s_ + 0.5));
    pending_s_ -= substeps_ * substep_s_;
    if (substeps_ > 0) advance_implicit(tips);
    return;
  }
  // Substeps of a fixed Δt (the bound): the tick's time, plus what the
  // last tick left over, in whole steps; the remainder waits for the next.
  pending_s_ = std::min(pending_s_ + tick_s, kRegionMaxAdvanceS);
  substeps_ = static_cast<int>(std::floor(pending_s_ / substep_s_));
  pending_s_ -= substeps_ * substep_s_;
  if (substeps_ > 0) advance_explicit(tips);
}

// u_Γ⁰ = G_ΓS f_S on the held Γ (explicit) or on Γ as loaded (implicit).
void HybridRegion::offset_from_rest_loads(std::span<const int> rest_indices,
                                          std::span<const double> rest_forces_n) {
  const bool implicit = settings_.integrator == RegionIntegrator::kImplicit;
  const std::vector<int>& gamma = implicit ? loaded_compliance_ : interface_compliance_;
  Eigen::VectorXd& offset = implicit ? loaded_offset_m_ : offset_m_;
  offset.setZero();
  for (std::size_t j = 0; j < rest_indices.size(); ++j) {
    const Vector3d f(rest_forces_n[3 * j], rest_forces_n[3 * j + 1], rest_forces_n[3 * j + 2]);
    for (std::size_t k = 0; k < gamma.size(); ++k)
      offset.segment<3>(3 * static_cast<Eigen::Index>(k)) +=
          model_ref_.G_block(gamma[k], rest_indices[j]) * f;
  }
}

void HybridRegion::advance_explicit(std::span<const RegionTip> tips) {
  for (auto& f : tip_force_step_n_) f.setZero();
  for (auto& m : tip_torque_step_nm_) m.setZero();
  for (int n = 0; n < substeps_; ++n) {
    add_tip_forces(tips, true);
    step_force_n_ = region_load_n_;
    add_coupling_force();
    model_.step(substep_s_, step_force_n_);
  }
  for (std::size_t t = 0; t < tip_force_n_.size(); ++t) {
    const bool given = t < tips.size();
    tip_force_n_[t] = given ? Vector3d(tip_force_step_n_[t] / substeps_) : Vector3d::Zero();
    tip_torque_nm_[t] = given ? Vector3d(tip_torque_step_nm_[t] / substeps_) : Vector3d::Zero();
  }

  // f_Γ = S (u_Γ − u_Γ⁰) at the end of the tick.
  step_force_n_.setZero();
  add_coupling_force();
}

// Backward Euler, A u⁺ = b (region_implicit_step.hpp), per step:
//   b = f_tips(u) + M [c u + (u − u⁻)/Δt²] + k_s u (skin) + h u (held)
//       + S u_Γ⁰ (Γ),
// the tips' penalty taken at u and corrected by k_s (u⁺ − u) (A's k_s), so
// that it is exact at rest and damps, never feeds, the motion between.
// S u_Γ⁰ is never formed: the solve shifts Γ by u_Γ⁰ (solve_offset). The
// push on the rest is read off Γ's rows: S (u⁺_Γ − u_Γ⁰) = b_Γ − S u_Γ⁰
// − ((A − S) u⁺)_Γ, a sparse product instead of a dense one.
void HybridRegion::advance_implicit(std::span<const RegionTip> tips) {
  const detail::ImplicitStepCoefficients& step = implicit_->coefficients();
  const double c = step.mass_coefficient(), inv_dt2 = 1 / (step.time_step_s * step.time_step_s);
  const int nv = model_.vertex_count();
  const auto n_loaded = static_cast<Eigen::Index>(loaded_interface_.size());
  for (int n = 0; n < substeps_; ++n) {
    const Eigen::VectorXd& u = model_.displacement_m();
    const Eigen::VectorXd& u_previous = model_.previous_displacement_m();
    add_tip_forces(tips, false);
    rhs_n_ = region_load_n_;
    for (int v = 0; v < nv; ++v) {
      if (model_.is_fixed(v)) continue;
      const auto u_v = u.segment<3>(3 * v);
      rhs_n_.segment<3>(3 * v) +=
          model_.mass_kg(v) * (c * u_v + inv_dt2 * (u_v - u_previous.segment<3>(3 * v))) +
          ((on_skin_[v] != 0 ? step.skin_stiffness_n_per_m : 0.0) +
           (implicit_->holds(v) ? implicit_->hold_stiffness() : 0.0)) *
              u_v;
    }
    for (Eigen::Index g = 0; g < n_loaded; ++g) {
      const int v = loaded_interface_[g];
      rhs_n_.segment<3>(3 * v) += implicit_->interface_proximal(v) * u.segment<3>(3 * v);
    }
    // b without S u_Γ⁰ in rhs_n_, and the solve adds it.
    implicit_->solve_offset(rhs_n_, loaded_offset_m_, next_m_);
    implicit_->interface_rows(next_m_, loaded_rows_n_);
    for (Eigen::Index g = 0; g < n_loaded; ++g)
      loaded_push_n_.segment<3>(3 * g) =
          rhs_n_.segment<3>(3 * loaded_interface_[g]) - loaded_rows_n_.segment<3>(3 * g);
    retimed_m_ = u;
    model_.set_state(next_m_, retimed_m_);
  }
  // What the tips feel: the penalty at u⁺.
  for (auto& f : tip_force_step_n_) f.setZero();
  for (auto& m : tip_torque_step_nm_) m.setZero();
  add_tip_forces(tips, true);
  for (std::size_t t = 0; t < tip_force_n_.size(); ++t) {
    const bool given = t < tips.size();
    tip_force_n_[t] = given ? tip_force_step_n_[t] : Vector3d::Zero();
    tip_torque_nm_[t] = given ? tip_torque_step_nm_[t] : Vector3d::Zero();
  }
  // f_Γ and u_Γ − u_Γ⁰ on the held Γ.
  const Eigen::VectorXd& u = model_.displacement_m();
  for (std::size_t k = 0; k < interface_.size(); ++k) {
    const auto at = static_cast<Eigen::Index>(3 * k);
    const auto slot = static_cast<Eigen::Index>(3 * held_slot_[k]);
    interface_force_n_.segment<3>(at) = loaded_push_n_.segment<3>(slot);
    gamma_u_m_.segment<3>(at) = u.segment<3>(3 * interface_[k]) - loaded_offset_m_.segment<3>(slot);
  }
}

// f_Γ = S (u_Γ − u_Γ⁰) from the displacement now, and −f_Γ on the region's
// Γ vertices (the rest pushes back) into step_force_n_.
void HybridRegion::add_coupling_force() {
  if (interface_.empty()) return;
  for (std::size_t k = 0; k < interface_.size(); ++k)
    gamma_u_m_.segment<3>(3 * static_cast<Eigen::Index>(k)) =
        model_.displacement_m().segment<3>(3 * interface_[k]) -
        offset_m_.segment<3>(3 * static_cast<Eigen::Index>(k));
  // S is symmetric: its lower half is read, half the memory of the product.
  interface_force_n_.noalias() = coupling_.selfadjointView<Eigen::Lower>() * gamma_u_m_;
  for (std::size_t k = 0; k < interface_.size(); ++k)
    step_force_n_.segment<3>(3 * interface_[k]) -=
        interface_force_n_.segment<3>(3 * static_cast<Eigen::Index>(k));
}

// Σ_w |S_vw| per Γ row, the coupling's part of Gershgorin's bound.
void HybridRegion::update_coupling_row_sums() {
  coupling_row_sum_ = coupling_.cwiseAbs().rowwise().sum();
}

void HybridRegion::update_explicit_bound() {
  // Two proven bounds on the elastic part, the smaller taken: the element
  // bound with the coupling's, ω² ≤ ω_elements² + λ_max(S) / min m_Γ, and
  // Gershgorin's on M⁻¹ (K + S); then the contacts', max_tips · k / min
  // m_skin (each term bounds its part's Rayleigh quotient: docs/model/hybrid-serving.md).
  const double inf = std::numeric_limits<double>::infinity();
  double least_interface_mass = inf, least_skin_mass = inf;
  for (int v : interface_)
    if (!model_.is_detached(v))
      least_interface_mass = std::min(least_interface_mass, model_.mass_kg(v));
  for (int v : skin_) least_skin_mass = std::min(least_skin_mass, model_.mass_kg(v));
  double elastic2 = element_omega2_;
  if (least_interface_mass < inf) elastic2 += coupling_eigen_max_ / least_interface_mass;
  if (model_.remaining_tetrahedra() > 0) {
    // Gershgorin's discs of M⁻¹ (K + S) lie within the sum of K's widest
    // and S's widest (per mass) row.
    const double gershgorin_k = model_.stable_time_step(0.5, 1).gershgorin_omega_rad_s;
    double coupling_rows = 0;
    for (std::size_t k = 0; k < interface_.size(); ++k)
      if (!model_.is_detached(interface_[k]))
        coupling_rows =
            std::max(coupling_rows,
                     coupling_row_sum_.segment<3>(3 * static_cast<Eigen::Index>(k)).maxCoeff() /
                         model_.mass_kg(interface_[k]));
    elastic2 = std::min(elastic2, gershgorin_k * gershgorin_k + coupling_rows);
  }
  double omega2 = elastic2;
  if (least_skin_mass < inf)
    omega2 += settings_.max_tips * settings_.contact_stiffness_n_per_m / least_skin_mass;
  substep_bound_s_ =
      omega2 > 0 ? settings_.step_safety * 2 / std::sqrt(omega2) : kRegionMaxAdvanceS;
}

void HybridRegion::retime_explicit_step() {
  if (implicit_ || substep_bound_s_ >= substep_s_) return;
  // A lighter vertex needs a shorter step. The centred difference keeps
  // u⁻ = u(t − Δt): re-time it for the new Δt at the same velocity.
  const Eigen::VectorXd& u = model_.displacement_m();
  retimed_m_ = u - (u - model_.previous_displacement_m()) * (substep_bound_s_ / substep_s_);
  model_.set_state(u, retimed_m_);
  substep_s_ = substep_bound_s_;
}

}  // namespace palpate
