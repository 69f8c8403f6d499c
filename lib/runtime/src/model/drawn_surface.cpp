#include "palpate/runtime/drawn_surface.hpp"

#include <Eigen/Geometry>

namespace palpate {

Eigen::MatrixX3d vertex_normals(const DrawnSurface& surface) {
  Eigen::MatrixX3d normals = Eigen::MatrixX3d::Zero(surface.vertex_count(), 3);
  const auto& t = surface.triangles;
  for (std::size_t f = 0; f + 2 < t.size(); f += 3) {
    const int a = static_cast<int>(t[f]), b = static_cast<int>(t[f + 1]),
              c = static_cast<int>(t[f + 2]);
    const Eigen::Vector3d pa = surface.rest_position(a);
    const Eigen::RowVector3d twice_area_normal =
        (surface.rest_position(b) - pa).cross(surface.rest_position(c) - pa).transpose();
    normals.row(a) += twice_area_normal;
    normals.row(b) += twice_area_normal;
    normals.row(c) += twice_area_normal;
  }
  for (Eigen::Index v = 0; v < normals.rows(); ++v)
    if (const double length = normals.row(v).norm(); length > 0) normals.row(v) /= length;
  return normals;
}

}  // namespace palpate
