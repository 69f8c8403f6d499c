#pragma once
/// @file
/// Attachment regions: the vertices held fixed where the organ is attached
/// (ligaments, vessels), and the check that they stop every rigid motion.

#include <filesystem>
#include <string>
#include <vector>

#include "palpate/offline/mesh.hpp"

namespace palpate {

/// Axis-aligned box, metres: fixes vertices with min ≤ x ≤ max.
struct BoxRegion {
  Eigen::Vector3d min, max;
};
/// Ball, metres: fixes vertices with ‖x − center‖ ≤ radius.
struct SphereRegion {
  Eigen::Vector3d center;
  double radius = 0;
};
/// Half-space, metres: fixes vertices with (x − point)·normal ≥ 0.
struct HalfSpaceRegion {
  Eigen::Vector3d point, normal;
};

/// Where the organ is held. The union of all parts is fixed.
struct AttachmentSpec {
  std::vector<std::string> groups;  ///< Gmsh physical group names (or "#tag")
  std::filesystem::path ids_file;   ///< 0-based vertex indices in the file's node order
  std::vector<BoxRegion> boxes;
  std::vector<SphereRegion> spheres;
  std::vector<HalfSpaceRegion> half_spaces;
  /// The unit the regions were given in ("m", "cm" or "mm"): they are kept
  /// in metres, and messages about them speak the user's unit.
  std::string unit = "m";
  bool empty() const {
    return groups.empty() && ids_file.empty() && boxes.empty() && spheres.empty() &&
           half_spaces.empty();
  }
};

/// Reads a file of 0-based vertex indices, one per line ('#' starts a
/// comment; blank lines are skipped).
/// @throws InputError naming the file and line of a bad entry.
std::vector<int> read_vertex_id_file(const std::filesystem::path& file);

/// The sorted vertices (mesh numbering) an attachment selects.
/// @throws InputError for an unknown group, an index out of the file's node
///   range, or a region that selects no vertex (with the mesh's extent).
std::vector<int> select_fixed_vertices(const TetMesh& mesh, const AttachmentSpec& spec);

/// Checks that the fixed vertices stop all six rigid motions of every
/// connected part of the mesh: at least three of them, not on one line.
/// @throws InputError naming the part and what it lacks.
void check_attachment_stops_rigid_motion(const TetMesh& mesh, const std::vector<int>& fixed);

}  // namespace palpate
