#pragma once
/// @file
/// One candidate contact of a tick, as the active set sees it (internal to
/// the runtime; palpate/runtime/solve/active_set.hpp).

#include <array>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/request_status.hpp"

namespace palpate::detail {

/// One candidate contact of a tick.
struct ActiveRow {
  static constexpr char kActive = 0, kReleased = 1, kDormant = 2;
  int count = 1;                    ///< vertices of the point, 1 to 3
  std::array<int, 3> index{};       ///< compliance indices, −1 for a fixed vertex
  std::array<double, 3> weights{};  ///< barycentric
  ConstraintKind kind = ConstraintKind::kDisplacement;  ///< displacement or normal displacement
  /// Imposed displacement, m (a normal displacement: value.x(), along normal).
  Eigen::Vector3d value = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< unit for a tip point; zero when held
  bool tip = false;       ///< a tip point: may slide, leave or join; a held one never changes
  double friction = 0;    ///< Coulomb coefficient μ of its tool
  double depth = 0;       ///< penetration, m: the shallowest goes first when singular
  double join_gap_m = 0;  ///< a dormant point joins when pushed this far into the tip
  char state = kActive;   ///< kActive, kReleased (let go this tick) or kDormant (watched)
  /// A tip point that slid in this solve (onto its cone's edge, or its
  /// tangential rows let go): false until then.
  bool slipped = false;
};

}  // namespace palpate::detail
