#include "palpate/runtime/hybrid_region.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "palpate/core/error.hpp"
#include "region_implicit_step.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;

constexpr const char* kWhat = "cut region";
// Simulated time one advance() may cover: a tick after a pause of seconds is
// not replayed step by step (docs/model.md, "The hybrid model as served").
constexpr double kMaxAdvanceS = 0.01;

std::array<int, 3> sorted(std::array<int, 3> t) {
  std::sort(t.begin(), t.end());
  return t;
}

// The faces of a tetrahedron (a, b, c, d), by the vertex each leaves out.
constexpr int kFace[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};

std::vector<Matrix12d> element_stiffnesses(const CutRegionData& region) {
  std::vector<Matrix12d> out(static_cast<std::size_t>(region.tetrahedra.rows()));
  for (Eigen::Index t = 0; t < region.tetrahedra.rows(); ++t)
    for (int i = 0; i < 12; ++i)
      for (int j = 0; j < 12; ++j)
        out[static_cast<std::size_t>(t)](i, j) = region.element_stiffness_n_per_m(t, 12 * i + j);
  return out;
}

const CutRegionData& region_of(const SurfaceModel& model) {
  if (!model.cut_region)
    throw InputError(fmt::format(
        "{}: model '{}' ({}) has no cuttable region; a compliance file made with [cut_region] "
        "(format 1.3, docs/precompute.md \"A cuttable region\") is accepted",
        kWhat, model.id, model.path.string()));
  return *model.cut_region;
}

TensorMassMaterial material_of(const CutRegionData& region, const HybridRegionSettings& s) {
  if (!(s.step_safety > 0 && s.step_safety < 1))
    throw InputError(
        fmt::format("{}: step safety {}; a fraction in (0, 1) is accepted", kWhat, s.step_safety));
  if (!(s.contact_stiffness_n_per_m >= 0) || !std::isfinite(s.contact_stiffness_n_per_m))
    throw InputError(fmt::format("{}: contact stiffness {} N/m; a finite value ≥ 0 is accepted",
                                 kWhat, s.contact_stiffness_n_per_m));
  if (s.max_tips < 1 || s.max_tips > 64)
    throw InputError(fmt::format("{}: {} tips; 1 to 64 are accepted", kWhat, s.max_tips));
  if (!(s.implicit_step_s > 0 && s.implicit_step_s <= kMaxAdvanceS))
    throw InputError(fmt::format("{}: implicit step {} s; a step in (0, {}] s is accepted", kWhat,
                                 s.implicit_step_s, kMaxAdvanceS));
  if (!(s.interface_damping >= 0) || !std::isfinite(s.interface_damping))
    throw InputError(fmt::format("{}: interface damping κ = {}; a finite κ ≥ 0 is accepted", kWhat,
                                 s.interface_damping));
  if (s.refactor_rank < 3 || s.refactor_rank > 3000)
    throw InputError(
        fmt::format("{}: refactor rank {}; 3 to 3000 DOFs are accepted", kWhat, s.refactor_rank));
  if (!std::isfinite(s.damping_per_s))
    throw InputError(fmt::format(
        "{}: damping {} 1/s; a finite γ ≥ 0, or a negative value for the file's, is accepted",
        kWhat, s.damping_per_s));
  return {region.density_kg_m3, s.damping_per_s >= 0 ? s.damping_per_s : region.damping_per_s};
}

}  // namespace

HybridRegion::HybridRegion(const SurfaceModel& model, const HybridRegionSettings& settings)
    : model_ref_(model),
      settings_(settings),
      model_(region_of(model).vertices_m, region_of(model).tetrahedra,
             element_stiffnesses(region_of(model)), material_of(region_of(model), settings),
             std::vector<int>(region_of(model).fixed_vertices.begin(),
                              region_of(model).fixed_vertices.end())) {
  const CutRegionData& region = *model.cut_region;
  // The element bound alone, before the coupling joins it (docs/model.md).
  const double element_omega = model_.stable_time_step(0.5, 1).element_omega_rad_s;
  element_omega2_ = element_omega * element_omega;

  // S = G_ΓΓ⁻¹ from the file's own G.
  interface_.assign(region.interface_vertices.begin(), region.interface_vertices.end());
  interface_compliance_.assign(region.interface_compliance_index.begin(),
                               region.interface_compliance_index.end());
  const auto n = static_cast<Eigen::Index>(interface_.size());
  Eigen::MatrixXd g_gg(3 * n, 3 * n);
  for (Eigen::Index a = 0; a < n; ++a)
    for (Eigen::Index b = 0; b < n; ++b)
      g_gg.block<3, 3>(3 * a, 3 * b) =
          model.G_block(interface_compliance_[a], interface_compliance_[b]);
  g_gg = 0.5 * (g_gg + g_gg.transpose()).eval();  // symmetric to round-off as stored
  const Eigen::LLT<Eigen::MatrixXd> llt(g_gg);
  if (n > 0 && llt.info() != Eigen::Success)
    throw InputError(fmt::format(
        "{}: model '{}': G on the region's boundary Γ ({} vertices) is not positive definite, so "
        "the rest of the organ has no stiffness there; a compliance file precompute wrote and "
        "checked is accepted",
        kWhat, model.id, n));
  coupling_ = llt.solve(Eigen::MatrixXd::Identity(3 * n, 3 * n));
  coupling_ = 0.5 * (coupling_ + coupling_.transpose()).eval();
  if (n > 0) {
    coupling_eigen_max_ =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(coupling_, Eigen::EigenvaluesOnly)
            .eigenvalues()
            .maxCoeff();
  }
  update_coupling_row_sums();
  loaded_interface_ = interface_;
  loaded_compliance_ = interface_compliance_;
  held_slot_.resize(interface_.size());
  for (std::size_t k = 0; k < held_slot_.size(); ++k) held_slot_[k] = static_cast<int>(k);

  // The faces the region shares with the rest, matched by input-file ids.
  std::map<std::array<int, 3>, int> rest_faces;
  const DrawnSurface& drawn = model.surface;
  for (int t = 0; t < drawn.triangle_count(); ++t) {
    std::array<int, 3> key{};
    for (int c = 0; c < 3; ++c)
      key[c] = model.source_vertex_ids.at(drawn.vertex_ids[drawn.triangles[3 * t + c]]);
    rest_faces.emplace(sorted(key), t);
  }
  rest_triangle_face_.assign(static_cast<std::size_t>(drawn.triangle_count()), -1);
  for (int t = 0; t < model_.tetrahedron_count(); ++t) {
    for (const auto& face : kFace) {
      std::array<int, 3> region_vertices{}, key{};
      for (int c = 0; c < 3; ++c) {
        region_vertices[c] = region.tetrahedra(t, face[c]);
        key[c] = region.source_vertex_ids[region_vertices[c]];
      }
      const auto found = rest_faces.find(sorted(key));
      if (found != rest_faces.end())
        interface_faces_.push_back({sorted(region_vertices), found->second, t});
    }
  }
  std::sort(interface_faces_.begin(), interface_faces_.end(),
            [](const InterfaceFace& a, const InterfaceFace& b) {
              return a.region_sorted < b.region_sorted;
            });
  for (std::size_t f = 0; f < interface_faces_.size(); ++f)
    rest_triangle_face_[static_cast<std::size_t>(interface_faces_[f].rest_triangle)] =
        static_cast<int>(f);

  const int nv = model_.vertex_count();
  on_skin_.assign(static_cast<std::size_t>(nv), 0);
  skin_.reserve(static_cast<std::size_t>(nv));
  visible_.reserve(model_.boundary_triangles().capacity());
  offset_m_ = Eigen::VectorXd::Zero(3 * n);
  interface_force_n_ = Eigen::VectorXd::Zero(3 * n);
  gamma_u_m_ = Eigen::VectorXd::Zero(3 * n);
  region_load_n_ = Eigen::VectorXd::Zero(3 * nv);
  step_force_n_ = Eigen::VectorXd::Zero(3 * nv);
  tip_force_n_.assign(static_cast<std::size_t>(settings_.max_tips), Vector3d::Zero());
  tip_force_step_n_ = tip_force_n_;
  tip_torque_nm_ = tip_force_n_;
  tip_torque_step_nm_ = tip_force_n_;
  retimed_m_ = Eigen::VectorXd::Zero(3 * nv);
  removed_.reserve(static_cast<std::size_t>(model_.tetrahedron_count()));
  update_after_topology_change();
  substep_s_ = substep_bound_s_;
  if (settings_.integrator == RegionIntegrator::kImplicit) {
    substep_s_ = settings_.implicit_step_s;
    const detail::ImplicitStepCoefficients coefficients{
        settings_.implicit_step_s, material_of(region, settings_).mass_damping_per_s,
        settings_.contact_stiffness_n_per_m, settings_.interface_damping};
    implicit_ = std::make_unique<detail::ImplicitRegionStep>(
        model_, loaded_interface_, coupling_, coefficients, on_skin_, settings_.refactor_rank);
    rhs_n_ = Eigen::VectorXd::Zero(3 * nv);
    next_m_ = rhs_n_;
    loaded_offset_m_ = Eigen::VectorXd::Zero(3 * n);
    loaded_s_offset_n_ = loaded_offset_m_;
    loaded_push_n_ = loaded_offset_m_;
    loaded_rows_n_ = loaded_offset_m_;
    skin_before_.reserve(static_cast<std::size_t>(nv));
    touched_.reserve(static_cast<std::size_t>(nv));
  }
}

HybridRegion::~HybridRegion() = default;

int HybridRegion::update_rank() const { return implicit_ ? implicit_->update_rank() : 0; }
int HybridRegion::factorizations() const { return implicit_ ? implicit_->factorizations() : 0; }
double HybridRegion::last_factorization_s() const {
  return implicit_ ? implicit_->last_factorization_s() : 0;
}
void HybridRegion::finish_background_work() {
  if (implicit_) implicit_->finish_background_work(on_skin_);
}

bool HybridRegion::is_interface_face(const std::array<int, 3>& triangle) const {
  const auto key = sorted(triangle);
  const auto at = std::lower_bound(
      interface_faces_.begin(), interface_faces_.end(), key,
      [](const InterfaceFace& f, const std::array<int, 3>& k) { return f.region_sorted < k; });
  return at != interface_faces_.end() && at->region_sorted == key;
}

void HybridRegion::update_after_topology_change() {
  visible_.clear();
  for (const auto& t : model_.boundary_triangles())
    if (!is_interface_face(t)) visible_.push_back(t);
  for (int v : skin_) on_skin_[v] = 0;
  skin_.clear();
  // Γ vertices are pressed through the rest's triangles around them (the
  // contact engine's), not twice.
  for (int v : interface_) on_skin_[v] = 1;
  for (const auto& t : visible_)
    for (int v : t)
      if (on_skin_[v] == 0 && !model_.is_fixed(v) && !model_.is_detached(v)) {
        on_skin_[v] = 1;
        skin_.push_back(v);
      }

  for (int v : interface_) on_skin_[v] = 0;

  // Two proven bounds on the elastic part, the smaller taken: the element
  // bound with the coupling's, ω² ≤ ω_elements² + λ_max(S) / min m_Γ, and
  // Gershgorin's on M⁻¹ (K + S); then the contacts', max_tips · k / min
  // m_skin (each term bounds its part's Rayleigh quotient: docs/model.md).
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
  substep_bound_s_ = omega2 > 0 ? settings_.step_safety * 2 / std::sqrt(omega2) : kMaxAdvanceS;
}

void HybridRegion::add_tip_forces(std::span<const RegionTip> tips, bool accumulate) {
  region_load_n_.setZero();
  pressed_vertices_ = 0;
  const double k = settings_.contact_stiffness_n_per_m;
  const auto& u = model_.displacement_m();
  const auto& rest = model_.rest_positions_m();
  for (std::size_t t = 0; t < tips.size(); ++t) {
    const RegionTip& tip = tips[t];
    const Vector3d axis = tip.end_m - tip.base_m;
    const double length2 = axis.squaredNorm();
    Vector3d on_tip = Vector3d::Zero(), about_base = Vector3d::Zero();
    for (int v : skin_) {
      const Vector3d x = rest.row(v).transpose() + u.segment<3>(3 * v);
      const double s = length2 > 0 ? std::clamp((x - tip.base_m).dot(axis) / length2, 0.0, 1.0) : 0;
      const Vector3d from_axis = x - (tip.base_m + s * axis);
      const double d = from_axis.norm();
      if (d >= tip.radius_m || d <= 1e-12 * tip.radius_m) continue;  // clear, or on the axis
      const Vector3d f = k * (tip.radius_m - d) / d * from_axis;
      region_load_n_.segment<3>(3 * v) += f;
      on_tip -= f;
      about_base -= (x - tip.base_m).cross(f);
      ++pressed_vertices_;
    }
    if (accumulate) {
      tip_force_step_n_[t] += on_tip;
      tip_torque_step_nm_[t] += about_base;
    }
  }
}

void HybridRegion::advance(double tick_s, std::span<const int> rest_indices,
                           std::span<const double> rest_forces_n, std::span<const RegionTip> tips) {
  if (!(tick_s > 0) || !std::isfinite(tick_s))
    throw InputError(
        fmt::format("{}: tick of {} s; a finite duration > 0 is accepted", kWhat, tick_s));
  if (tips.size() > static_cast<std::size_t>(settings_.max_tips))
    throw InputError(fmt::format("{}: {} tips; at most {} (max_tips) are accepted", kWhat,
                                 tips.size(), settings_.max_tips));
  if (rest_forces_n.size() != 3 * rest_indices.size())
    throw InputError(
        fmt::format("{}: {} rest forces for {} loaded vertices; 3 per vertex are "
                    "accepted",
                    kWhat, rest_forces_n.size(), rest_indices.size()));

  offset_from_rest_loads(rest_indices, rest_forces_n);
  if (settings_.integrator == RegionIntegrator::kImplicit) {
    // The whole steps nearest to the time owed: a tick a little short or
    // long of Δt still takes one step.
    pending_s_ = std::min(pending_s_ + tick_s, kMaxAdvanceS);
    substeps_ = static_cast<int>(std::floor(pending_s_ / substep_s_ + 0.5));
    pending_s_ -= substeps_ * substep_s_;
    if (substeps_ > 0) advance_implicit(tips);
    return;
  }
  // Substeps of a fixed Δt (the bound): the tick's time, plus what the
  // last tick left over, in whole steps; the remainder waits for the next.
  pending_s_ = std::min(pending_s_ + tick_s, kMaxAdvanceS);
  substeps_ = static_cast<int>(std::floor(pending_s_ / substep_s_));
  pending_s_ -= substeps_ * substep_s_;
  if (substeps_ > 0) advance_explicit(tips);
}

// u_Γ⁰ = G_ΓS f_S on the held Γ (explicit) or on Γ as loaded (implicit,
// with S u_Γ⁰).
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
  if (implicit && offset.size() > 0) {
    if (rest_indices.empty())
      loaded_s_offset_n_.setZero();
    else
      detail::symmetric_product(coupling_, offset, loaded_s_offset_n_);
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
// The push on the rest is read off Γ's rows: S (u⁺_Γ − u_Γ⁰) = b_Γ − S u_Γ⁰
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
      rhs_n_.segment<3>(3 * v) += loaded_s_offset_n_.segment<3>(3 * g) +
                                  implicit_->interface_proximal(v) * u.segment<3>(3 * v);
    }
    implicit_->solve(rhs_n_, next_m_);
    implicit_->interface_rows(next_m_, loaded_rows_n_);
    for (Eigen::Index g = 0; g < n_loaded; ++g)
      loaded_push_n_.segment<3>(3 * g) = rhs_n_.segment<3>(3 * loaded_interface_[g]) -
                                         loaded_s_offset_n_.segment<3>(3 * g) -
                                         loaded_rows_n_.segment<3>(3 * g);
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

void HybridRegion::add_rest_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const {
  if (u_m.size() != model_ref_.compliance_rows())
    throw InputError(fmt::format("{}: a field of {} values for {} compliance rows", kWhat,
                                 u_m.size(), model_ref_.compliance_rows()));
  for (std::size_t k = 0; k < interface_.size(); ++k) {
    const Vector3d f = interface_force_n_.segment<3>(3 * static_cast<Eigen::Index>(k));
    const Eigen::Index column = 3 * static_cast<Eigen::Index>(interface_compliance_[k]);
    if (model_ref_.float32())
      u_m.noalias() += model_ref_.G32.middleCols<3>(column).cast<double>() * f;
    else
      u_m.noalias() += model_ref_.G.middleCols<3>(column) * f;
  }
}

int HybridRegion::cut(const Vector3d& blade_a_m, const Vector3d& blade_b_m) {
  if (!blade_a_m.allFinite() || !blade_b_m.allFinite())
    throw InputError(fmt::format(
        "{}: a blade with a non-finite end; finite positions in metres are accepted", kWhat));
  model_.tetrahedra_crossed_by_segment(blade_a_m, blade_b_m, removed_);
  for (int t : removed_) model_.remove_tetrahedron(t);
  return after_cut(static_cast<int>(removed_.size()));
}

int HybridRegion::cut(const Blade& before, const Blade& after) {
  if (!before.a_m.allFinite() || !before.b_m.allFinite() || !after.a_m.allFinite() ||
      !after.b_m.allFinite())
    throw InputError(fmt::format(
        "{}: a blade with a non-finite end; finite positions in metres are accepted", kWhat));
  return after_cut(model_.cut_swept_blade(before, after, removed_));
}

int HybridRegion::after_cut(int removed) {
  if (removed == 0) return 0;
  release_detached_interface();
  if (implicit_) skin_before_.assign(on_skin_.begin(), on_skin_.end());
  update_after_topology_change();
  if (implicit_) {
    // A changed on the removed tetrahedra's vertices and where the skin did.
    touched_.clear();
    const Eigen::MatrixX4i& tets = model_.tetrahedra();
    for (int t : removed_)
      for (int c = 0; c < 4; ++c) touched_.push_back(tets(t, c));
    for (std::size_t v = 0; v < on_skin_.size(); ++v)
      if (on_skin_[v] != skin_before_[v]) touched_.push_back(static_cast<int>(v));
    std::sort(touched_.begin(), touched_.end());
    touched_.erase(std::unique(touched_.begin(), touched_.end()), touched_.end());
    implicit_->update(touched_, on_skin_);
    return removed;
  }
  if (substep_bound_s_ < substep_s_) {
    // A lighter vertex needs a shorter step. The centred difference keeps
    // u⁻ = u(t − Δt): re-time it for the new Δt at the same velocity.
    const Eigen::VectorXd& u = model_.displacement_m();
    retimed_m_ = u - (u - model_.previous_displacement_m()) * (substep_bound_s_ / substep_s_);
    model_.set_state(u, retimed_m_);
    substep_s_ = substep_bound_s_;
  }
  return removed;
}

// A Γ vertex the cut left without a region tetrahedron is no longer held by
// the region: the rest is free there. The rest's stiffness on the Γ still
// held is then S condensed onto it, S' = S_aa − S_ad S_dd⁻¹ S_da (the Schur
// complement of the dropped DOFs d; the same as inverting G on the kept
// vertices), and the dropped vertex carries no coupling force.
void HybridRegion::release_detached_interface() {
  std::vector<Eigen::Index> keep, drop;
  for (std::size_t k = 0; k < interface_.size(); ++k)
    for (int a = 0; a < 3; ++a)
      (model_.is_detached(interface_[k]) ? drop : keep)
          .push_back(3 * static_cast<Eigen::Index>(k) + a);
  if (drop.empty()) return;
  if (implicit_) {
    // The implicit step keeps S as loaded: a released vertex's rows hold no
    // region, which is this condensation solved with the rest (no mass
    // there, so its row says S (u_Γ − u_Γ⁰) = 0 at that vertex).
    std::vector<int> vertices, compliance, slots;
    for (std::size_t k = 0; k < interface_.size(); ++k)
      if (!model_.is_detached(interface_[k])) {
        vertices.push_back(interface_[k]);
        compliance.push_back(interface_compliance_[k]);
        slots.push_back(held_slot_[k]);
      }
    interface_ = std::move(vertices);
    interface_compliance_ = std::move(compliance);
    held_slot_ = std::move(slots);
    interface_force_n_ = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * interface_.size()));
    gamma_u_m_ = interface_force_n_;
    return;
  }
  const Eigen::MatrixXd s_ad = coupling_(keep, drop);
  const Eigen::MatrixXd s_dd = coupling_(drop, drop);
  Eigen::MatrixXd condensed = coupling_(keep, keep) - s_ad * s_dd.llt().solve(s_ad.transpose());
  coupling_ = 0.5 * (condensed + condensed.transpose());
  std::vector<int> vertices, compliance;
  for (std::size_t i = 0; i < keep.size(); i += 3) {
    vertices.push_back(interface_[static_cast<std::size_t>(keep[i] / 3)]);
    compliance.push_back(interface_compliance_[static_cast<std::size_t>(keep[i] / 3)]);
  }
  interface_ = std::move(vertices);
  interface_compliance_ = std::move(compliance);
  update_coupling_row_sums();
  const auto n = static_cast<Eigen::Index>(3 * interface_.size());
  offset_m_ = Eigen::VectorXd::Zero(n);
  interface_force_n_ = Eigen::VectorXd::Zero(n);
  gamma_u_m_ = Eigen::VectorXd::Zero(n);
}

Eigen::Vector3d HybridRegion::position_m(int vertex) const {
  return model_.rest_positions_m().row(vertex).transpose() +
         model_.displacement_m().segment<3>(3 * vertex);
}

Eigen::Vector3d HybridRegion::rest_point_of(const Eigen::Vector3d& x_m) const {
  int nearest = -1;
  double best = std::numeric_limits<double>::infinity();
  for (int v = 0; v < model_.vertex_count(); ++v) {
    if (model_.is_detached(v)) continue;
    const double d = (position_m(v) - x_m).squaredNorm();
    if (d < best) {
      best = d;
      nearest = v;
    }
  }
  return nearest < 0 ? x_m : Vector3d(x_m - model_.displacement_m().segment<3>(3 * nearest));
}

void HybridRegion::visible_triangles(std::vector<std::array<int, 3>>& out) const {
  out.assign(visible_.begin(), visible_.end());
}

int HybridRegion::covered_rest_triangles(std::span<std::uint32_t> out) const {
  std::size_t count = 0;
  for (const InterfaceFace& f : interface_faces_)
    if (!model_.is_removed(f.region_tet) && count < out.size())
      out[count++] = static_cast<std::uint32_t>(f.rest_triangle);
  return static_cast<int>(count);
}

bool HybridRegion::covers_rest_triangle(int triangle) const {
  const int f = rest_triangle_face_.at(static_cast<std::size_t>(triangle));
  return f >= 0 && !model_.is_removed(interface_faces_[static_cast<std::size_t>(f)].region_tet);
}

}  // namespace palpate
