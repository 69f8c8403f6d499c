#pragma once
// Private to palpate_runtime: loads on the surface the tools do not make
// (a served cut region's push on the rest, docs/model/hybrid-serving.md "The hybrid model
// as served"), as the contact engine takes them: the displacement
// u_b = G f_b they give a compliance vertex (memoized per set), and two
// bounds on how far they move a vertex: from their energy (any vertex), and
// from the u_b last computed there plus the bound on the loads' changes
// since (the vertices near a tool, which the engine deforms every tick, are
// the only ones it computes u_b for: the others' bounds leave them out).

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "palpate/runtime/contact/surface_point.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace palpate::detail {

/// G's block rows at a set of loaded vertices b, gathered per compliance
/// vertex v the first time it is asked for and kept while the loaded
/// vertices stay: (G^{b v}), 3·count × 3, contiguous, so that u_b at v is
/// one product (G^{b v})ᵀ f_b (G symmetric) read down three short
/// columns, not count 3 × 3 blocks from 3·count columns of G far apart. The
/// background loads of one engine share one (its own and its surface's).
class LoadColumns {
 public:
  /// Room for @p count loads on @p model's compliance vertices: 9·count
  /// doubles per compliance vertex, of which only the vertices gathered
  /// take memory (allocates; @p model must outlive it).
  void reserve(const SurfaceModel& model, int count);
  /// The block column of compliance vertex @p v for loads on @p indices
  /// (at most the reserved count): 3·indices.size() rows, 3 columns. Other
  /// indices than the last call's forget every vertex's. Allocates nothing.
  Eigen::Map<const Eigen::MatrixX3d> at(int v, std::span<const int> indices);

 private:
  const SurfaceModel* model_ = nullptr;
  int capacity_ = 0;
  std::vector<int> index_;  // the loaded vertices the columns are for
  int count_ = 0;
  // Per compliance vertex, 9·capacity_; left uninitialized, so that only the
  // pages of the vertices gathered (those near a tool) are ever touched.
  std::unique_ptr<double[]> rows_;
  std::vector<std::uint32_t> epoch_;  // per compliance vertex: current when = epoch_now_
  std::uint32_t epoch_now_ = 1;
};

class BackgroundLoads {
 public:
  /// Room for @p count loads on @p model's compliance vertices (allocates;
  /// @p model and @p columns, reserved for as many, must outlive it).
  void reserve(const SurfaceModel& model, int count, LoadColumns& columns);
  /// Replaces the loads (3 forces each, N) and their energy f_bᵀ G f_b (J).
  /// On the same vertices as the last call, the change's bound (last_known's
  /// drift) grows by Σ_j √‖G^{jj}‖ |f_j − f_j⁻|; on others, what was known of
  /// every vertex is forgotten.
  /// @throws InputError beyond the reserved count, for a vertex out of
  ///         range or a force count other than 3 per load. Allocates nothing.
  void set(std::span<const int> indices, std::span<const double> forces_n, double energy_j);
  /// The same with u_b = G_bb f_b at the loaded vertices (3 each, m): the
  /// energy is f_b · u_b, and on the same vertices as the last call the
  /// bound grows by √((f − f⁻) · (u_b − u_b⁻)) instead (the change's energy),
  /// when the last call gave u_b too.
  /// @throws InputError as set(), and for a displacement count other than
  ///         3 per load.
  void set(std::span<const int> indices, std::span<const double> forces_n,
           std::span<const double> displacements_m);

  /// Takes @p other's loads as set() would (an engine's surface takes the
  /// loads so once per solve). Allocates nothing; @p other reserved no more.
  void copy_from(const BackgroundLoads& other);

  int count() const { return count_; }
  double energy_j() const { return energy_j_; }
  /// How far they move any vertex at most, m: |G_v f_b| ≤ √‖G^{vv}‖ √(f_bᵀ G f_b)
  /// with @p max_softness the largest √‖G^{vv}‖.
  double reach_m(double max_softness) const {
    return count_ > 0 ? max_softness * std::sqrt(energy_j_) : 0.0;
  }
  /// (1 + 1e-6) √(f_bᵀ G f_b): with a vertex's √‖G^{vv}‖, the bound on its u_b.
  double spread() const { return (1 + 1e-6) * std::sqrt(energy_j_); }
  /// u_b = Σ_j G^{v b_j} f_j at compliance vertex @p v (memoized per set).
  const Eigen::Vector3d& at(int v);
  /// The u_b compliance vertex @p v had when at() last computed it under
  /// loads on these vertices, and @p drift: it has moved since by at most
  /// √‖G^{vv}‖ · drift (m). False when never computed since the loaded
  /// vertices changed.
  bool last_known(int v, const Eigen::Vector3d*& u, double& drift) const {
    const auto slot = static_cast<std::size_t>(v);
    if (u_epoch_[slot] == 0) return false;
    u = &u_[slot];
    drift = drift_ - u_drift_[slot];
    return true;
  }
  /// H u_b at a point of a surface triangle (fixed vertices, index
  /// ≥ @p compliance_count, do not move).
  Eigen::Vector3d at_point(const SurfacePoint& point, int compliance_count) {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int i = 0; i < point.count; ++i) {
      const int v = point.vertices[static_cast<std::size_t>(i)];
      if (v < compliance_count) u += point.weights[static_cast<std::size_t>(i)] * at(v);
    }
    return u;
  }

 private:
  void forget_all();
  void replace(std::span<const int> indices, std::span<const double> forces_n, double energy_j,
               std::span<const double> displacements_m);

  const SurfaceModel* model_ = nullptr;
  LoadColumns* columns_ = nullptr;
  int count_ = 0;
  std::vector<int> index_;
  std::vector<double> force_;
  std::vector<double> displacement_;  // u_b at the loads, when given (has_displacement_)
  bool has_displacement_ = false;
  double energy_j_ = 0;
  std::vector<double> softness_;  // per compliance vertex: √‖G^{vv}‖ (Frobenius ≥ spectral)
  // Σ over the sets on these vertices of each change's bound (√(m·N)):
  // √(Δf · Δu_b) when both sets gave u_b, else Σ_j √‖G^{jj}‖ |Δf_j|.
  double drift_ = 0;
  std::vector<Eigen::Vector3d> u_;      // per compliance vertex, current when u_epoch_ = epoch_
  std::vector<std::uint32_t> u_epoch_;  // 0: never computed on these vertices
  std::vector<double> u_drift_;         // drift_ when u_ was computed
  std::uint32_t epoch_ = 1;
};

}  // namespace palpate::detail
