#pragma once
/// @file
/// The stiffness of a tetrahedral region as a tensor-mass model keeps it: a
/// 3 × 3 tensor per vertex and one per edge, sums of the element blocks
/// (S. Cotin, H. Delingette & N. Ayache, "A hybrid elastic model for
/// real-time cutting, deformations and force feedback for surgery training
/// and simulation", The Visual Computer 16(8), 2000, §4): what
/// palpate-precompute writes into the compliance file's /cut_region. The
/// run-time model (runtime/tensor_mass) builds the same sums from the
/// element blocks, and re-sums the tensors a cut touches from the
/// tetrahedra that remain.

#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate {

/// K = Σ_e K_e over a region's tetrahedra (all vertices free), as tensors.
struct TensorMassTensors {
  /// #V × 9, N/m: K_ii = Σ over the tetrahedra holding i of K_e(i, i),
  /// row-major 3 × 3.
  Eigen::MatrixXd vertex_n_per_m;
  Eigen::MatrixX2i edges;  ///< #E × 2, (i, j) with i < j, sorted: the edges of the tetrahedra
  /// #E × 9, N/m: K_ij = Σ over the tetrahedra holding i and j of K_e(i, j),
  /// row-major 3 × 3 (K_ji = K_ijᵀ).
  Eigen::MatrixXd edge_n_per_m;
};

/// The tensors of K = Σ_e K_e: then the elastic force on vertex i under
/// displacements u is −(K_ii u_i + Σ_j K_ij u_j), j over i's edges.
/// @param vertex_count #V
/// @param tetrahedra #T × 4 indices into 0..#V−1
/// @param element_stiffness #T 12 × 12 element stiffnesses (fem.hpp), N/m,
///   in the vertex order of @p tetrahedra
TensorMassTensors tensor_mass_tensors(Eigen::Index vertex_count, CRef<Eigen::MatrixX4i> tetrahedra,
                                      const std::vector<Matrix12d>& element_stiffness);

}  // namespace palpate
