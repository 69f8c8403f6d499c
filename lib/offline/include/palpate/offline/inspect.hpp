#pragma once
/// @file
/// A mesh looked at before the first precompute run (`palpate-precompute
/// inspect MESH`, docs/precompute.md, "Inspecting a mesh"): its counts, its
/// size in every unit with a guess, its physical groups, the quality of its
/// tetrahedra, and what each method would cost, so that a user can choose a
/// unit, an attachment and a method.

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "palpate/offline/mesh_io.hpp"
#include "palpate/offline/plausibility.hpp"

namespace palpate {

struct MeshInspection {
  std::string file;
  std::string unit;  ///< the unit the caller gave (metres below use it)
  long file_nodes = 0, vertices = 0, tetrahedra = 0, unreferenced_vertices = 0;
  /// In the file's own numbers (before any unit).
  std::array<double, 3> bbox_min{}, bbox_max{};
  double diagonal = 0;
  std::vector<UnitReading> readings;  ///< m, cm, mm
  std::string likely_unit;            ///< the reading most like an organ

  struct Group {
    int tag = 0;
    std::string name;
    long vertices = 0;    ///< vertices it holds (any dimension)
    long tetrahedra = 0;  ///< 3-D groups: tetrahedra tagged with it
  };
  std::vector<Group> groups;

  // Quality, in the caller's unit.
  long inverted = 0, degenerate = 0;  ///< negative, zero volume
  long first_bad = -1;                ///< first inverted or degenerate tetrahedron
  double min_volume_m3 = 0, max_volume_m3 = 0;
  double min_dihedral_deg = 0, max_dihedral_deg = 0;
  long min_dihedral_tetrahedron = -1;
  long sliver_count = 0;  ///< tetrahedra with a dihedral angle under 5°

  // The surface and what G would cost, if no surface vertex were fixed
  // (the attachment removes a few): valid only when nothing is inverted.
  bool valid = false;
  std::string invalid_reason;  ///< why the rest was not computed
  long surface_triangles = 0, surface_vertices = 0;
  double G_bytes = 0;  ///< 8 (3 N_S)², float64

  struct MethodCost {
    std::string method;
    double memory_bytes = 0;  ///< peak, about
    double disk_bytes = 0;    ///< the file
    double seconds = 0;       ///< about, on this machine
  };
  std::vector<MethodCost> methods;
  double dgemm_gflop_per_s = 0;  ///< this machine's, measured for the estimate
};

/// Reads and looks at @p file (in a child process, as precompute does).
/// @throws InputError when the file cannot be read as a mesh at all.
MeshInspection inspect_mesh(const std::filesystem::path& file, const MeshReadOptions& options);

/// For a terminal.
std::string format_inspection(const MeshInspection& inspection);
/// As JSON (`inspect --json`).
std::string inspection_json(const MeshInspection& inspection);

}  // namespace palpate
