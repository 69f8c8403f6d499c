#pragma once
/// @file
/// Tetrahedral organ meshes: the data, their validation, and the boundary
/// surface the compliance lives on.

#include <map>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate {

/// A tetrahedral mesh in SI units, as read from a file and checked.
struct TetMesh {
  Eigen::MatrixX3d vertices;    ///< #V × 3 rest positions, metres
  Eigen::MatrixX4i tetrahedra;  ///< #T × 4 vertex indices, 0-based, positively oriented
  Eigen::VectorXi tet_group;    ///< #T physical group tag of each tetrahedron (0: none)
  /// Physical group tag → name (3-D groups: materials; any dimension: attachment).
  std::map<int, std::string> group_names;
  /// Physical group name (or "#tag") → vertices it contains, sorted, 0-based.
  std::map<std::string, std::vector<int>> group_vertices;
  /// #V: index of each vertex in the input file's node order (before dropping
  /// unreferenced vertices).
  Eigen::VectorXi source_ids;
  /// Number of nodes in the input file (before dropping unreferenced ones).
  Eigen::Index source_vertex_count = 0;
  std::string source;  ///< where the mesh came from (file path), for messages
};

/// What validate_and_compact() noticed and fixed (warnings, not errors).
struct MeshCheck {
  std::vector<int> dropped_vertices;  ///< unreferenced, by source index
  double min_volume_m3 = 0;
  double max_volume_m3 = 0;
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero();
  Eigen::Vector3d bbox_max = Eigen::Vector3d::Zero();
};

/// Checks a mesh and drops the vertices no tetrahedron uses.
/// @throws InputError naming the vertex or element at fault for: no
///   tetrahedra, NaN/Inf coordinates, indices out of range, repeated vertices
///   in a tetrahedron, inverted or zero-volume tetrahedra.
MeshCheck validate_and_compact(TetMesh& mesh);

/// The boundary of a tetrahedral mesh.
struct Boundary {
  Eigen::MatrixX3i triangles;    ///< #F × 3, outward orientation (normal = (b−a)×(c−a))
  std::vector<bool> on_surface;  ///< #V
};

/// Faces that belong to exactly one tetrahedron, oriented outward.
/// @throws InputError if a face is shared by more than two tetrahedra, or the
///   boundary is not a 2-manifold (an edge with other than two boundary faces).
Boundary extract_boundary(const TetMesh& mesh);

/// Parts of the mesh that move as one elastic body: tetrahedra connected
/// through shared faces (bodies touching at a vertex or an edge can still
/// turn about it). Returns #T labels 0..C−1.
std::vector<int> solid_parts(const TetMesh& mesh, int* count);

}  // namespace palpate
