#pragma once
/// @file
/// Linear elasticity on P1 tetrahedra: Lamé parameters, the element
/// stiffness, and the assembled global stiffness K (docs/model/elasticity.md, "Linear
/// elasticity on P1 tetrahedra", "Global stiffness and the attachment";
/// Cotin, Delingette & Ayache, IEEE TVCG 5(1), 1999).

#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate {

/// Lamé coefficients of an isotropic linear elastic material, in pascals.
struct Lame {
  double lambda_pa = 0;
  double mu_pa = 0;
};

/// λ = Eν / ((1+ν)(1−2ν)),  μ = E / (2(1+ν)).
/// @throws InputError unless E > 0 (finite) and −1 < ν < 0.5.
Lame lame_parameters(double young_modulus_pa, double poisson_ratio);

/// Signed volume of the tetrahedron whose rows are P0..P3 (m³): positive when
/// (P1−P0, P2−P0, P3−P0) is a right-handed frame.
double signed_volume(CRef<Matrix43d> vertices_m);

/// Stiffness of one P1 tetrahedron, 12 × 12 (N/m), in vertex-major order
/// (3j+a is axis a of vertex j). Block (j,k) is
///
///   K_jk = (λ M_j M_kᵀ + μ M_k M_jᵀ + μ (M_j·M_k) I₃) / (36 V),
///
/// with ∇λ_i = −M_i / (6V) the barycentric gradients, so that the elastic
/// force on vertex j is F_j = −Σ_k K_jk U_k. (The lecture prints the first two
/// terms with j and k swapped, i.e. the transposed block.)
/// @param vertices_m rows P0..P3 in metres; the volume must be positive.
Matrix12d element_stiffness(CRef<Matrix43d> vertices_m, const Lame& material);

/// Numbering of the free degrees of freedom of a mesh.
///
/// The surface (compliance) vertices come first, in increasing vertex index,
/// then the free interior vertices; vertex r of that order owns DOFs 3r..3r+2
/// (x, y, z). Fixed vertices own none.
struct DofMap {
  std::vector<int> first_dof;            ///< #V: 3·rank of the vertex, or −1 if fixed
  std::vector<int> compliance_vertices;  ///< free surface vertices, compliance order
  std::vector<int> interior_vertices;    ///< free interior vertices, DOF order
  int surface_dofs() const { return 3 * static_cast<int>(compliance_vertices.size()); }
  int dofs() const {
    return 3 * static_cast<int>(compliance_vertices.size() + interior_vertices.size());
  }
  /// The vertex that owns a DOF (inverse of first_dof).
  int vertex_of_dof(int dof) const;
};

/// Builds the DofMap for #V vertices given the boundary flag of each vertex
/// and the sorted list of fixed vertices.
DofMap make_dof_map(const std::vector<bool>& on_surface, const std::vector<int>& fixed_vertices);

/// Global stiffness on the free DOFs of a DofMap, upper triangle only
/// (CHOLMOD's symmetric storage), compressed column storage, N/m.
/// @param vertices_m #V × 3 rest positions, metres
/// @param tetrahedra #T × 4 vertex indices, positively oriented
/// @param material_of_tet #T indices into @p materials
SparseMatrixd assemble_stiffness(CRef<Eigen::MatrixX3d> vertices_m,
                                 CRef<Eigen::MatrixX4i> tetrahedra,
                                 CRef<Eigen::VectorXi> material_of_tet,
                                 const std::vector<Lame>& materials, const DofMap& dofs);

/// Full (both triangles) stiffness of the unconstrained mesh, 3#V × 3#V, in
/// vertex order (DOF 3v+a). For tests and analysis, not for the solvers.
SparseMatrixd assemble_full_stiffness(CRef<Eigen::MatrixX3d> vertices_m,
                                      CRef<Eigen::MatrixX4i> tetrahedra,
                                      CRef<Eigen::VectorXi> material_of_tet,
                                      const std::vector<Lame>& materials);

}  // namespace palpate
