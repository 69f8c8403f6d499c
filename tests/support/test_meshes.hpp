#pragma once
// Small meshes the tests build themselves (nothing is downloaded).

#include <filesystem>
#include <string>

#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/mesh.hpp"

namespace palpate::testing {

/// A box [0,lx]×[0,ly]×[0,lz] (metres) cut into nx×ny×nz cubes of six
/// positively oriented tetrahedra each (Kuhn subdivision: conforming).
TetMesh box_mesh(double lx, double ly, double lz, int nx, int ny, int nz);

/// Index of grid vertex (i, j, k) in box_mesh().
inline int box_vertex(int i, int j, int k, int nx, int ny) {
  return i + (nx + 1) * (j + (ny + 1) * k);
}

/// The smallest compliance model: two tetrahedra sharing face (1, 2, 3),
/// 1 cm edges, vertex 0 fixed, vertices 1..4 the compliance vertices, one
/// material "organ" (85 kPa, 0.45), G's softness zero. Its metadata (method,
/// producer, dates, hashes) is each test's to set.
ComplianceModel two_tetrahedra_model();

/// Writes a Gmsh .msh 2.2 ASCII file with node tags 1..#V (coordinates as
/// given, no unit conversion) and one physical volume per tet_group value.
void write_msh22(const TetMesh& mesh, const std::filesystem::path& file);

/// A fresh empty directory under the system temp dir, removed at exit of the
/// test binary's scope owner.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

}  // namespace palpate::testing
