#pragma once
// What the tensor-mass tests share: a 4 cm cube of 4 × 4 × 4 Kuhn cells
// (optionally jittered), its element blocks and assembled K from the offline
// layer, a region model owning its mesh, and dense modal helpers; the
// 7 × 7 × 7 box of the cutting tests and their random directions.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include "palpate/offline/fem.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "support/test_meshes.hpp"

namespace palpate::tensor_mass_test {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

constexpr int kCells = 4;         // 4 × 4 × 4 cells, 384 tetrahedra, 125 vertices
constexpr double kSide_m = 0.04;  // a 4 cm cube: 1 cm cells
inline const Lame kLiver = lame_parameters(85e3, 0.45);  // docs/configuration.md's organ
inline const TensorMassMaterial kTissue{1060, 0};

inline int vertex(int i, int j, int k) { return testing::box_vertex(i, j, k, kCells, kCells); }

/// The cube, interior vertices moved by up to 0.1 cell (a generic mesh)
/// when @p jitter; the tetrahedra stay positive.
inline TetMesh cube(bool jitter) {
  TetMesh mesh = testing::box_mesh(kSide_m, kSide_m, kSide_m, kCells, kCells, kCells);
  if (jitter) {
    std::mt19937 rng(20);
    std::uniform_real_distribution<double> d(-0.1 * kSide_m / kCells, 0.1 * kSide_m / kCells);
    for (int i = 1; i < kCells; ++i)
      for (int j = 1; j < kCells; ++j)
        for (int k = 1; k < kCells; ++k)
          mesh.vertices.row(vertex(i, j, k)) += Eigen::RowVector3d(d(rng), d(rng), d(rng));
  }
  return mesh;
}

inline std::vector<Matrix12d> element_stiffnesses(const TetMesh& mesh, const Eigen::MatrixX4i& tets,
                                                  const std::vector<Lame>& lame_of_tet) {
  std::vector<Matrix12d> out;
  for (Eigen::Index t = 0; t < tets.rows(); ++t) {
    Matrix43d p;
    for (int q = 0; q < 4; ++q) p.row(q) = mesh.vertices.row(tets(t, q));
    out.push_back(element_stiffness(p, lame_of_tet[t]));
  }
  return out;
}

inline MatrixXd full_stiffness(const TetMesh& mesh, const Eigen::MatrixX4i& tets) {
  return MatrixXd(
      assemble_full_stiffness(mesh.vertices, tets, Eigen::VectorXi::Zero(tets.rows()), {kLiver}));
}

inline Eigen::MatrixX4i rows(const Eigen::MatrixX4i& tets, const std::vector<int>& keep) {
  Eigen::MatrixX4i out(keep.size(), 4);
  for (std::size_t r = 0; r < keep.size(); ++r) out.row(r) = tets.row(keep[r]);
  return out;
}

inline std::vector<int> face_x0(int i) {
  std::vector<int> out;
  for (int j = 0; j <= kCells; ++j)
    for (int k = 0; k <= kCells; ++k) out.push_back(vertex(i, j, k));
  return out;
}

/// A tensor-mass model with its own copy of the mesh and element blocks.
struct Region {
  TetMesh mesh;
  Eigen::MatrixX4i tets;
  std::vector<Matrix12d> ke;
  TensorMassModel model;
  Region(TetMesh m, Eigen::MatrixX4i t, const std::vector<int>& fixed,
         TensorMassMaterial material = kTissue)
      : mesh(std::move(m)),
        tets(std::move(t)),
        ke(element_stiffnesses(mesh, tets, std::vector<Lame>(tets.rows(), kLiver))),
        model(mesh.vertices, tets, ke, material, fixed) {}
};

/// The DOFs of a list of vertices, in its order.
inline std::vector<int> dofs_of(const std::vector<int>& vertices) {
  std::vector<int> out;
  for (int v : vertices)
    for (int a = 0; a < 3; ++a) out.push_back(3 * v + a);
  return out;
}

/// The vertices that move in the model (neither fixed nor detached).
inline std::vector<int> moving_vertices(const TensorMassModel& m) {
  std::vector<int> out;
  for (int v = 0; v < m.vertex_count(); ++v)
    if (!m.is_fixed(v) && !m.is_detached(v)) out.push_back(v);
  return out;
}

/// ω_min and ω_max of M⁻¹ A on the moving DOFs, A given on them (dense).
inline std::array<double, 2> omega_range(const TensorMassModel& m, const MatrixXd& a) {
  const auto moving = moving_vertices(m);
  VectorXd s(3 * moving.size());
  for (std::size_t r = 0; r < moving.size(); ++r)
    s.segment<3>(3 * r).setConstant(1 / std::sqrt(m.mass_kg(moving[r])));
  const VectorXd w2 = Eigen::SelfAdjointEigenSolver<MatrixXd>(s.asDiagonal() * a * s.asDiagonal(),
                                                              Eigen::EigenvaluesOnly)
                          .eigenvalues();
  return {std::sqrt(w2.minCoeff()), std::sqrt(w2.maxCoeff())};
}

/// Steps from rest under a constant load until every mode has decayed by
/// e⁻³⁰: γ = 2 ω_min damps the slowest mode critically and the others at
/// the rate γ/2 = ω_min.
inline void settle(TensorMassModel& m, const VectorXd& load_n, double omega_min) {
  const double dt = 0.9 * m.stable_time_step().critical_time_step_s;
  const int steps = static_cast<int>(std::ceil(30 / (omega_min * dt)));
  for (int n = 0; n < steps; ++n) m.step(dt, load_n);
}

inline Matrix43d corners(const TensorMassModel& m, int t) {
  Matrix43d x;
  for (int k = 0; k < 4; ++k) x.row(k) = m.rest_positions_m().row(m.tetrahedra()(t, k));
  return x;
}

/// The region of the robustness tests: 7 × 7 × 7 cubes of 4 mm (2,058
/// tetrahedra, 512 vertices, a 28 mm cube), liver, interior vertices moved
/// by up to 0.1 cell when @p jitter (a generic mesh for the queries).
constexpr int kBoxCells = 7;
constexpr double kBoxCell_m = 4e-3;
inline TetMesh big_box(bool jitter) {
  const double side = kBoxCells * kBoxCell_m;
  TetMesh mesh = testing::box_mesh(side, side, side, kBoxCells, kBoxCells, kBoxCells);
  if (jitter) {
    std::mt19937 rng(21);
    std::uniform_real_distribution<double> d(-0.1 * kBoxCell_m, 0.1 * kBoxCell_m);
    for (int i = 1; i < kBoxCells; ++i)
      for (int j = 1; j < kBoxCells; ++j)
        for (int k = 1; k < kBoxCells; ++k)
          mesh.vertices.row(testing::box_vertex(i, j, k, kBoxCells, kBoxCells)) +=
              Eigen::RowVector3d(d(rng), d(rng), d(rng));
  }
  return mesh;
}
inline std::vector<int> big_box_face_x0() {
  std::vector<int> out;
  for (int j = 0; j <= kBoxCells; ++j)
    for (int k = 0; k <= kBoxCells; ++k)
      out.push_back(testing::box_vertex(0, j, k, kBoxCells, kBoxCells));
  return out;
}

inline Vector3d random_unit(std::mt19937& rng) {
  std::normal_distribution<double> n(0, 1);
  Vector3d d;
  do d = Vector3d(n(rng), n(rng), n(rng));
  while (d.norm() < 1e-6);
  return d.normalized();
}

}  // namespace palpate::tensor_mass_test
