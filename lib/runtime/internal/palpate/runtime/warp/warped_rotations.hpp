#pragma once
// Private to palpate_runtime: the rotations a warped contact engine needs,
// vertex by vertex within a tick (docs/model/warped.md, "Large rotations: warped
// compliance"; docs/tools.md, "On a warped model").

#include <cstdint>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/rotation_field.hpp"

namespace palpate::detail {

/// ω = S Ω û at the compliance vertices the engine asks for, with û from
/// the last solve's loads (given by a function of the vertex). û is kept for
/// one epoch (until the loads change); Ω û and ω for kRotationTicks to
/// 2 kRotationTicks − 1 ticks, staggered by vertex so that the refreshes
/// spread over the ticks: rotations change slowly, and a neighbourhood of 6
/// median edges holds hundreds of vertices. Allocation-free after
/// construction.
class WarpedRotations {
 public:
  static constexpr std::uint64_t kRotationTicks = 16;

  WarpedRotations(const RotationField& field, int compliance_vertex_count)
      : field_(field),
        material_seen_(static_cast<std::size_t>(compliance_vertex_count), 0),
        fitted_until_(static_cast<std::size_t>(compliance_vertex_count), 0),
        omega_until_(static_cast<std::size_t>(compliance_vertex_count), 0),
        material_(static_cast<std::size_t>(compliance_vertex_count)),
        fitted_(static_cast<std::size_t>(compliance_vertex_count)),
        omega_(static_cast<std::size_t>(compliance_vertex_count)) {}

  /// The loads changed: û must be computed again.
  void next_epoch() {
    if (++epoch_ == 0) {
      std::fill(material_seen_.begin(), material_seen_.end(), 0);
      epoch_ = 1;
    }
  }
  /// One more tool update: kept rotations age.
  void next_tick() { ++ticks_; }

  /// û of compliance vertex @p v; @p displacement(v) computes it.
  template <typename Displacement>
  const Eigen::Vector3d& material(int v, Displacement&& displacement) {
    const auto vv = static_cast<std::size_t>(v);
    if (material_seen_[vv] != epoch_) {
      material_seen_[vv] = epoch_;
      material_[vv] = displacement(v);
    }
    return material_[vv];
  }

  /// ω of compliance vertex @p v.
  template <typename Displacement>
  const Eigen::Vector3d& rotation(int v, Displacement&& displacement) {
    const auto vv = static_cast<std::size_t>(v);
    if (omega_until_[vv] <= ticks_) {
      omega_until_[vv] = ticks_ + kRotationTicks + vv % kRotationTicks;
      omega_[vv] = field_.smoothed_at(v, [&](int b) { return fitted(b, displacement); });
    }
    return omega_[vv];
  }

 private:
  template <typename Displacement>
  const Eigen::Vector3d& fitted(int b, Displacement& displacement) {
    const auto bb = static_cast<std::size_t>(b);
    if (fitted_until_[bb] <= ticks_) {
      fitted_until_[bb] = ticks_ + kRotationTicks + bb % kRotationTicks;
      fitted_[bb] = field_.fitted_at(b, [&](int j) { return material(j, displacement); });
    }
    return fitted_[bb];
  }

  const RotationField& field_;
  std::uint32_t epoch_ = 1;
  std::uint64_t ticks_ = 0;
  std::vector<std::uint32_t> material_seen_;
  std::vector<std::uint64_t> fitted_until_, omega_until_;
  std::vector<Eigen::Vector3d> material_, fitted_, omega_;
};

}  // namespace palpate::detail
