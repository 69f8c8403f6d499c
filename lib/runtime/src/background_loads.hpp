#pragma once
// Private to palpate_runtime: loads on the surface the tools do not make
// (a served cut region's push on the rest, docs/model.md "The hybrid model
// as served"), as the contact engine takes them: the displacement
// u_b = G f_b they give a compliance vertex (memoized per set), the surface
// loads with the tools' ones, and the bound on how far they move a vertex.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "palpate/runtime/surface_model.hpp"

namespace palpate::detail {

class BackgroundLoads {
 public:
  /// Room for @p count loads on a model of @p compliance_count vertices,
  /// merged after at most @p tool_loads loads of the tools (allocates).
  void reserve(int count, int compliance_count, std::size_t tool_loads);
  /// Replaces the loads (3 forces each, N) and their energy f_bᵀ G f_b (J).
  /// @throws InputError beyond the reserved count, for a vertex out of
  ///         range or a force count other than 3 per load. Allocates nothing.
  void set(std::span<const int> indices, std::span<const double> forces_n, double energy_j);

  int count() const { return count_; }
  double energy_j() const { return energy_j_; }
  /// How far they move any vertex at most, m: |G_v f_b| ≤ √‖G^{vv}‖ √(f_bᵀ G f_b)
  /// with @p max_softness the largest √‖G^{vv}‖.
  double reach_m(double max_softness) const {
    return count_ > 0 ? max_softness * std::sqrt(energy_j_) : 0.0;
  }
  /// u_b = Σ_j G^{v b_j} f_j at compliance vertex @p v.
  const Eigen::Vector3d& at(const SurfaceModel& model, int v);
  /// H u_b at a point given by vertices and weights (fixed vertices, index
  /// ≥ @p compliance_count, do not move).
  template <typename Point>
  Eigen::Vector3d at_point(const SurfaceModel& model, const Point& point, int compliance_count) {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int i = 0; i < point.count; ++i) {
      const int v = point.vertices[static_cast<std::size_t>(i)];
      if (v < compliance_count) u += point.weights[static_cast<std::size_t>(i)] * at(model, v);
    }
    return u;
  }
  /// The tools' @p tool_count loads followed by these, into arrays that
  /// stay as they are until the next call (what DeformedSurface::set_loads
  /// views), and the bound on the energy of the sum: √ of it ≤ the sum of
  /// the √ (the G-norm's triangle inequality). @returns the loads' count.
  int merge(int tool_count, const int* tool_index, const double* tool_force, double tool_energy,
            const int*& index, const double*& force, double& energy);

 private:
  int count_ = 0;
  std::vector<int> index_;
  std::vector<double> force_;
  double energy_j_ = 0;
  std::vector<int> merged_index_;
  std::vector<double> merged_force_;
  std::vector<Eigen::Vector3d> u_;  // per compliance vertex, valid when u_epoch_ = epoch_
  std::vector<std::uint32_t> u_epoch_;
  std::uint32_t epoch_ = 1;
};

}  // namespace palpate::detail
