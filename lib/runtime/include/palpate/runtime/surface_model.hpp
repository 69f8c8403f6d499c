#pragma once
/// @file
/// A compliance file loaded for serving: G in memory, plus what a client needs
/// to draw the organ and address its vertices (docs/dds.md, ModelDescription).

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/file/cut_region_data.hpp"
#include "palpate/runtime/drawn_surface.hpp"

namespace palpate {

/// What a mesh vertex id is, for requests that name it.
enum class VertexRole : std::int8_t {
  kInterior = -1,  ///< inside the organ: no compliance there
  kFixed = -2,     ///< attached: it cannot move
};

/// One organ as palpated serves it. Immutable once loaded; shared read-only by
/// the request thread and the stream thread.
struct SurfaceModel {
  std::string id;              ///< model id clients name in requests
  std::filesystem::path path;  ///< the compliance file it came from
  Eigen::MatrixXd G;           ///< 3N_S × 3N_S surface compliance, m/N, compliance order
  /// The same, as stored, when a float32 file is loaded with keep_float32
  /// (half the memory; G is then empty). Use G_block() and
  /// surface_displacement(const SurfaceModel&, …) to read either.
  Eigen::MatrixXf G32;
  std::string material_summary;  ///< from the file
  std::string input_hash;        ///< "sha256:<hex>", from the file
  /// The file's cuttable region (/cut_region, format 1.3), as the job chose
  /// it, or empty. Such a file's mesh and G are the organ without that
  /// region, which palpated steps beside it (HybridRegion; docs/model/hybrid-serving.md,
  /// "The hybrid model as served").
  std::string cut_region_spec;
  /// The region itself (null without one): what HybridRegion steps.
  std::shared_ptr<const CutRegionData> cut_region;
  /// For each mesh vertex id, its index in the input mesh file (the numbers
  /// messages use; a Γ vertex has the same one in cut_region).
  std::vector<std::int32_t> source_vertex_ids;

  /// The surface to draw and touch: the N_S compliance vertices first
  /// (compliance order), then the fixed vertices of the surface.
  DrawnSurface surface;

  /// For each mesh vertex id: its compliance index (≥ 0), or a VertexRole.
  std::vector<std::int32_t> compliance_index_of_vertex;

  /// 3N_S, the rows of G whichever precision holds it.
  Eigen::Index compliance_rows() const { return G32.size() > 0 ? G32.rows() : G.rows(); }
  /// N_S, the number of compliance vertices.
  int compliance_vertex_count() const { return static_cast<int>(compliance_rows() / 3); }
  /// True when G is held in float32 (G32).
  bool float32() const { return G32.size() > 0; }
  /// Bytes of G in memory.
  double G_bytes() const {
    return float32() ? 4.0 * static_cast<double>(G32.size()) : 8.0 * static_cast<double>(G.size());
  }
  /// The 3 × 3 block G^ab (m/N) of compliance vertices a and b, in double.
  Eigen::Matrix3d G_block(Eigen::Index a, Eigen::Index b) const {
    if (float32()) return G32.block<3, 3>(3 * a, 3 * b).cast<double>();
    return G.block<3, 3>(3 * a, 3 * b);
  }
  /// Number of vertices of the volume mesh (valid ids are below it).
  std::uint32_t mesh_vertex_count() const {
    return static_cast<std::uint32_t>(compliance_index_of_vertex.size());
  }
};

/// What palpated says of a warped model's cut region, which it does not
/// step (the tensor-mass region is linear).
inline constexpr const char* kCutRegionNotSimulated =
    "a warped model is served without its cuttable region, which is linear: where the region "
    "was, tools and requests meet the rest of the organ's surface, a cavity (docs/model.md, "
    "\"The hybrid model as served\"); serve it linear (no warped = true) to step the region";

/// Loads and checks a compliance file (read_compliance_file) and derives the
/// drawing and addressing tables.
/// @param keep_float32 a float32 file's G stays float32 in memory (G32, half
///   the bytes; the algebra still runs in double); otherwise G is double.
/// @throws InputError naming the file when it is missing or malformed.
SurfaceModel load_surface_model(std::string id, const std::filesystem::path& path,
                                bool keep_float32 = false);

}  // namespace palpate
