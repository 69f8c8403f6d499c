#pragma once
// A small precompute job the tests run themselves: a 100 × 50 × 40 mm box,
// clamped on x = 0, soft-tissue material.

#include <filesystem>
#include <span>
#include <string>

#include "palpate/offline/mesh.hpp"
#include "palpate/offline/precompute.hpp"

namespace palpate::testing {

/// The job for @p mesh, written to `<dir>/<name>.msh`, clamped on x = 0 (the
/// half-space x ≤ 1 mm), ν = 0.45 → `<dir>/<name>.h5`.
PrecomputeJob clamped_job(const TetMesh& mesh, const std::filesystem::path& dir,
                          const std::string& name, double young_modulus_pa);
/// Runs clamped_job and returns the compliance file.
std::filesystem::path write_clamped_compliance(const TetMesh& mesh,
                                               const std::filesystem::path& dir,
                                               const std::string& name, double young_modulus_pa);

/// The job for box mesh `<dir>/<name>.msh` (written here) → `<dir>/<name>.h5`.
/// @param cells cubes along x (y and z get half as many, at least 2)
PrecomputeJob box_job(const std::filesystem::path& dir, const std::string& name = "box",
                      int cells = 4, double young_modulus_pa = 85e3);

/// Runs box_job and returns the compliance file.
std::filesystem::path write_box_compliance(const std::filesystem::path& dir,
                                           const std::string& name = "box", int cells = 4,
                                           double young_modulus_pa = 85e3);

/// The compliance vertex on the box's top face (z = 40 mm) nearest (x, y)
/// in mm, from drawn rest positions (SurfaceModel or ModelInfo: the first
/// @p compliance_vertex_count are the compliance vertices); −1 if none.
int box_top_vertex(std::span<const double> rest_positions_m, int compliance_vertex_count,
                   double x_mm, double y_mm);

}  // namespace palpate::testing
