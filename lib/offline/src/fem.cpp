#include "palpate/offline/fem.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <cmath>

#include "palpate/core/error.hpp"

namespace palpate {

Lame lame_parameters(double young_modulus_pa, double poisson_ratio) {
  if (!(young_modulus_pa > 0) || !std::isfinite(young_modulus_pa))
    throw InputError(
        fmt::format("Young's modulus {} Pa is not accepted: it must be a finite number > 0 Pa "
                    "(liver: about 1e4 to 1.7e5 Pa)",
                    young_modulus_pa));
  if (!(poisson_ratio > -1.0 && poisson_ratio < 0.5))
    throw InputError(
        fmt::format("Poisson ratio {} is not accepted: it must lie in the open interval (-1, 0.5) "
                    "(soft tissue: 0.45 to 0.49)",
                    poisson_ratio));
  const double E = young_modulus_pa;
  const double nu = poisson_ratio;
  // λ = Eν / ((1+ν)(1−2ν)),  μ = E / (2(1+ν))
  return {E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))};
}

double signed_volume(CRef<Matrix43d> P) {
  const Eigen::Vector3d e1 = (P.row(1) - P.row(0)).transpose();
  const Eigen::Vector3d e2 = (P.row(2) - P.row(0)).transpose();
  const Eigen::Vector3d e3 = (P.row(3) - P.row(0)).transpose();
  return e1.dot(e2.cross(e3)) / 6.0;
}

Matrix12d element_stiffness(CRef<Matrix43d> P, const Lame& material) {
  const double V = signed_volume(P);
  PALPATE_DEMAND(V > 0);
  // M_i: area-weighted normal of the face opposite vertex i, with the sign
  // that makes ∇λ_i = −M_i / (6V). The gradients are the rows of the inverse
  // of the edge matrix; ∇λ_0 = −(∇λ_1 + ∇λ_2 + ∇λ_3).
  Eigen::Matrix3d D;
  D << (P.row(1) - P.row(0)), (P.row(2) - P.row(0)), (P.row(3) - P.row(0));
  // x − P0 = Dᵀ (λ1, λ2, λ3), so ∇λ_i is row i−1 of D⁻ᵀ.
  const Eigen::Matrix3d grad123 = D.transpose().inverse();
  Matrix43d M;
  M.row(1) = grad123.row(0);
  M.row(2) = grad123.row(1);
  M.row(3) = grad123.row(2);
  M.row(0) = -(M.row(1) + M.row(2) + M.row(3));
  M *= -6.0 * V;

  const double inv36V = 1.0 / (36.0 * V);
  Matrix12d K;
  for (int j = 0; j < 4; ++j) {
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d Mj = M.row(j).transpose();
      const Eigen::Vector3d Mk = M.row(k).transpose();
      // K_jk = (λ M_j M_kᵀ + μ M_k M_jᵀ + μ (M_j·M_k) I₃) / (36 V)
      K.block<3, 3>(3 * j, 3 * k) =
          (material.lambda_pa * Mj * Mk.transpose() + material.mu_pa * Mk * Mj.transpose() +
           material.mu_pa * Mj.dot(Mk) * Eigen::Matrix3d::Identity()) *
          inv36V;
    }
  }
  return K;
}

int DofMap::vertex_of_dof(int dof) const {
  const int rank = dof / 3;
  const int ns = static_cast<int>(compliance_vertices.size());
  return rank < ns ? compliance_vertices[rank] : interior_vertices[rank - ns];
}

DofMap make_dof_map(const std::vector<bool>& on_surface, const std::vector<int>& fixed_vertices) {
  const int nv = static_cast<int>(on_surface.size());
  std::vector<bool> fixed(nv, false);
  for (int v : fixed_vertices) {
    PALPATE_DEMAND(v >= 0 && v < nv);
    fixed[v] = true;
  }
  DofMap map;
  map.first_dof.assign(nv, -1);
  for (int v = 0; v < nv; ++v) {
    if (fixed[v]) continue;
    (on_surface[v] ? map.compliance_vertices : map.interior_vertices).push_back(v);
  }
  int rank = 0;
  for (int v : map.compliance_vertices) map.first_dof[v] = 3 * rank++;
  for (int v : map.interior_vertices) map.first_dof[v] = 3 * rank++;
  return map;
}

namespace {

// Sums the element blocks into triplets; `dof_of` maps a vertex to its first
// DOF (−1: fixed, dropped). With `upper_only`, keeps entries with row ≤ col.
template <typename DofOf>
SparseMatrixd assemble(CRef<Eigen::MatrixX3d> X, CRef<Eigen::MatrixX4i> T,
                       CRef<Eigen::VectorXi> material_of_tet, const std::vector<Lame>& materials,
                       int n, DofOf dof_of, bool upper_only) {
  std::vector<Eigen::Triplet<double, int>> triplets;
  triplets.reserve(static_cast<size_t>(T.rows()) * (upper_only ? 78 : 144));
  Matrix43d P;
  for (Eigen::Index t = 0; t < T.rows(); ++t) {
    for (int i = 0; i < 4; ++i) P.row(i) = X.row(T(t, i));
    const Matrix12d Ke = element_stiffness(P, materials[material_of_tet[t]]);
    for (int j = 0; j < 4; ++j) {
      const int dj = dof_of(T(t, j));
      if (dj < 0) continue;
      for (int k = 0; k < 4; ++k) {
        const int dk = dof_of(T(t, k));
        if (dk < 0) continue;
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b)
            if (!upper_only || dj + a <= dk + b)
              triplets.emplace_back(dj + a, dk + b, Ke(3 * j + a, 3 * k + b));
      }
    }
  }
  SparseMatrixd K(n, n);
  K.setFromTriplets(triplets.begin(), triplets.end());
  K.makeCompressed();
  return K;
}

}  // namespace

SparseMatrixd assemble_stiffness(CRef<Eigen::MatrixX3d> vertices_m,
                                 CRef<Eigen::MatrixX4i> tetrahedra,
                                 CRef<Eigen::VectorXi> material_of_tet,
                                 const std::vector<Lame>& materials, const DofMap& dofs) {
  return assemble(
      vertices_m, tetrahedra, material_of_tet, materials, dofs.dofs(),
      [&](int v) { return dofs.first_dof[v]; }, true);
}

SparseMatrixd assemble_full_stiffness(CRef<Eigen::MatrixX3d> vertices_m,
                                      CRef<Eigen::MatrixX4i> tetrahedra,
                                      CRef<Eigen::VectorXi> material_of_tet,
                                      const std::vector<Lame>& materials) {
  return assemble(
      vertices_m, tetrahedra, material_of_tet, materials, 3 * static_cast<int>(vertices_m.rows()),
      [](int v) { return 3 * v; }, false);
}

}  // namespace palpate
