#pragma once
/// @file
/// The organ's surface as it is drawn, touched and addressed: one type for
/// palpated's loaded model (SurfaceModel::surface), what a client receives
/// (ModelInfo::surface, from the ModelDescription topic, docs/dds.md),
/// gestures and benchmarks; and the one area-weighted vertex normal.

#include <cstdint>
#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate {

/// Surface vertices and triangles. The first compliance_vertex_count drawn
/// vertices are the compliance vertices in compliance order (they can move);
/// the others are the fixed (attached) vertices of the surface.
struct DrawnSurface {
  int compliance_vertex_count = 0;        ///< N_S
  std::vector<std::uint32_t> vertex_ids;  ///< mesh vertex id of each drawn vertex
  std::vector<double> rest_positions_m;   ///< 3 per drawn vertex, m, model frame
  std::vector<std::uint32_t> triangles;   ///< 3 per triangle, into drawn vertices, outward

  /// Drawn vertices.
  int vertex_count() const { return static_cast<int>(vertex_ids.size()); }
  /// Triangles.
  int triangle_count() const { return static_cast<int>(triangles.size() / 3); }
  /// Rest position of drawn vertex @p v, m.
  Eigen::Vector3d rest_position(int v) const {
    const double* p = &rest_positions_m[3 * static_cast<std::size_t>(v)];
    return {p[0], p[1], p[2]};
  }
};

/// The outward unit normal of every drawn vertex (#drawn × 3): the sum of
/// the outward normals of the triangles around it weighted by their areas,
///
///     n_v ∝ Σ_{triangles (a, b, c) ∋ v} (b − a) × (c − a),
///
/// ((b − a) × (c − a) is twice the triangle's area times its outward unit
/// normal), normalized. A row is zero where that sum vanishes: a vertex in
/// no triangle of non-zero area, which callers must treat as having no
/// normal. O(#triangles).
/// @pre the triangles index drawn vertices
Eigen::MatrixX3d vertex_normals(const DrawnSurface& surface);

}  // namespace palpate
