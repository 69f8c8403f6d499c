#pragma once
/// @file
/// One contact of a contact engine's last solve (ToolContactEngine,
/// tool_contact.hpp): a point of the surface a tool's tip presses or its
/// jaws hold, and its force on the organ.

#include <Eigen/Core>
#include <array>

namespace palpate {

/// One contact of the last solve: a point of the surface, on 1 to 3 drawn
/// vertices (compliance vertices first, as in DrawnSurface), pressed by a
/// tool's tip or held by its jaws.
struct ContactPoint {
  int tool = 0;
  bool held = false;  ///< held by the jaws, else a tip contact
  int triangle = -1;  ///< drawn triangle it lies on
  int vertex_count = 1;
  std::array<int, 3> vertices{};  ///< drawn vertices with a non-zero weight
  std::array<double, 3> weights{};
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  ///< deformed, m
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();     ///< on the organ, N
  /// The unit normal of a sliding tip contact (its force is along it); zero
  /// for a held point or a sticking tip.
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
};

}  // namespace palpate
