#pragma once
/// @file
/// The contact patches the run-time benchmarks impose displacements on: the k
/// compliance vertices nearest a seed vertex, like the jaws of a tool tip
/// pressing into the organ, pushed along the inward normal at the seed.
/// Works on the DrawnSurface that both SurfaceModel (in process) and
/// ModelInfo (over DDS) carry, so every benchmark presses the same patch.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <span>
#include <vector>

#include "palpate/runtime/drawn_surface.hpp"

namespace palpate::bench {

using palpate::DrawnSurface;

/// One patch: mesh vertex ids (the seed first, then by distance) and the
/// direction the tool pushes along.
struct Patch {
  std::vector<std::uint32_t> vertex_ids;
  std::array<double, 3> inward_normal{};  ///< unit, at the seed
};

/// Unit inward normal at drawn vertex @p v (minus vertex_normals()).
inline std::array<double, 3> inward_normal(const DrawnSurface& s, int v) {
  const Eigen::Vector3d n = -vertex_normals(s).row(v).transpose();
  return {n[0], n[1], n[2]};
}

/// The @p k compliance vertices nearest compliance vertex @p seed (itself
/// included), by rest distance.
inline Patch nearest_patch(const DrawnSurface& s, int seed, int k) {
  std::vector<int> order(static_cast<std::size_t>(s.compliance_vertex_count));
  std::iota(order.begin(), order.end(), 0);
  const auto distance2 = [&](int v) {
    double sum = 0;
    for (int d = 0; d < 3; ++d) {
      const double x =
          s.rest_positions_m[3 * static_cast<std::size_t>(v) + static_cast<std::size_t>(d)] -
          s.rest_positions_m[3 * static_cast<std::size_t>(seed) + static_cast<std::size_t>(d)];
      sum += x * x;
    }
    return sum;
  };
  const auto count = std::min<std::size_t>(static_cast<std::size_t>(k), order.size());
  std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(count), order.end(),
                    [&](int a, int b) { return distance2(a) < distance2(b); });
  Patch patch;
  for (std::size_t j = 0; j < count; ++j)
    patch.vertex_ids.push_back(s.vertex_ids[static_cast<std::size_t>(order[j])]);
  patch.inward_normal = inward_normal(s, seed);
  return patch;
}

/// Seed of the main patch: a fixed compliance vertex (the middle of the
/// compliance order), so that every run presses the same place.
inline int main_seed(const DrawnSurface& s) { return s.compliance_vertex_count / 2; }

/// @p count seeds spread over the compliance order (the main seed first), for
/// patches that change every request.
inline std::vector<int> spread_seeds(const DrawnSurface& s, int count) {
  std::vector<int> seeds;
  for (int i = 0; i < count; ++i)
    seeds.push_back((main_seed(s) +
                     static_cast<int>(static_cast<long>(i) * s.compliance_vertex_count / count)) %
                    s.compliance_vertex_count);
  return seeds;
}

/// Imposed depth for request number @p i: 3 mm, varied by up to 1.5 % so that
/// no two consecutive requests are identical.
inline double press_depth_m(std::uint64_t i) {
  return 3e-3 * (1.0 + 1e-3 * static_cast<double>(i % 16));
}

}  // namespace palpate::bench
