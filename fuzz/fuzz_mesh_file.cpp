// Mesh files through the Gmsh SDK: read_mesh on fuzzed bytes (Gmsh .msh,
// medit .mesh or legacy VTK, chosen by the first byte), then the checks
// palpate-precompute runs on what it read: validate_and_compact and
// extract_boundary. Gmsh itself is Debian's, not instrumented: its crashes
// show up, its branches do not guide the fuzzer (docs/fuzzing.md).

#include <cstdint>
#include <span>

#include "fuzz_support.hpp"
#include "palpate/offline/mesh.hpp"
#include "palpate/offline/mesh_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static constexpr const char* kNames[] = {"mesh.msh", "mesh.mesh", "mesh.vtk"};
  const auto file = palpate::fuzz::write_scratch_file(kNames[data[0] % 3], {data + 1, size - 1});
  palpate::TetMesh mesh;
  if (!palpate::fuzz::accepted([&] { mesh = palpate::read_mesh(file, {}); })) return 0;
  PALPATE_FUZZ_CHECK(mesh.tetrahedra.rows() == mesh.tet_group.size());
  if (!palpate::fuzz::accepted([&] { palpate::validate_and_compact(mesh); })) return 0;
  palpate::fuzz::accepted([&] { palpate::extract_boundary(mesh); });
  return 0;
}
