#pragma once
/// @file
/// Reading organ meshes through the Gmsh SDK, filling closed surfaces with
/// tetrahedra, and generating palpate's own sample organ.

#include <filesystem>
#include <string>
#include <vector>

#include "palpate/offline/mesh.hpp"

namespace palpate {

/// Length units accepted for mesh files. Coordinates are multiplied by the
/// factor to give metres.
struct LengthUnit {
  std::string name;  ///< "m", "cm" or "mm"
  double to_metres;  ///< 1, 0.01 or 0.001
};

/// Parses "m", "cm" or "mm".
/// @throws InputError for anything else, naming the accepted values.
LengthUnit parse_length_unit(const std::string& name);

/// How read_mesh() interprets a file.
struct MeshReadOptions {
  LengthUnit unit{"m", 1.0};
  /// Target tetrahedron size when filling a closed surface (STL), in the
  /// file's unit; 0 chooses 1/20 of the bounding-box diagonal.
  double fill_size = 0;
};

/// Reads a tetrahedral mesh (Gmsh .msh v2/v4, medit .mesh, VTK; anything Gmsh
/// reads) or fills a closed triangulated surface (.stl) with tetrahedra.
/// Vertex i of the result is the node of rank i by node tag in the file (the
/// file's node order when tags are 1..N, as Gmsh writes them); physical groups
/// are kept (3-D: material regions; any dimension: attachment regions).
/// The result is not validated yet: call validate_and_compact().
/// @throws InputError for a missing/unreadable file, a format Gmsh rejects,
///   second-order elements, or a surface that cannot be filled.
TetMesh read_mesh(const std::filesystem::path& file, const MeshReadOptions& options);

/// read_mesh() in a child process that hands the mesh back: Gmsh crashes
/// on some damaged files (docs/fuzzing.md), and in the caller's process that
/// would be a segmentation fault. What palpate-precompute uses.
/// @throws InputError naming the file when Gmsh dies reading it (signal),
///   and whatever read_mesh() throws, with its message.
TetMesh read_mesh_isolated(const std::filesystem::path& file, const MeshReadOptions& options);

/// Generates palpate's sample organ with Gmsh: a liver-sized ellipsoid
/// (semi-axes 80 × 50 × 40 mm) holding a stiffer spherical tumour (radius
/// 15 mm), physical volumes "parenchyma" (1) and "tumour" (2), and writes it
/// as a Gmsh .msh 4.1 file in metres.
/// @param mesh_size_m target tetrahedron edge length (metres)
/// @throws SystemError if Gmsh fails or the file cannot be written.
void write_sample_organ(const std::filesystem::path& file, double mesh_size_m);

/// Converts a mesh file to the format given by the extension of @p output
/// (.msh, .mesh, .vtk...) through Gmsh. @p msh_version applies to .msh output.
void convert_mesh_file(const std::filesystem::path& input, const std::filesystem::path& output,
                       double msh_version = 4.1);

}  // namespace palpate
