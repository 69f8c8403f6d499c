#pragma once
/// @file
/// The floor of a contact tick (issue 17's 64-point target;
/// docs/benchmarks-history.md, "The 64-point tick's floor"), for bench/contact_bench.cpp.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cstddef>
#include <vector>

#include "palpate/core/statistics.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace palpate::bench {

/// What no exact detection and solve of the next tick can skip, timed
/// apart from the engine after each update (issue 17's 64-point target):
/// the deformed positions of the vertices within the tool's search radius
/// at rest (r + search_margin + the contact points' largest displacement,
/// the engine's own radius), u_v = Σ_l G^{vl} f_l under the loads just
/// solved, read down the loads' columns of G as the engine reads them; and
/// G's blocks among the contact points' vertices (G_UU, half of it: G is
/// symmetric), the solve's first read. Nothing else: no closest point, no
/// sort, no factorization, no local model.
struct TickFloor {
  std::vector<int> candidates;
  std::vector<Eigen::Vector3d> u;
  std::vector<int> used;
  std::vector<char> in_used;
  std::vector<double> positions_us, blocks_us, whole_us, block_major_us;
  double candidate_sum = 0, used_sum = 0, load_sum = 0;
  // PALPATE_BENCH_LAYOUTS=1 (float64 files): the positions also read two
  // other ways, timed the same way: every vertex's, each load's columns
  // read whole (whole_columns_*), and the candidates' from a copy of G
  // whose 3 × 3 blocks are contiguous, G^{vl} at 9 (l n + v) (block_major_*;
  // a layout the engine does not have, 346 MB more on h8).
  std::vector<double> block_major;
  Eigen::VectorXd whole;
  double sink = 0;

  /// Also times the positions read the two other ways (allocates the copy
  /// of G; nothing for a float32 model).
  void time_layouts_too(const palpate::SurfaceModel& m) {
    if (m.float32() || m.G.size() == 0) return;
    const auto n = static_cast<std::size_t>(m.compliance_vertex_count());
    block_major.resize(9 * n * n);
    for (std::size_t l = 0; l < n; ++l)
      for (std::size_t v = 0; v < n; ++v)
        Eigen::Map<Eigen::Matrix3d>(block_major.data() + 9 * (l * n + v)) =
            m.G_block(static_cast<Eigen::Index>(v), static_cast<Eigen::Index>(l));
    whole.resize(m.G.rows());
  }

  void measure(const palpate::SurfaceModel& m, const palpate::ToolContactEngine& engine,
               const Eigen::Vector3d& centre, double reach_m) {
    const auto points = engine.contact_points();
    if (points.empty()) return;
    const int n = m.compliance_vertex_count();
    double largest = 0;
    for (const auto& p : points) {
      Eigen::Vector3d at_rest = Eigen::Vector3d::Zero();
      for (int i = 0; i < p.vertex_count; ++i)
        at_rest += p.weights[static_cast<std::size_t>(i)] *
                   m.surface.rest_position(p.vertices[static_cast<std::size_t>(i)]);
      largest = std::max(largest, (p.position_m - at_rest).norm());
    }
    const double radius = reach_m + largest;
    candidates.clear();
    for (int j = 0; j < n; ++j)
      if ((m.surface.rest_position(j) - centre).squaredNorm() <= radius * radius)
        candidates.push_back(j);
    u.assign(candidates.size(), Eigen::Vector3d::Zero());
    const auto index = engine.contact_indices();
    const auto force = engine.contact_forces();
    const Eigen::Index ld = m.float32() ? m.G32.rows() : m.G.rows();
    const auto start = std::chrono::steady_clock::now();
    for (std::size_t l = 0; l < index.size(); ++l) {
      const Eigen::Vector3d f(force[3 * l], force[3 * l + 1], force[3 * l + 2]);
      if (m.float32()) {  // the columns in float32, the sums in double
        const float* columns = m.G32.data() + 3 * index[l] * ld;
        for (std::size_t j = 0; j < candidates.size(); ++j)
          u[j].noalias() += Eigen::Map<const Eigen::Matrix3f, 0, Eigen::OuterStride<>>(
                                columns + 3 * candidates[j], 3, 3, Eigen::OuterStride<>(ld))
                                .cast<double>() *
                            f;
        continue;
      }
      const double* columns = m.G.data() + 3 * index[l] * ld;
      for (std::size_t j = 0; j < candidates.size(); ++j)
        u[j].noalias() += Eigen::Map<const Eigen::Matrix3d, 0, Eigen::OuterStride<>>(
                              columns + 3 * candidates[j], 3, 3, Eigen::OuterStride<>(ld)) *
                          f;
    }
    const auto middle = std::chrono::steady_clock::now();
    if (!block_major.empty()) {
      // Every vertex, each load's three columns read whole, in order.
      whole.setZero();
      const auto from = std::chrono::steady_clock::now();
      for (std::size_t l = 0; l < index.size(); ++l) {
        const Eigen::Vector3d f(force[3 * l], force[3 * l + 1], force[3 * l + 2]);
        whole.noalias() +=
            Eigen::Map<const Eigen::MatrixXd>(m.G.data() + 3 * index[l] * ld, ld, 3) * f;
      }
      const auto to = std::chrono::steady_clock::now();
      whole_us.push_back(std::chrono::duration<double, std::micro>(to - from).count());
      sink += whole.sum();
      // The candidates' blocks, each contiguous.
      std::vector<Eigen::Vector3d> v(candidates.size(), Eigen::Vector3d::Zero());
      const auto block_from = std::chrono::steady_clock::now();
      for (std::size_t l = 0; l < index.size(); ++l) {
        const Eigen::Vector3d f(force[3 * l], force[3 * l + 1], force[3 * l + 2]);
        const double* blocks = block_major.data() +
                               9 * static_cast<std::size_t>(index[l]) * static_cast<std::size_t>(n);
        for (std::size_t j = 0; j < candidates.size(); ++j)
          v[j].noalias() += Eigen::Map<const Eigen::Matrix3d>(
                                blocks + 9 * static_cast<std::size_t>(candidates[j])) *
                            f;
      }
      const auto block_to = std::chrono::steady_clock::now();
      block_major_us.push_back(
          std::chrono::duration<double, std::micro>(block_to - block_from).count());
      for (std::size_t j = 0; j < v.size(); ++j) sink += (v[j] - u[j]).norm();
    }
    for (const auto& v : u) sink += v.x();
    used.clear();
    in_used.assign(static_cast<std::size_t>(n), 0);
    for (const auto& p : points)
      for (int i = 0; i < p.vertex_count; ++i)
        if (const int v = p.vertices[static_cast<std::size_t>(i)];
            v < n && !in_used[static_cast<std::size_t>(v)]) {
          in_used[static_cast<std::size_t>(v)] = 1;
          used.push_back(v);
        }
    const auto blocks_start = std::chrono::steady_clock::now();
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (std::size_t b = 0; b < used.size(); ++b)
      for (std::size_t a = 0; a <= b; ++a) sum += m.G_block(used[a], used[b]);
    const auto end = std::chrono::steady_clock::now();
    sink += sum.sum();
    using us = std::chrono::duration<double, std::micro>;
    positions_us.push_back(us(middle - start).count());
    blocks_us.push_back(us(end - blocks_start).count());
    candidate_sum += static_cast<double>(candidates.size());
    used_sum += static_cast<double>(used.size());
    load_sum += static_cast<double>(index.size());
  }

  void report(benchmark::State& state) {
    if (positions_us.empty()) return;
    std::vector<double> both(positions_us.size());
    for (std::size_t i = 0; i < both.size(); ++i) both[i] = positions_us[i] + blocks_us[i];
    const auto q = [](std::vector<double> v, double at) {
      std::sort(v.begin(), v.end());
      return palpate::sorted_percentile(v, at);
    };
    const auto ticks = static_cast<double>(positions_us.size());
    state.counters["floor_p50_us"] = q(both, 0.5);
    state.counters["floor_p99_us"] = q(both, 0.99);
    state.counters["floor_positions_p50_us"] = q(positions_us, 0.5);
    state.counters["floor_positions_p99_us"] = q(positions_us, 0.99);
    if (!block_major_us.empty()) {
      state.counters["whole_columns_p50_us"] = q(whole_us, 0.5);
      state.counters["whole_columns_p99_us"] = q(whole_us, 0.99);
      state.counters["block_major_p50_us"] = q(block_major_us, 0.5);
      state.counters["block_major_p99_us"] = q(block_major_us, 0.99);
    }
    state.counters["floor_G_UU_p50_us"] = q(blocks_us, 0.5);
    state.counters["floor_candidates"] = candidate_sum / ticks;
    state.counters["floor_U"] = used_sum / ticks;
    state.counters["floor_loads"] = load_sum / ticks;
    benchmark::DoNotOptimize(sink);
  }
};

}  // namespace palpate::bench
