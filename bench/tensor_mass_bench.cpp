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
// Cutting (issue 20: a cut within 10 ms; the tick is 1 ms), on the 2,058-
// tetrahedron box held on x = 0: BM_CutTick is one tick's cut, the query
// of the quadrilateral a blade swept (tetrahedra_swept_by_blade, spatial
// index) and remove_tetrahedron for each tetrahedron it returns, for a
// blade of 10 mm and one of 40 mm (across the whole 28 mm section) moving
// 1 mm a tick in strokes across the region, and BM_CutSection a blade
// sweeping a whole cross-section in one tick; BM_SweptQuery is the query
// alone (no removal), through the index and, as the same-run baseline, by
// a scan of every tetrahedron with the same exact test; BM_SegmentQuery the
// same for tetrahedra_crossed_by_segment.
//
// Usage: palpate_tensor_mass_bench [--benchmark_...]

#include <benchmark/benchmark.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <array>
#include <cmath>
#include <random>
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

/// Strokes of a blade of @p length_m across the size-1 box (7 × 7 × 7
/// cells): twenty, at random x and heights, the blade leaning 17° from z,
/// each moving along y at 1 mm a tick from 2 mm before the region to 2 mm
/// past it (32 ticks). A fixed seed: the same sweeps in every run.
std::vector<std::array<palpate::Blade, 2>> strokes(double length_m) {
  const double side = kSizes[1][1] * kCell_m;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<std::array<palpate::Blade, 2>> out;
  const Eigen::Vector3d along = Eigen::Vector3d(0.3, 0, 1).normalized();
  for (int s = 0; s < 20; ++s) {
    const double x = (0.1 + 0.8 * unit(rng)) * side, z = (0.2 + 0.6 * unit(rng)) * side;
    for (int tick = 0; tick < 32; ++tick) {
      const Eigen::Vector3d at(x, -2e-3 + 1e-3 * tick, z), next = at + Eigen::Vector3d(0, 1e-3, 0);
      const Eigen::Vector3d half = 0.5 * length_m * along;
      out.push_back(
          {palpate::Blade{at - half, at + half}, palpate::Blade{next - half, next + half}});
    }
  }
  return out;
}

/// One tick's cut: the swept quadrilateral's tetrahedra, each removed. The
/// strokes cut the region apart as they go; after the last, the region is
/// restored (outside the timing) and the strokes start again.
void BM_CutTick(benchmark::State& state) {
  const double length_m = static_cast<double>(state.range(0)) * 1e-3;
  Setup s = make(kSizes[1][0], kSizes[1][1], false);
  const TensorMassModel whole = s.model;
  const auto sweeps = strokes(length_m);
  std::vector<int> removed;
  removed.reserve(static_cast<std::size_t>(whole.tetrahedron_count()));
  std::size_t next = 0;
  long cut = 0, most = 0;
  for (auto _ : state) {
    if (next == sweeps.size()) {
      state.PauseTiming();
      s.model = whole;
      next = 0;
      state.ResumeTiming();
    }
    const int n = s.model.cut_swept_blade(sweeps[next][0], sweeps[next][1], removed);
    ++next;
    cut += n;
    most = std::max<long>(most, n);
    benchmark::DoNotOptimize(removed.data());
  }
  state.counters["tets"] = static_cast<double>(whole.tetrahedron_count());
  state.counters["removed_per_tick"] =
      static_cast<double>(cut) / static_cast<double>(state.iterations());
  state.counters["most_removed"] = static_cast<double>(most);
}

/// The heaviest tick: a blade across the whole section sweeping all of it
/// at once, the plane x = 14 mm (through the middle of a layer of cubes)
/// from y = −6 mm to 34 mm, z −6 to 34 mm: every tetrahedron of the layer
/// (294) removed in one tick, leaving two parts. The region is restored
/// before each tick, outside the timing.
void BM_CutSection(benchmark::State& state) {
  Setup s = make(kSizes[1][0], kSizes[1][1], false);
  const TensorMassModel whole = s.model;
  const double x = 3.5 * kCell_m, lo = -6e-3, hi = 34e-3;
  const palpate::Blade before{{x, lo, lo}, {x, lo, hi}}, after{{x, hi, lo}, {x, hi, hi}};
  std::vector<int> removed;
  removed.reserve(static_cast<std::size_t>(whole.tetrahedron_count()));
  int n = 0;
  for (auto _ : state) {
    state.PauseTiming();
    s.model = whole;
    state.ResumeTiming();
    n = s.model.cut_swept_blade(before, after, removed);
    benchmark::DoNotOptimize(removed.data());
  }
  state.counters["tets"] = static_cast<double>(whole.tetrahedron_count());
  state.counters["removed"] = n;
  state.counters["parts"] = s.model.connected_parts();
}

/// The swept-quadrilateral query alone on the whole region: through the
/// index (scan = 0) or by the scan of every tetrahedron (scan = 1, the
/// baseline: the same exact test, triangle_meets_tetrahedron).
void BM_SweptQuery(benchmark::State& state) {
  const bool scan = state.range(1) != 0;
  Setup s = make(kSizes[1][0], kSizes[1][1], false);
  const auto sweeps = strokes(static_cast<double>(state.range(0)) * 1e-3);
  const TensorMassModel& m = s.model;
  std::vector<int> out;
  out.reserve(static_cast<std::size_t>(m.tetrahedron_count()));
  std::vector<palpate::Matrix43d> corners(static_cast<std::size_t>(m.tetrahedron_count()));
  for (int t = 0; t < m.tetrahedron_count(); ++t)
    for (int k = 0; k < 4; ++k)
      corners[static_cast<std::size_t>(t)].row(k) = m.rest_positions_m().row(m.tetrahedra()(t, k));
  std::size_t next = 0;
  long met = 0;
  for (auto _ : state) {
    const auto& [before, after] = sweeps[next];
    next = (next + 1) % sweeps.size();
    if (scan) {
      out.clear();
      for (int t = 0; t < m.tetrahedron_count(); ++t) {
        const auto& x = corners[static_cast<std::size_t>(t)];
        if (!m.is_removed(t) &&
            (palpate::triangle_meets_tetrahedron(before.a_m, before.b_m, after.b_m, x) ||
             palpate::triangle_meets_tetrahedron(before.a_m, after.b_m, after.a_m, x)))
          out.push_back(t);
      }
    } else {
      m.tetrahedra_swept_by_blade(before, after, out);
    }
    met += static_cast<long>(out.size());
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["tets"] = static_cast<double>(m.tetrahedron_count());
  state.counters["met_per_query"] =
      static_cast<double>(met) / static_cast<double>(state.iterations());
}

/// The same for the segment query: the blades of the strokes above.
void BM_SegmentQuery(benchmark::State& state) {
  const bool scan = state.range(1) != 0;
  Setup s = make(kSizes[1][0], kSizes[1][1], false);
  const auto sweeps = strokes(static_cast<double>(state.range(0)) * 1e-3);
  const TensorMassModel& m = s.model;
  std::vector<int> out;
  out.reserve(static_cast<std::size_t>(m.tetrahedron_count()));
  std::size_t next = 0;
  for (auto _ : state) {
    const palpate::Blade& blade = sweeps[next][0];
    next = (next + 1) % sweeps.size();
    if (scan) {
      out.clear();
      palpate::Matrix43d x;
      for (int t = 0; t < m.tetrahedron_count(); ++t) {
        for (int k = 0; k < 4; ++k) x.row(k) = m.rest_positions_m().row(m.tetrahedra()(t, k));
        if (!m.is_removed(t) && palpate::segment_meets_tetrahedron(blade.a_m, blade.b_m, x))
          out.push_back(t);
      }
    } else {
      m.tetrahedra_crossed_by_segment(blade.a_m, blade.b_m, out);
    }
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["tets"] = static_cast<double>(m.tetrahedron_count());
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
BENCHMARK(BM_CutTick)->Arg(10)->Arg(40)->ArgName("blade_mm")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CutSection)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SweptQuery)
    ->ArgsProduct({{10, 40}, {0, 1}})
    ->ArgNames({"blade_mm", "scan"})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SegmentQuery)
    ->ArgsProduct({{10, 40}, {0, 1}})
    ->ArgNames({"blade_mm", "scan"})
    ->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
