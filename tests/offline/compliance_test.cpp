// The surface compliance: both methods against a dense reference and each
// other, on a box and on a liver-sized organ; symmetry and SPD blocks.

#include "palpate/offline/compliance.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

struct Problem {
  SparseMatrixd K;
  int m = 0;
};

// Box clamped on its x = 0 face.
Problem clamped_box(int nx, int ny, int nz, double nu) {
  const TetMesh mesh = testing::box_mesh(0.1, 0.06, 0.05, nx, ny, nz);
  const Boundary b = extract_boundary(mesh);
  std::vector<int> fixed;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    if (mesh.vertices(v, 0) == 0) fixed.push_back(static_cast<int>(v));
  const DofMap dofs = make_dof_map(b.on_surface, fixed);
  return {assemble_stiffness(mesh.vertices, mesh.tetrahedra,
                             Eigen::VectorXi::Zero(mesh.tetrahedra.rows()),
                             {lame_parameters(85e3, nu)}, dofs),
          dofs.surface_dofs()};
}

TEST(Compliance, BothMethodsEqualTheDenseInverseOfK) {
  const Problem p = clamped_box(4, 3, 3, 0.45);
  ASSERT_LT(p.m, p.K.rows());  // there are interior DOFs to condense
  const Eigen::MatrixXd Kd = Eigen::MatrixXd(SparseMatrixd(p.K.selfadjointView<Eigen::Upper>()));
  const Eigen::MatrixXd ref = Kd.inverse().topLeftCorner(p.m, p.m);
  // Explicit Schur complement on the dense matrix, the textbook way.
  const int n = static_cast<int>(Kd.rows()), m = p.m;
  const Eigen::MatrixXd S =
      Kd.topLeftCorner(m, m) -
      Kd.topRightCorner(m, n - m) *
          Kd.bottomRightCorner(n - m, n - m).llt().solve(Kd.bottomLeftCorner(n - m, m));
  ComplianceOptions options;
  options.block_columns = 50;  // several blocks, the last one partial
  ComplianceStats solves_stats, cond_stats;
  const Eigen::MatrixXd G1 = compliance_by_solves(p.K, m, options, &solves_stats);
  const Eigen::MatrixXd G2 = compliance_by_condensation(p.K, m, options, &cond_stats);
  // κ(K) ≈ 1e4 here: dense and sparse factorizations agree to ~1e-12.
  EXPECT_LE(max_relative_difference(ref, G1), 1e-10);
  EXPECT_LE(max_relative_difference(ref, G2), 1e-10);
  EXPECT_LE(max_relative_difference(S.inverse(), G2), 1e-10);
  EXPECT_LE(max_relative_difference(G1, G2), 1e-10);
  EXPECT_LE(solves_stats.max_residual, 1e-10);
  EXPECT_LE(cond_stats.max_residual, 1e-10);
  EXPECT_LE(cond_stats.max_column_mismatch, 1e-10);
  EXPECT_GE(solves_stats.checked_columns.size(), 2u);
}

TEST(Compliance, IsSymmetricWithPositiveDefiniteDiagonalBlocks) {
  const Problem p = clamped_box(5, 3, 3, 0.49);  // nearly incompressible
  const Eigen::MatrixXd G = compliance_by_solves(p.K, p.m, {}, nullptr);
  EXPECT_LE(symmetry_error(G), 1e-10);
  int worst = -1;
  EXPECT_GT(min_diagonal_block_eigenvalue(G, &worst), 0);
  EXPECT_GE(worst, 0);
  // Whole G is SPD too: its Cholesky succeeds.
  EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(0.5 * (G + G.transpose())).info(), Eigen::Success);
}

TEST(Compliance, MethodsAgreeOnALiverSizedOrgan) {
  testing::TempDir dir;
  write_sample_organ(dir / "organ.msh", 0.008);  // ~1,900 vertices: the 1999 liver's scale
  TetMesh mesh = read_mesh(dir / "organ.msh", {});
  validate_and_compact(mesh);
  ASSERT_GT(mesh.vertices.rows(), 1200);
  const Boundary b = extract_boundary(mesh);
  std::vector<int> fixed;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    if ((mesh.vertices.row(v) - Eigen::RowVector3d(-0.03, 0, 0.04)).norm() < 0.025)
      fixed.push_back(static_cast<int>(v));
  Eigen::VectorXi material = (mesh.tet_group.array() == 2).cast<int>();
  const DofMap dofs = make_dof_map(b.on_surface, fixed);
  const SparseMatrixd K =
      assemble_stiffness(mesh.vertices, mesh.tetrahedra, material,
                         {lame_parameters(85e3, 0.45), lame_parameters(340e3, 0.45)}, dofs);
  const int m = dofs.surface_dofs();
  const Eigen::MatrixXd G1 = compliance_by_solves(K, m, {}, nullptr);
  const Eigen::MatrixXd G2 = compliance_by_condensation(K, m, {}, nullptr);
  EXPECT_LE(max_relative_difference(G1, G2), 1e-8);  // the product's acceptance threshold
  EXPECT_LE(symmetry_error(G1), 1e-10);
  EXPECT_GT(min_diagonal_block_eigenvalue(G1), 0);
}

TEST(Compliance, ReportsTheColumnWhereKIsNotPositiveDefinite) {
  // No fixed vertex: K is singular (six rigid modes).
  const TetMesh mesh = testing::box_mesh(0.1, 0.1, 0.1, 2, 2, 2);
  const Boundary b = extract_boundary(mesh);
  const DofMap dofs = make_dof_map(b.on_surface, {});
  const SparseMatrixd K = assemble_stiffness(mesh.vertices, mesh.tetrahedra,
                                             Eigen::VectorXi::Zero(mesh.tetrahedra.rows()),
                                             {lame_parameters(1e5, 0.3)}, dofs);
  try {
    compliance_by_solves(K, dofs.surface_dofs(), {}, nullptr);
    ADD_FAILURE() << "no NotPositiveDefinite";
  } catch (const NotPositiveDefinite& e) {
    EXPECT_GE(e.column(), 0);
    EXPECT_LT(e.column(), K.rows());
  }
}

}  // namespace
}  // namespace palpate
