#pragma once
/// @file
/// How large an organ is: the bounds precompute warns outside of (a mesh in
/// millimetres read as metres, docs/errors.md "Warnings") and palpated
/// warns of again when it serves such a file.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <span>

namespace palpate {

/// Organ sizes, m: the diagonal of the bounding box, from a small sample or
/// a kidney (1 cm) to a whole liver's 0.3 m with room (1 m).
inline constexpr double kPlausibleOrganMinM = 0.01;
inline constexpr double kPlausibleOrganMaxM = 1.0;

/// The diagonal of the bounding box of @p positions_m (x, y, z per point), m;
/// 0 for no points.
inline double bounding_diagonal_m(std::span<const double> positions_m) {
  if (positions_m.size() < 3) return 0;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (std::size_t i = 0; i + 2 < positions_m.size(); i += 3) {
    const Eigen::Vector3d p(positions_m[i], positions_m[i + 1], positions_m[i + 2]);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).norm();
}

/// Whether an organ @p diagonal_m across is an organ's size.
inline bool plausible_organ_size(double diagonal_m) {
  return diagonal_m >= kPlausibleOrganMinM && diagonal_m <= kPlausibleOrganMaxM;
}

}  // namespace palpate
