#include "palpate/runtime/hybrid_region.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "palpate/core/error.hpp"
#include "palpate/runtime/region/hybrid_region_limits.hpp"
#include "palpate/runtime/region/region_implicit_step.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;

using detail::kRegionMaxAdvanceS;
using detail::kRegionWhat;

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
        kRegionWhat, model.id, model.path.string()));
  return *model.cut_region;
}

TensorMassMaterial material_of(const CutRegionData& region, const HybridRegionSettings& s) {
  if (!(s.step_safety > 0 && s.step_safety < 1))
    throw InputError(fmt::format("{}: step safety {}; a fraction in (0, 1) is accepted",
                                 kRegionWhat, s.step_safety));
  if (!(s.contact_stiffness_n_per_m >= 0) || !std::isfinite(s.contact_stiffness_n_per_m))
    throw InputError(fmt::format("{}: contact stiffness {} N/m; a finite value ≥ 0 is accepted",
                                 kRegionWhat, s.contact_stiffness_n_per_m));
  if (s.max_tips < 1 || s.max_tips > 64)
    throw InputError(fmt::format("{}: {} tips; 1 to 64 are accepted", kRegionWhat, s.max_tips));
  if (!(s.implicit_step_s > 0 && s.implicit_step_s <= kRegionMaxAdvanceS))
    throw InputError(fmt::format("{}: implicit step {} s; a step in (0, {}] s is accepted",
                                 kRegionWhat, s.implicit_step_s, kRegionMaxAdvanceS));
  if (!(s.interface_damping >= 0) || !std::isfinite(s.interface_damping))
    throw InputError(fmt::format("{}: interface damping κ = {}; a finite κ ≥ 0 is accepted",
                                 kRegionWhat, s.interface_damping));
  if (s.refactor_rank < 3 || s.refactor_rank > 3000)
    throw InputError(fmt::format("{}: refactor rank {}; 3 to 3000 DOFs are accepted", kRegionWhat,
                                 s.refactor_rank));
  if (!std::isfinite(s.damping_per_s))
    throw InputError(fmt::format(
        "{}: damping {} 1/s; a finite γ ≥ 0, or a negative value for the file's, is accepted",
        kRegionWhat, s.damping_per_s));
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
  // The element bound alone, before the coupling joins it (docs/model/hybrid-serving.md).
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
        kRegionWhat, model.id, n));
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
  update_explicit_bound();
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

void HybridRegion::add_rest_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const {
  if (u_m.size() != model_ref_.compliance_rows())
    throw InputError(fmt::format("{}: a field of {} values for {} compliance rows", kRegionWhat,
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
        "{}: a blade with a non-finite end; finite positions in metres are accepted", kRegionWhat));
  model_.tetrahedra_crossed_by_segment(blade_a_m, blade_b_m, removed_);
  for (int t : removed_) model_.remove_tetrahedron(t);
  return after_cut(static_cast<int>(removed_.size()));
}

int HybridRegion::cut(const Blade& before, const Blade& after) {
  if (!before.a_m.allFinite() || !before.b_m.allFinite() || !after.a_m.allFinite() ||
      !after.b_m.allFinite())
    throw InputError(fmt::format(
        "{}: a blade with a non-finite end; finite positions in metres are accepted", kRegionWhat));
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
  retime_explicit_step();
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
  Eigen::MatrixXd condensed = coupling_(keep, keep);
  // (Every Γ vertex released: nothing to condense onto, and Eigen's
  // triangular solve of an empty right-hand side reads through null.)
  if (!keep.empty()) condensed -= s_ad * s_dd.llt().solve(s_ad.transpose());
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
