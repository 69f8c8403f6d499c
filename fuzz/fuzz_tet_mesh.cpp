// Mesh validation, structure-aware: TetMesh values built from the input
// (vertices on a small grid or anywhere, NaN and huge coordinates;
// tetrahedra with out-of-range, repeated, inverted or flat corners; groups
// of vertices), then validate_and_compact, extract_boundary and
// solid_parts, then an attachment (select_fixed_vertices with a fuzzed vertex
// id file, check_attachment_stops_rigid_motion) as palpate-precompute runs
// them. What validation accepts must hold up: every vertex used, positive
// finite volumes, indices in range.

#include <fuzzer/FuzzedDataProvider.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "fuzz_support.hpp"
#include "palpate/offline/attachment.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh.hpp"

namespace {

double coordinate(FuzzedDataProvider& in) {
  static constexpr double kSpecial[] = {1e-300,
                                        1e300,
                                        -1e300,
                                        std::numeric_limits<double>::max(),
                                        std::numeric_limits<double>::denorm_min(),
                                        std::numeric_limits<double>::infinity(),
                                        std::numeric_limits<double>::quiet_NaN()};
  switch (in.ConsumeIntegralInRange(0, 15)) {
    case 0:
      return in.PickValueInArray(kSpecial);
    case 1:
      return in.ConsumeFloatingPoint<double>();
    default:
      return 0.01 * in.ConsumeIntegralInRange(0, 3);  // a 4 × 4 × 4 grid, 1 cm apart
  }
}

int vertex_index(FuzzedDataProvider& in, int nv) {
  if (in.ConsumeIntegralInRange(0, 31) == 0) return in.ConsumeIntegral<int>();
  return in.ConsumeIntegralInRange(-1, nv);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  palpate::TetMesh mesh;
  mesh.source = "fuzz";
  const int nv = in.ConsumeIntegralInRange(0, 48);
  const int nt = in.ConsumeIntegralInRange(0, 48);
  mesh.vertices.resize(nv, 3);
  for (int v = 0; v < nv; ++v)
    for (int a = 0; a < 3; ++a) mesh.vertices(v, a) = coordinate(in);
  mesh.tetrahedra.resize(nt, 4);
  mesh.tet_group.resize(nt);
  for (int t = 0; t < nt; ++t) {
    for (int i = 0; i < 4; ++i) mesh.tetrahedra(t, i) = vertex_index(in, nv);
    mesh.tet_group[t] = in.ConsumeIntegralInRange(0, 3);
  }
  if (in.ConsumeBool()) {  // the file's node numbering, as read_mesh gives it
    mesh.source_ids.resize(nv);
    for (int v = 0; v < nv; ++v) mesh.source_ids[v] = in.ConsumeIntegral<int>();
    mesh.source_vertex_count = in.ConsumeIntegralInRange(0, 2 * nv);
  }
  for (int g = in.ConsumeIntegralInRange(0, 3); g > 0; --g) {
    const std::string name = "group" + std::to_string(g);
    mesh.group_names[g] = name;
    auto& ids = mesh.group_vertices[name];
    // Vertices of the mesh, as read_mesh gives them (TetMesh's contract).
    for (int k = nv > 0 ? in.ConsumeIntegralInRange(0, 8) : 0; k > 0; --k)
      ids.push_back(in.ConsumeIntegralInRange(0, nv - 1));
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  }

  palpate::MeshCheck check;
  if (!palpate::fuzz::accepted([&] { check = palpate::validate_and_compact(mesh); })) return 0;
  const Eigen::Index kept = mesh.vertices.rows();
  PALPATE_FUZZ_CHECK(mesh.tetrahedra.rows() == nt && nt > 0);
  PALPATE_FUZZ_CHECK(mesh.source_ids.size() == kept && mesh.tet_group.size() == nt);
  PALPATE_FUZZ_CHECK(static_cast<Eigen::Index>(check.dropped_vertices.size()) + kept == nv);
  PALPATE_FUZZ_CHECK(mesh.vertices.allFinite());
  std::vector<bool> used(static_cast<std::size_t>(kept), false);
  for (Eigen::Index t = 0; t < nt; ++t) {
    palpate::Matrix43d P;
    for (int i = 0; i < 4; ++i) {
      const int v = mesh.tetrahedra(t, i);
      PALPATE_FUZZ_CHECK(v >= 0 && v < kept);
      used[static_cast<std::size_t>(v)] = true;
      P.row(i) = mesh.vertices.row(v);
    }
    const double volume = palpate::signed_volume(P);
    PALPATE_FUZZ_CHECK(std::isfinite(volume) && volume > 0);
  }
  for (const bool u : used) PALPATE_FUZZ_CHECK(u);
  PALPATE_FUZZ_CHECK(std::isfinite(check.min_volume_m3) && check.min_volume_m3 > 0);
  PALPATE_FUZZ_CHECK(check.min_volume_m3 <= check.max_volume_m3);
  for (const auto& [name, ids] : mesh.group_vertices)
    for (const int v : ids) PALPATE_FUZZ_CHECK(v >= 0 && v < kept);

  palpate::Boundary boundary;
  if (palpate::fuzz::accepted([&] { boundary = palpate::extract_boundary(mesh); })) {
    PALPATE_FUZZ_CHECK(static_cast<Eigen::Index>(boundary.on_surface.size()) == kept);
    PALPATE_FUZZ_CHECK(boundary.triangles.rows() >= 4);
    for (Eigen::Index f = 0; f < boundary.triangles.rows(); ++f)
      for (int i = 0; i < 3; ++i)
        PALPATE_FUZZ_CHECK(boundary.on_surface[static_cast<std::size_t>(boundary.triangles(f, i))]);
  }
  int parts = 0;
  const std::vector<int> label = palpate::solid_parts(mesh, &parts);
  PALPATE_FUZZ_CHECK(static_cast<int>(label.size()) == nt && parts >= 1 && parts <= nt);
  for (const int l : label) PALPATE_FUZZ_CHECK(l >= 0 && l < parts);

  // The job's attachment on this mesh: groups (known or not), regions, and a
  // vertex id file of fuzzed text.
  palpate::AttachmentSpec spec;
  for (int k = in.ConsumeIntegralInRange(0, 2); k > 0; --k)
    spec.groups.push_back(in.ConsumeBool()
                              ? "group" + std::to_string(in.ConsumeIntegralInRange(1, 3))
                              : in.ConsumeRandomLengthString(8));
  auto point = [&] { return Eigen::Vector3d(coordinate(in), coordinate(in), coordinate(in)); };
  for (int k = in.ConsumeIntegralInRange(0, 2); k > 0; --k)
    spec.boxes.push_back({point(), point()});
  for (int k = in.ConsumeIntegralInRange(0, 1); k > 0; --k)
    spec.spheres.push_back({point(), coordinate(in)});
  for (int k = in.ConsumeIntegralInRange(0, 2); k > 0; --k)
    spec.half_spaces.push_back({point(), point()});
  if (in.ConsumeBool()) {
    const std::string text = in.ConsumeRandomLengthString(256);
    spec.ids_file = palpate::fuzz::write_scratch_file(
        "ids.txt", {reinterpret_cast<const std::uint8_t*>(text.data()), text.size()});
  }
  std::vector<int> fixed;
  if (!palpate::fuzz::accepted([&] { fixed = palpate::select_fixed_vertices(mesh, spec); }))
    return 0;
  PALPATE_FUZZ_CHECK(std::is_sorted(fixed.begin(), fixed.end()));
  PALPATE_FUZZ_CHECK(std::adjacent_find(fixed.begin(), fixed.end()) == fixed.end());
  for (const int v : fixed) PALPATE_FUZZ_CHECK(v >= 0 && v < kept);
  palpate::fuzz::accepted([&] { palpate::check_attachment_stops_rigid_motion(mesh, fixed); });
  return 0;
}
