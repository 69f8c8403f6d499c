#pragma once
/// @file
/// A compliance file loaded for serving: G in memory, plus what a client needs
/// to draw the organ and address its vertices (docs/dds.md, ModelDescription).

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "palpate/eigen.hpp"

namespace palpate {

/// What a mesh vertex id is, for requests that name it.
enum class VertexRole : std::int8_t {
  kInterior = -1,  ///< inside the organ: no compliance there
  kFixed = -2,     ///< attached: it cannot move
};

/// One organ as palpated serves it. Immutable once loaded; shared read-only by
/// the request thread and the stream thread.
struct SurfaceModel {
  std::string id;                ///< model id clients name in requests
  std::filesystem::path path;    ///< the compliance file it came from
  Eigen::MatrixXd G;             ///< 3N_S × 3N_S surface compliance, m/N, compliance order
  std::string material_summary;  ///< from the file
  std::string input_hash;        ///< "sha256:<hex>", from the file

  /// Drawn vertices: the N_S compliance vertices first (compliance order),
  /// then the fixed vertices of the surface.
  std::vector<std::uint32_t> drawn_vertex_ids;  ///< mesh vertex id of each drawn vertex
  std::vector<double> drawn_rest_positions_m;   ///< 3 per drawn vertex, m
  std::vector<std::uint32_t>
      drawn_triangles;  ///< 3 per surface triangle, into drawn vertices, outward

  /// For each mesh vertex id: its compliance index (≥ 0), or a VertexRole.
  std::vector<std::int32_t> compliance_index_of_vertex;

  /// N_S, the number of compliance vertices.
  int compliance_vertex_count() const { return static_cast<int>(G.rows() / 3); }
  /// Number of vertices of the volume mesh (valid ids are below it).
  std::uint32_t mesh_vertex_count() const {
    return static_cast<std::uint32_t>(compliance_index_of_vertex.size());
  }
};

/// Loads and checks a compliance file (read_compliance_file) and derives the
/// drawing and addressing tables.
/// @throws InputError naming the file when it is missing or malformed.
SurfaceModel load_surface_model(std::string id, const std::filesystem::path& path);

}  // namespace palpate
