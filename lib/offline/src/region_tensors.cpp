#include "palpate/offline/region_tensors.hpp"

#include <map>
#include <utility>

#include "palpate/core/error.hpp"

namespace palpate {

namespace {

// A 3 × 3 block as one row of 9 values, row-major (the file's layout,
// cut_region_data.hpp).
Eigen::Matrix<double, 1, 9> row_major(const Eigen::Matrix3d& block) {
  Eigen::Matrix<double, 1, 9> row;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) row[3 * i + j] = block(i, j);
  return row;
}

}  // namespace

TensorMassTensors tensor_mass_tensors(Eigen::Index vertex_count, CRef<Eigen::MatrixX4i> tetrahedra,
                                      const std::vector<Matrix12d>& element_stiffness) {
  PALPATE_DEMAND(static_cast<Eigen::Index>(element_stiffness.size()) == tetrahedra.rows());
  std::vector<Eigen::Matrix3d> vertex(static_cast<size_t>(vertex_count), Eigen::Matrix3d::Zero());
  // Ordered by (i, j): the file's edge order, and one entry per edge however
  // many tetrahedra share it.
  std::map<std::pair<int, int>, Eigen::Matrix3d> edge;
  for (Eigen::Index t = 0; t < tetrahedra.rows(); ++t) {
    const Matrix12d& K = element_stiffness[static_cast<size_t>(t)];
    for (int a = 0; a < 4; ++a) {
      const int i = tetrahedra(t, a);
      vertex[static_cast<size_t>(i)] += K.block<3, 3>(3 * a, 3 * a);
      for (int b = 0; b < 4; ++b) {
        const int j = tetrahedra(t, b);
        // Block (a, b) couples i to j; its transpose, block (b, a), is K_ji.
        if (i < j) {
          auto [it, inserted] = edge.try_emplace({i, j}, Eigen::Matrix3d::Zero());
          it->second += K.block<3, 3>(3 * a, 3 * b);
        }
      }
    }
  }
  TensorMassTensors out;
  out.vertex_n_per_m.resize(vertex_count, 9);
  for (Eigen::Index v = 0; v < vertex_count; ++v)
    out.vertex_n_per_m.row(v) = row_major(vertex[static_cast<size_t>(v)]);
  out.edges.resize(static_cast<Eigen::Index>(edge.size()), 2);
  out.edge_n_per_m.resize(static_cast<Eigen::Index>(edge.size()), 9);
  Eigen::Index e = 0;
  for (const auto& [ij, block] : edge) {
    out.edges(e, 0) = ij.first;
    out.edges(e, 1) = ij.second;
    out.edge_n_per_m.row(e) = row_major(block);
    ++e;
  }
  return out;
}

}  // namespace palpate
