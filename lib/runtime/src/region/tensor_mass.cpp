#include "palpate/runtime/tensor_mass.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"
#include "palpate/runtime/region/tet_grid.hpp"

namespace palpate {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr const char* kTensorMassWhat = "tensor-mass region";

Vector3d row(const Eigen::MatrixX3d& m, int r) { return m.row(r).transpose(); }

double tet_volume(const Eigen::MatrixX3d& x, const Eigen::MatrixX4i& t, int tet) {
  const Vector3d p0 = row(x, t(tet, 0));
  return (row(x, t(tet, 1)) - p0).dot((row(x, t(tet, 2)) - p0).cross(row(x, t(tet, 3)) - p0)) / 6.0;
}

}  // namespace

TensorMassModel::TensorMassModel(CRef<Eigen::MatrixX3d> rest_positions_m,
                                 CRef<Eigen::MatrixX4i> tetrahedra,
                                 const std::vector<Matrix12d>& element_stiffness_n_per_m,
                                 const TensorMassMaterial& material,
                                 const std::vector<int>& fixed_vertices)
    : rest_m_(rest_positions_m), tets_(tetrahedra), element_k_(element_stiffness_n_per_m) {
  const int nv = static_cast<int>(rest_m_.rows());
  const int nt = static_cast<int>(tets_.rows());
  if (!(material.density_kg_m3 > 0) || !std::isfinite(material.density_kg_m3))
    throw InputError(
        fmt::format("{}: density {} kg/m³; a finite density > 0 is accepted "
                    "(soft tissue: about 1060 kg/m³)",
                    kTensorMassWhat, material.density_kg_m3));
  if (!(material.mass_damping_per_s >= 0) || !std::isfinite(material.mass_damping_per_s))
    throw InputError(fmt::format("{}: mass damping γ = {} 1/s; a finite γ ≥ 0 is accepted",
                                 kTensorMassWhat, material.mass_damping_per_s));
  density_kg_m3_ = material.density_kg_m3;
  damping_per_s_ = material.mass_damping_per_s;
  for (int v = 0; v < nv; ++v)
    if (!rest_m_.row(v).allFinite())
      throw InputError(
          fmt::format("{}: vertex {} has a non-finite rest position ({}, {}, {}) m; "
                      "finite coordinates in metres are accepted",
                      kTensorMassWhat, v, rest_m_(v, 0), rest_m_(v, 1), rest_m_(v, 2)));
  if (static_cast<int>(element_k_.size()) != nt)
    throw InputError(
        fmt::format("{}: {} element stiffnesses for {} tetrahedra; one 12 × 12 "
                    "matrix per tetrahedron is accepted",
                    kTensorMassWhat, element_k_.size(), nt));
  tet_volume_m3_.resize(nt);
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k)
      if (tets_(t, k) < 0 || tets_(t, k) >= nv)
        throw InputError(
            fmt::format("{}: tetrahedron {} has vertex index {}; indices 0..{} "
                        "(the rows of the rest positions) are accepted",
                        kTensorMassWhat, t, tets_(t, k), nv - 1));
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        if (tets_(t, a) == tets_(t, b))
          throw InputError(
              fmt::format("{}: tetrahedron {} uses vertex {} twice; four distinct "
                          "vertices are accepted",
                          kTensorMassWhat, t, tets_(t, a)));
    tet_volume_m3_[t] = tet_volume(rest_m_, tets_, t);
    if (!(tet_volume_m3_[t] > 0))
      throw InputError(
          fmt::format("{}: tetrahedron {} (vertices {}, {}, {}, {}) has volume {} m³; "
                      "positively oriented tetrahedra (volume > 0) are accepted",
                      kTensorMassWhat, t, tets_(t, 0), tets_(t, 1), tets_(t, 2), tets_(t, 3),
                      tet_volume_m3_[t]));
    const Matrix12d& k = element_k_[t];
    if (!k.allFinite())
      throw InputError(
          fmt::format("{}: the element stiffness of tetrahedron {} has a non-finite "
                      "entry; finite values in N/m are accepted",
                      kTensorMassWhat, t));
    // Round-off of the element formula is ~10⁻¹⁶ of its largest entry.
    const double asymmetry = (k - k.transpose()).cwiseAbs().maxCoeff();
    if (asymmetry > 1e-10 * k.cwiseAbs().maxCoeff())
      throw InputError(fmt::format(
          "{}: the element stiffness of tetrahedron {} is not symmetric "
          "(|K − Kᵀ| up to {:.3g} of its largest entry {:.3g} N/m); "
          "symmetric to 1e-10 relative is accepted",
          kTensorMassWhat, t, asymmetry / k.cwiseAbs().maxCoeff(), k.cwiseAbs().maxCoeff()));
  }
  // Each element's highest ω² with its own lumped masses, M_t = (ρ V_t / 4) I:
  // uᵀ K u = Σ_t u_tᵀ K^t u_t ≤ max_t ω_t² Σ_t u_tᵀ M_t u_t = max_t ω_t² uᵀ M u,
  // for the mesh as built and for whatever tetrahedra a cut leaves.
  for (int t = 0; t < nt; ++t)
    element_omega2_max_ =
        std::max(element_omega2_max_,
                 Eigen::SelfAdjointEigenSolver<Matrix12d>(element_k_[t], Eigen::EigenvaluesOnly)
                         .eigenvalues()
                         .maxCoeff() /
                     (density_kg_m3_ * tet_volume_m3_[t] / 4));
  fixed_.assign(nv, 0);
  for (int v : fixed_vertices) {
    if (v < 0 || v >= nv)
      throw InputError(fmt::format("{}: fixed vertex {} does not exist; indices 0..{} are accepted",
                                   kTensorMassWhat, v, nv - 1));
    if (fixed_[v] != 0)
      throw InputError(
          fmt::format("{}: fixed vertex {} is listed twice; distinct vertices are "
                      "accepted",
                      kTensorMassWhat, v));
    fixed_[v] = 1;
  }

  build_topology();
  grid_ = std::make_shared<const detail::TetGrid>(rest_m_, tets_);
  tet_stamp_.assign(static_cast<std::size_t>(nt), 0U);

  u_ = Eigen::VectorXd::Zero(3 * nv);
  u_previous_ = u_;
  force_ = u_;
}

// (K u)_i = K_ii u_i + Σ_j K_ij u_j: one pass over the vertices, one over the
// edges, each edge giving K_ij u_j to i and K_ijᵀ u_i to j.
void TensorMassModel::add_stiffness_product(CRef<Eigen::VectorXd> u,
                                            Eigen::Ref<Eigen::VectorXd> out, double sign) const {
  PALPATE_DEMAND(u.size() == 3 * vertex_count() && out.size() == 3 * vertex_count());
  const double* x = u.data();
  double* y = out.data();
  const int nv = vertex_count();
  for (int v = 0; v < nv; ++v)
    Eigen::Map<Vector3d>(y + 3 * v) +=
        sign * (vertex_tensor_[v] * Eigen::Map<const Vector3d>(x + 3 * v));
  for (const LiveEdge& e : live_edges_) {
    Eigen::Map<Vector3d>(y + 3 * e.i) += sign * (e.k_ij * Eigen::Map<const Vector3d>(x + 3 * e.j));
    Eigen::Map<Vector3d>(y + 3 * e.j) +=
        sign * (e.k_ij.transpose() * Eigen::Map<const Vector3d>(x + 3 * e.i));
  }
}

void TensorMassModel::apply_stiffness(CRef<Eigen::VectorXd> u_m,
                                      Eigen::Ref<Eigen::VectorXd> ku_n) const {
  ku_n.setZero();
  add_stiffness_product(u_m, ku_n, 1.0);
}

void TensorMassModel::internal_force(CRef<Eigen::VectorXd> u_m,
                                     Eigen::Ref<Eigen::VectorXd> f_n) const {
  f_n.setZero();
  add_stiffness_product(u_m, f_n, -1.0);
}

void TensorMassModel::set_interface_coupling(const std::vector<int>& interface_vertices,
                                             CRef<Eigen::MatrixXd> stiffness_n_per_m) {
  const int nv = vertex_count();
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(interface_vertices.size());
  std::vector<char> seen(nv, 0);
  for (int v : interface_vertices) {
    if (v < 0 || v >= nv)
      throw InputError(
          fmt::format("{}: interface vertex {} does not exist; indices 0..{} are "
                      "accepted",
                      kTensorMassWhat, v, nv - 1));
    if (seen[v] != 0)
      throw InputError(
          fmt::format("{}: interface vertex {} is listed twice; distinct vertices are "
                      "accepted",
                      kTensorMassWhat, v));
    if (fixed_[v] != 0)
      throw InputError(
          fmt::format("{}: interface vertex {} is fixed; an interface vertex must be "
                      "free (the rest of the organ holds it through S)",
                      kTensorMassWhat, v));
    seen[v] = 1;
  }
  if (stiffness_n_per_m.rows() != n || stiffness_n_per_m.cols() != n)
    throw InputError(
        fmt::format("{}: the interface stiffness S is {} × {} for {} interface "
                    "vertices; 3n × 3n = {} × {} is accepted",
                    kTensorMassWhat, stiffness_n_per_m.rows(), stiffness_n_per_m.cols(),
                    interface_vertices.size(), n, n));
  if (!stiffness_n_per_m.allFinite())
    throw InputError(
        fmt::format("{}: the interface stiffness S has a non-finite entry; finite "
                    "values in N/m are accepted",
                    kTensorMassWhat));
  double largest_eigenvalue = 0;
  if (n > 0) {
    const double largest = stiffness_n_per_m.cwiseAbs().maxCoeff();
    const double asymmetry =
        (stiffness_n_per_m - stiffness_n_per_m.transpose()).cwiseAbs().maxCoeff();
    if (asymmetry > 1e-10 * largest)
      throw InputError(
          fmt::format("{}: the interface stiffness S is not symmetric (|S − Sᵀ| up to "
                      "{:.3g} of its largest entry); symmetric to 1e-10 relative is "
                      "accepted",
                      kTensorMassWhat, asymmetry / largest));
    // An indefinite S would feed energy in: the explicit step would diverge
    // whatever Δt. The tolerance is the eigensolver's round-off.
    const Eigen::VectorXd eigenvalues =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(stiffness_n_per_m, Eigen::EigenvaluesOnly)
            .eigenvalues();
    const double least = eigenvalues.minCoeff();
    largest_eigenvalue = eigenvalues.maxCoeff();
    if (least < -1e-10 * largest * static_cast<double>(n))
      throw InputError(
          fmt::format("{}: the interface stiffness S has the eigenvalue {:.6g} N/m; "
                      "a positive semi-definite S is accepted",
                      kTensorMassWhat, least));
  }
  interface_ = interface_vertices;
  coupling_ = stiffness_n_per_m;
  coupling_eigen_max_ = largest_eigenvalue;
  offset_m_ = Eigen::VectorXd::Zero(n);
  gap_m_ = offset_m_;
  coupling_force_n_ = offset_m_;
}

void TensorMassModel::set_interface_offset(CRef<Eigen::VectorXd> offset_m) {
  PALPATE_DEMAND(offset_m.size() == offset_m_.size());
  offset_m_ = offset_m;
}

void TensorMassModel::add_coupling_force(CRef<Eigen::VectorXd> u_m,
                                         Eigen::Ref<Eigen::VectorXd> f_n) {
  if (interface_.empty()) return;
  const int n = static_cast<int>(interface_.size());
  for (int k = 0; k < n; ++k) gap_m_.segment<3>(3 * k) = u_m.segment<3>(3 * interface_[k]);
  gap_m_ -= offset_m_;
  coupling_force_n_.noalias() = coupling_ * gap_m_;
  for (int k = 0; k < n; ++k)
    f_n.segment<3>(3 * interface_[k]) -= coupling_force_n_.segment<3>(3 * k);
}

void TensorMassModel::step(double time_step_s, CRef<Eigen::VectorXd> external_force_n) {
  PALPATE_DEMAND(time_step_s > 0 && external_force_n.size() == u_.size());
  force_ = external_force_n;
  add_stiffness_product(u_, force_, -1.0);
  add_coupling_force(u_, force_);
  // m (u⁺ − 2u + u⁻)/Δt² + γ m (u⁺ − u⁻)/(2Δt) = f, solved for u⁺ per vertex.
  const double c0 = 1 / (time_step_s * time_step_s), c1 = damping_per_s_ / (2 * time_step_s);
  const double inv = 1 / (c0 + c1);
  const int nv = vertex_count();
  for (int v = 0; v < nv; ++v) {
    auto u = u_.segment<3>(3 * v);
    auto u_prev = u_previous_.segment<3>(3 * v);
    if (fixed_[v] != 0 || vertex_tet_count_[v] == 0) {
      u_prev = u;  // held: fixed at zero, detached where the cut left it
      continue;
    }
    const Vector3d next =
        inv * (force_.segment<3>(3 * v) / mass_kg_[v] + 2 * c0 * u - (c0 - c1) * u_prev);
    u_prev = u;
    u = next;
  }
}

void TensorMassModel::set_state(CRef<Eigen::VectorXd> u_m, CRef<Eigen::VectorXd> u_previous_m) {
  if (u_m.size() != u_.size() || u_previous_m.size() != u_.size())
    throw InputError(fmt::format("{}: a state of sizes {} and {}; 3 × {} vertices = {} is accepted",
                                 kTensorMassWhat, u_m.size(), u_previous_m.size(), vertex_count(),
                                 u_.size()));
  u_ = u_m;
  u_previous_ = u_previous_m;
  for (int v = 0; v < vertex_count(); ++v)
    if (fixed_[v] != 0) {
      u_.segment<3>(3 * v).setZero();
      u_previous_.segment<3>(3 * v).setZero();
    }
}

StableTimeStep TensorMassModel::stable_time_step(double tolerance, int max_iterations) const {
  const int nv = vertex_count();
  // M^-1/2 on the moving DOFs, zero elsewhere: the operator
  // A = M^-1/2 (K + S) M^-1/2 restricted to them is symmetric, with the
  // eigenvalues ω² of M⁻¹ (K + S).
  Eigen::VectorXd scale = Eigen::VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v)
    if (fixed_[v] == 0 && vertex_tet_count_[v] > 0)
      scale.segment<3>(3 * v).setConstant(1 / std::sqrt(mass_kg_[v]));
  const auto apply = [&](const Eigen::VectorXd& y, Eigen::VectorXd& z) {
    const Eigen::VectorXd w = scale.cwiseProduct(y);
    apply_stiffness(w, z);
    if (!interface_.empty()) {
      Eigen::VectorXd g(3 * interface_.size());
      for (std::size_t k = 0; k < interface_.size(); ++k)
        g.segment<3>(3 * k) = w.segment<3>(3 * interface_[k]);
      const Eigen::VectorXd sg = coupling_ * g;
      for (std::size_t k = 0; k < interface_.size(); ++k)
        z.segment<3>(3 * interface_[k]) += sg.segment<3>(3 * k);
    }
    z = scale.cwiseProduct(z);
  };

  StableTimeStep out;
  // A fixed start with no symmetry of the mesh (so not orthogonal to the
  // top mode in practice): a linear congruential sequence in (0.5, 1.5).
  Eigen::VectorXd y(3 * nv), z(3 * nv);
  std::uint64_t state = 0x9e3779b97f4a7c15ULL;
  for (Eigen::Index i = 0; i < y.size(); ++i) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    y[i] = (scale[i] != 0) ? 0.5 + static_cast<double>(state >> 11) * 0x1.0p-53 : 0.0;
  }
  if (y.norm() == 0) {  // nothing moves (every tetrahedron cut, say): any step is stable
    const double inf = std::numeric_limits<double>::infinity();
    out.critical_time_step_s = out.gershgorin_time_step_s = out.element_time_step_s = inf;
    out.iterations = 0;
    out.converged = true;
    return out;
  }
  y.normalize();
  double rho = 0;
  for (out.iterations = 1; out.iterations <= max_iterations; ++out.iterations) {
    apply(y, z);
    rho = y.dot(z);  // Rayleigh quotient, ‖y‖ = 1
    out.relative_residual = rho > 0 ? (z - rho * y).norm() / rho : 0;
    if (rho <= 0 || out.relative_residual <= tolerance) {
      out.converged = true;
      break;
    }
    y = z / z.norm();
  }
  out.iterations = std::min(out.iterations, max_iterations);
  out.omega_max_rad_s = std::sqrt(std::max(rho, 0.0));

  // Gershgorin on M⁻¹ (K + S), moving rows and columns only.
  Eigen::VectorXd row_sum = Eigen::VectorXd::Zero(3 * nv);
  const auto moving = [&](int v) { return scale[3 * v] != 0; };
  for (int v = 0; v < nv; ++v)
    if (moving(v)) row_sum.segment<3>(3 * v) += vertex_tensor_[v].cwiseAbs().rowwise().sum();
  for (const LiveEdge& e : live_edges_) {
    if (moving(e.i) && moving(e.j)) {
      row_sum.segment<3>(3 * e.i) += e.k_ij.cwiseAbs().rowwise().sum();
      row_sum.segment<3>(3 * e.j) += e.k_ij.cwiseAbs().colwise().sum().transpose();
    }
  }
  for (std::size_t a = 0; a < interface_.size(); ++a)
    for (std::size_t b = 0; b < interface_.size(); ++b)
      if (moving(interface_[a]) && moving(interface_[b]))
        row_sum.segment<3>(3 * interface_[a]) +=
            coupling_.block<3, 3>(3 * a, 3 * b).cwiseAbs().rowwise().sum();
  double bound = 0;
  for (int v = 0; v < nv; ++v)
    if (moving(v)) bound = std::max(bound, row_sum.segment<3>(3 * v).maxCoeff() / mass_kg_[v]);
  out.gershgorin_omega_rad_s = std::sqrt(bound);

  const double inf = std::numeric_limits<double>::infinity();
  out.critical_time_step_s = out.omega_max_rad_s > 0 ? 2 / out.omega_max_rad_s : inf;
  out.gershgorin_time_step_s = bound > 0 ? 2 / out.gershgorin_omega_rad_s : inf;

  // uᵀ S u ≤ λ_max(S) |u_Γ|² ≤ λ_max(S) / min_Γ m · uᵀ M u.
  double least_interface_mass_kg = inf;
  for (int v : interface_)
    if (moving(v)) least_interface_mass_kg = std::min(least_interface_mass_kg, mass_kg_[v]);
  const double element_bound =
      element_omega2_max_ +
      (least_interface_mass_kg < inf ? coupling_eigen_max_ / least_interface_mass_kg : 0.0);
  out.element_omega_rad_s = std::sqrt(element_bound);
  out.element_time_step_s = element_bound > 0 ? 2 / out.element_omega_rad_s : inf;
  return out;
}

}  // namespace palpate
