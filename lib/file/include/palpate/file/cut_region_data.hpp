#pragma once
/// @file
/// The cuttable region of the hybrid model as the compliance file stores it
/// (the group /cut_region, format 1.3; docs/compliance-file.md): what the run
/// time's tensor-mass model needs, in plain arrays, so that the file layer
/// knows nothing of how precompute chose or computed it (docs/model/hybrid-region.md, "The
/// hybrid model: a cuttable region and the precomputed rest").

#include <string>

#include "palpate/core/eigen.hpp"

namespace palpate {

/// A 3 × 3 stiffness tensor stored as one row of 9 values, row-major: entry
/// (i, j) at column 3i + j.
inline constexpr int kTensorValues = 9;
/// A 12 × 12 element stiffness stored as one row of 144 values, row-major:
/// entry (3a + i, 3b + j) (vertex a, b of the tetrahedron; axis i, j) at
/// column 12 (3a + i) + 3b + j.
inline constexpr int kElementStiffnessValues = 144;

/// The region's own tetrahedra and the data the tensor-mass model steps
/// with. Vertex indices are the region's own numbering (0..#R−1) unless said
/// otherwise. The region's stiffness K_R (the sum of its element
/// stiffnesses, all vertices free) is stored three ways: per element, and
/// as the tensor-mass model keeps it (S. Cotin, H. Delingette & N. Ayache,
/// "A hybrid elastic model…", The Visual Computer 16(8), 2000, §4): a 3 × 3
/// tensor per vertex, K_ii = Σ over the region's tetrahedra holding i of
/// their (i, i) block, and one per edge i < j, K_ij = Σ over those holding
/// both of their (i, j) block (K_ji = K_ijᵀ), so that the elastic force on
/// vertex i is −(K_ii u_i + Σ_j K_ij u_j).
struct CutRegionData {
  Eigen::MatrixX3d vertices_m;        ///< #R × 3 rest positions, metres
  Eigen::VectorXi source_vertex_ids;  ///< #R node index in the input mesh file
  Eigen::MatrixX4i tetrahedra;        ///< #T_R × 4, region numbering, positively oriented
  Eigen::VectorXi tet_material;       ///< #T_R index into the file's /material
  /// #T_R × 144, N/m: each tetrahedron's 12 × 12 stiffness (kElementStiffnessValues).
  Eigen::MatrixXd element_stiffness_n_per_m;
  Eigen::MatrixXd vertex_stiffness_n_per_m;  ///< #R × 9, N/m: K_ii (kTensorValues)
  Eigen::MatrixX2i edges;                    ///< #E × 2, (i, j) with i < j, sorted
  Eigen::MatrixXd edge_stiffness_n_per_m;    ///< #E × 9, N/m: K_ij (kTensorValues)
  /// #F × 3, faces of exactly one region tetrahedron, outward from the
  /// region: its part of the organ's surface and its faces on Γ.
  Eigen::MatrixX3i boundary_triangles;
  /// n_Γ, the free interface vertices Γ (region numbering), in the order of
  /// interface_compliance_index.
  Eigen::VectorXi interface_vertices;
  /// n_Γ, where each Γ vertex is in /compliance/vertex_ids: G's rows
  /// 3k..3k+2 for interface_compliance_index[i] = k, so that G_ΓΓ and G_SΓ
  /// are blocks of the file's G. Increasing.
  Eigen::VectorXi interface_compliance_index;
  Eigen::VectorXi fixed_vertices;  ///< region vertices the attachment holds, increasing
  double density_kg_m3 = 0;        ///< for the lumped masses
  double damping_per_s = 0;        ///< γ of the mass-proportional damping force −γ m v
  std::string spec;                ///< how the job chose the region, as text
};

/// Checks @p region against itself and the file it is in: shapes, index
/// ranges (@p compliance_vertices Γ's indices point into), finite values,
/// positively oriented tetrahedra, density > 0, damping ≥ 0, a symmetric K_ii.
/// @param where names the file, for messages
/// @throws InputError naming the dataset, the entry and what is accepted.
void check_cut_region(const CutRegionData& region, Eigen::Index compliance_vertices,
                      Eigen::Index materials, const std::string& where);

}  // namespace palpate
