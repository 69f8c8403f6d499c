// One explicit step of the tensor-mass region (TensorMassModel::step: the
// force by one pass over the vertices and one over the edges, the coupling
// −S (u_Γ − u_Γ⁰) when there is one, the per-vertex update), for structured
// box regions of about 500, 2,000 and 8,000 tetrahedra (Kuhn cubes of six
// tetrahedra, 4 mm cells, liver: E = 85 kPa as in docs/configuration.md,
// ν = 0.45, ρ = 1,060 kg/m³). Same-run baseline: K u alone, as an Eigen
// sparse matrix–vector product of the assembled K in compressed rows.
// Without coupling the region is held on its x = 0 face; with coupling that
// face is the interface, and S is the true condensed stiffness of a 3-cell
// thick box of the same material beyond it, held on its far face.
// BM_CriticalStep reports Δt_crit = 2/ω_max and the steps per 1 ms tick.
//
// Usage: palpate_tensor_mass_bench [--benchmark_...]

#include <benchmark/benchmark.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "palpate/offline/fem.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "support/test_meshes.hpp"

namespace {

using palpate::Lame;
using palpate::Matrix12d;
using palpate::Matrix43d;
using palpate::TensorMassModel;

constexpr double kCell_m = 4e-3;
const Lame kLiver = palpate::lame_parameters(85e3, 0.45);

struct Box {
  int nx, ny, nz;
  Eigen::MatrixX3d x;
  Eigen::MatrixX4i tets;
  int vertex(int i, int j, int k) const { return palpate::testing::box_vertex(i, j, k, nx, ny); }
  std::vector<int> face_x(int i) const {
    std::vector<int> out;
    for (int k = 0; k <= nz; ++k)
      for (int j = 0; j <= ny; ++j) out.push_back(vertex(i, j, k));
    return out;
  }
};

/// nx × ny × nz cubes of kCell_m, six positive tetrahedra each (Kuhn: the
/// tests' box mesh, tests/support/test_meshes.hpp).
Box box(int nx, int ny, int nz) {
  const palpate::TetMesh mesh =
      palpate::testing::box_mesh(nx * kCell_m, ny * kCell_m, nz * kCell_m, nx, ny, nz);
  return Box{nx, ny, nz, mesh.vertices, mesh.tetrahedra};
}

std::vector<Matrix12d> element_stiffnesses(const Box& b) {
  std::vector<Matrix12d> out;
  for (Eigen::Index t = 0; t < b.tets.rows(); ++t) {
    Matrix43d p;
    for (int q = 0; q < 4; ++q) p.row(q) = b.x.row(b.tets(t, q));
    out.push_back(palpate::element_stiffness(p, kLiver));
  }
  return out;
}

palpate::SparseMatrixd full_k(const Box& b) {
  return palpate::assemble_full_stiffness(b.x, b.tets, Eigen::VectorXi::Zero(b.tets.rows()),
                                          {kLiver});
}

std::vector<int> dofs_of(const std::vector<int>& vertices) {
  std::vector<int> out;
  for (int v : vertices)
    for (int a = 0; a < 3; ++a) out.push_back(3 * v + a);
  return out;
}

/// The condensed stiffness, on its x = 3 face, of a 3 × ny × nz box held on
/// its x = 0 face: S = K_ΓΓ − K_ΓI K_II⁻¹ K_IΓ (N/m), vertex order (j, k).
Eigen::MatrixXd outside_schur(int ny, int nz) {
  const Box out = box(3, ny, nz);
  const Eigen::MatrixXd k = Eigen::MatrixXd(full_k(out));
  std::vector<int> inner = out.face_x(1), second = out.face_x(2);
  inner.insert(inner.end(), second.begin(), second.end());
  const auto gam = dofs_of(out.face_x(3)), rest = dofs_of(inner);
  const Eigen::MatrixXd k_ig = k(rest, gam);
  return k(gam, gam) - k_ig.transpose() * Eigen::MatrixXd(k(rest, rest)).llt().solve(k_ig);
}

struct Setup {
  Box b;
  TensorMassModel model;
  double dt_s;
};

Setup make(int n_cells_x, int n_cells_yz, bool coupled) {
  Box b = box(n_cells_x, n_cells_yz, n_cells_yz);
  const auto ke = element_stiffnesses(b);
  const auto face = b.face_x(0);
  TensorMassModel model(b.x, b.tets, ke, {1060, 0}, coupled ? std::vector<int>{} : face);
  if (coupled) model.set_interface_coupling(face, outside_schur(n_cells_yz, n_cells_yz));
  const double dt = 0.9 * model.stable_time_step().critical_time_step_s;
  return {std::move(b), std::move(model), dt};
}

/// (cells along x, along y and z): 480, 2,058 and 7,986 tetrahedra.
constexpr std::array<std::array<int, 2>, 3> kSizes = {{{5, 4}, {7, 7}, {11, 11}}};

void BM_TensorMassStep(benchmark::State& state) {
  const auto size = kSizes[state.range(0)];
  Setup s = make(size[0], size[1], state.range(1) != 0);
  // A press on the far face, so the state is not all zeros.
  Eigen::VectorXd load = Eigen::VectorXd::Zero(3 * s.model.vertex_count());
  for (int v : s.b.face_x(size[0])) load[3 * v + 2] = -1e-3;
  for (auto _ : state) {
    s.model.step(s.dt_s, load);
    benchmark::DoNotOptimize(s.model.displacement_m().data());
  }
  state.counters["tets"] = static_cast<double>(s.b.tets.rows());
  state.counters["vertices"] = s.model.vertex_count();
  state.counters["interface"] = static_cast<double>(s.model.interface_vertices().size());
  // 1e-3 s × iterations / elapsed s: the steps that fit in a 1 ms tick.
  state.counters["steps_per_ms"] =
      benchmark::Counter(1e-3, benchmark::Counter::kIsIterationInvariantRate);
}

/// Same run baseline: y = K u, K the assembled 3#V × 3#V stiffness in CSR.
void BM_SparseKu(benchmark::State& state) {
  const auto size = kSizes[state.range(0)];
  const Box b = box(size[0], size[1], size[1]);
  const Eigen::SparseMatrix<double, Eigen::RowMajor> k = full_k(b);
  const Eigen::VectorXd u = Eigen::VectorXd::LinSpaced(k.cols(), -1e-4, 1e-4);
  Eigen::VectorXd y(k.rows());
  for (auto _ : state) {
    y.noalias() = k * u;
    benchmark::DoNotOptimize(y.data());
  }
  state.counters["tets"] = static_cast<double>(b.tets.rows());
  state.counters["nonzeros"] = static_cast<double>(k.nonZeros());
}

/// Δt_crit of the liver at 4 mm cells (coupled and not) and the substeps a
/// 1 ms haptic tick needs at 0.9 Δt_crit; the time is the power iteration's.
void BM_CriticalStep(benchmark::State& state) {
  const auto size = kSizes[state.range(0)];
  Box b = box(size[0], size[1], size[1]);
  const auto ke = element_stiffnesses(b);
  const bool coupled = state.range(1) != 0;
  TensorMassModel model(b.x, b.tets, ke, {1060, 0}, coupled ? std::vector<int>{} : b.face_x(0));
  if (coupled) model.set_interface_coupling(b.face_x(0), outside_schur(size[1], size[1]));
  palpate::StableTimeStep bound;
  for (auto _ : state) bound = model.stable_time_step();
  state.counters["dt_crit_us"] = bound.critical_time_step_s * 1e6;
  state.counters["dt_gershgorin_us"] = bound.gershgorin_time_step_s * 1e6;
  state.counters["dt_element_us"] = bound.element_time_step_s * 1e6;
  state.counters["iterations"] = bound.iterations;
  state.counters["substeps_per_ms"] = std::ceil(1e-3 / (0.9 * bound.critical_time_step_s));
}

BENCHMARK(BM_TensorMassStep)
    ->ArgsProduct({{0, 1, 2}, {0, 1}})
    ->ArgNames({"size", "coupled"})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SparseKu)->DenseRange(0, 2)->ArgName("size")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CriticalStep)
    ->ArgsProduct({{0, 2}, {0, 1}})
    ->ArgNames({"size", "coupled"})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
