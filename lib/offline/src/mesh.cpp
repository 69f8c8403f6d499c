#include "palpate/offline/mesh.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <unordered_map>

#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"

namespace palpate {

MeshCheck validate_and_compact(TetMesh& mesh) {
  const std::string& where = mesh.source;
  const Eigen::Index nv = mesh.vertices.rows();
  const Eigen::Index nt = mesh.tetrahedra.rows();
  if (nt == 0)
    throw InputError(
        fmt::format("{}: the mesh has no tetrahedra; palpate needs a volume mesh "
                    "of linear tetrahedra (or a closed STL surface to fill)",
                    where));
  if (mesh.source_vertex_count < nv) mesh.source_vertex_count = nv;
  if (mesh.source_ids.size() != nv) {
    mesh.source_ids.resize(nv);
    std::iota(mesh.source_ids.begin(), mesh.source_ids.end(), 0);
  }
  if (mesh.tet_group.size() != nt) mesh.tet_group = Eigen::VectorXi::Zero(nt);

  for (Eigen::Index v = 0; v < nv; ++v)
    if (!mesh.vertices.row(v).allFinite())
      throw InputError(
          fmt::format("{}: vertex {} has a non-finite coordinate ({}, {}, {}); "
                      "coordinates must be finite numbers",
                      where, mesh.source_ids[v], mesh.vertices(v, 0), mesh.vertices(v, 1),
                      mesh.vertices(v, 2)));

  std::vector<bool> used(nv, false);
  for (Eigen::Index t = 0; t < nt; ++t) {
    for (int i = 0; i < 4; ++i) {
      const int v = mesh.tetrahedra(t, i);
      if (v < 0 || v >= nv)
        throw InputError(
            fmt::format("{}: tetrahedron {} refers to vertex {}, out of range: the "
                        "mesh has {} vertices (indices 0..{})",
                        where, t, v, nv, nv - 1));
      for (int j = 0; j < i; ++j)
        if (mesh.tetrahedra(t, j) == v)
          throw InputError(
              fmt::format("{}: tetrahedron {} uses vertex {} twice", where, t, mesh.source_ids[v]));
      used[v] = true;
    }
  }

  // The same four vertices twice would count that element's stiffness twice
  // and hide its faces from the boundary.
  {
    struct TetHash {
      size_t operator()(const std::array<int, 4>& a) const {
        uint64_t h = 1469598103934665603ull;
        for (int x : a) h = (h ^ static_cast<uint32_t>(x)) * 1099511628211ull;
        return h;
      }
    };
    std::unordered_map<std::array<int, 4>, Eigen::Index, TetHash> first;
    first.reserve(static_cast<size_t>(nt));
    for (Eigen::Index t = 0; t < nt; ++t) {
      std::array<int, 4> key{mesh.tetrahedra(t, 0), mesh.tetrahedra(t, 1), mesh.tetrahedra(t, 2),
                             mesh.tetrahedra(t, 3)};
      std::sort(key.begin(), key.end());
      if (auto [it, inserted] = first.try_emplace(key, t); !inserted)
        throw InputError(
            fmt::format("{}: tetrahedra {} and {} have the same four vertices; each "
                        "tetrahedron must appear once",
                        where, it->second, t));
    }
  }

  MeshCheck check;
  check.min_volume_m3 = INFINITY;
  check.max_volume_m3 = 0;
  Matrix43d P;
  for (Eigen::Index t = 0; t < nt; ++t) {
    double longest = 0;
    for (int i = 0; i < 4; ++i) P.row(i) = mesh.vertices.row(mesh.tetrahedra(t, i));
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) longest = std::max(longest, (P.row(i) - P.row(j)).norm());
    const double V = signed_volume(P);
    // A tetrahedron this flat relative to its longest edge is degenerate at
    // double precision: its stiffness would be dominated by round-off.
    const double degenerate = 1e-12 * longest * longest * longest;
    auto ids = [&] {
      return fmt::format("{} {} {} {}", mesh.source_ids[mesh.tetrahedra(t, 0)],
                         mesh.source_ids[mesh.tetrahedra(t, 1)],
                         mesh.source_ids[mesh.tetrahedra(t, 2)],
                         mesh.source_ids[mesh.tetrahedra(t, 3)]);
    };
    // Coordinates so large that the volume overflows (NaN or infinity) would
    // pass both tests below.
    if (!std::isfinite(V) || !std::isfinite(degenerate))
      throw InputError(
          fmt::format("{}: tetrahedron {} (vertices {}) is too large: its volume "
                      "overflows double precision; coordinates must be lengths "
                      "(check the mesh's unit)",
                      where, t, ids()));
    if (std::abs(V) <= degenerate)
      throw InputError(
          fmt::format("{}: tetrahedron {} (vertices {}) has zero volume ({:.3g} m³); "
                      "every tetrahedron must have a positive volume",
                      where, t, ids(), V));
    if (V < 0)
      throw InputError(fmt::format(
          "{}: tetrahedron {} (vertices {}) is inverted (signed volume {:.3g} m³); palpate "
          "expects positively oriented tetrahedra, as Gmsh writes them",
          where, t, ids(), V));
    check.min_volume_m3 = std::min(check.min_volume_m3, V);
    check.max_volume_m3 = std::max(check.max_volume_m3, V);
  }

  // Drop unreferenced vertices, renumbering the others in order.
  std::vector<int> new_index(nv, -1);
  int kept = 0;
  for (Eigen::Index v = 0; v < nv; ++v) {
    if (used[v])
      new_index[v] = kept++;
    else
      check.dropped_vertices.push_back(mesh.source_ids[v]);
  }
  if (kept != nv) {
    Eigen::MatrixX3d vertices(kept, 3);
    Eigen::VectorXi source(kept);
    for (Eigen::Index v = 0; v < nv; ++v)
      if (new_index[v] >= 0) {
        vertices.row(new_index[v]) = mesh.vertices.row(v);
        source[new_index[v]] = mesh.source_ids[v];
      }
    for (Eigen::Index t = 0; t < nt; ++t)
      for (int i = 0; i < 4; ++i) mesh.tetrahedra(t, i) = new_index[mesh.tetrahedra(t, i)];
    for (auto& [name, ids] : mesh.group_vertices) {
      std::vector<int> kept_ids;
      for (int v : ids)
        if (v >= 0 && v < nv && new_index[v] >= 0) kept_ids.push_back(new_index[v]);
      ids = std::move(kept_ids);
    }
    mesh.vertices = std::move(vertices);
    mesh.source_ids = std::move(source);
  }
  check.bbox_min = mesh.vertices.colwise().minCoeff().transpose();
  check.bbox_max = mesh.vertices.colwise().maxCoeff().transpose();
  return check;
}

namespace {

struct FaceKey {
  std::array<int, 3> v;  // sorted
  bool operator==(const FaceKey&) const = default;
};
struct FaceHash {
  size_t operator()(const FaceKey& f) const {
    uint64_t h = 1469598103934665603ull;
    for (int x : f.v) h = (h ^ static_cast<uint64_t>(x)) * 1099511628211ull;
    return h;
  }
};

}  // namespace

Boundary extract_boundary(const TetMesh& mesh) {
  // Faces opposite each vertex, ordered so that their normal points out of a
  // positively oriented tetrahedron.
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  struct Seen {
    std::array<int, 3> oriented;
    int count;
    Eigen::Index tet;
  };
  std::unordered_map<FaceKey, Seen, FaceHash> faces;
  faces.reserve(static_cast<size_t>(mesh.tetrahedra.rows()) * 3);
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    for (const auto& f : kFace) {
      std::array<int, 3> o = {mesh.tetrahedra(t, f[0]), mesh.tetrahedra(t, f[1]),
                              mesh.tetrahedra(t, f[2])};
      FaceKey key{o};
      std::sort(key.v.begin(), key.v.end());
      auto [it, inserted] = faces.try_emplace(key, Seen{o, 0, t});
      if (++it->second.count > 2)
        throw InputError(
            fmt::format("{}: the face (vertices {} {} {}) is shared by more than two tetrahedra "
                        "(tetrahedra {} and {} among them); the mesh must be a manifold volume",
                        mesh.source, mesh.source_ids[key.v[0]], mesh.source_ids[key.v[1]],
                        mesh.source_ids[key.v[2]], it->second.tet, t));
    }
  }
  std::vector<std::array<int, 3>> tris;
  for (const auto& [key, seen] : faces)
    if (seen.count == 1) tris.push_back(seen.oriented);
  std::sort(tris.begin(), tris.end());  // deterministic output

  Boundary b;
  b.on_surface.assign(mesh.vertices.rows(), false);
  b.triangles.resize(static_cast<Eigen::Index>(tris.size()), 3);
  // Each boundary edge must be used once in each direction by the boundary
  // triangles: a closed, consistently oriented 2-manifold.
  std::unordered_map<uint64_t, int> directed;
  directed.reserve(tris.size() * 3);
  auto edge = [](int a, int c) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(c);
  };
  for (size_t f = 0; f < tris.size(); ++f) {
    for (int i = 0; i < 3; ++i) {
      b.triangles(static_cast<Eigen::Index>(f), i) = tris[f][i];
      b.on_surface[tris[f][i]] = true;
      ++directed[edge(tris[f][i], tris[f][(i + 1) % 3])];
    }
  }
  for (const auto& [e, count] : directed) {
    const int a = static_cast<int>(e >> 32);
    const int c = static_cast<int>(e & 0xffffffffu);
    auto back = directed.find(edge(c, a));
    if (count != 1 || back == directed.end() || back->second != 1)
      throw InputError(
          fmt::format("{}: the boundary is not a 2-manifold at the edge between vertices {} and {} "
                      "({} boundary triangles use it); each boundary edge must join exactly two "
                      "boundary triangles",
                      mesh.source, mesh.source_ids[a], mesh.source_ids[c],
                      count + (back == directed.end() ? 0 : back->second)));
  }
  return b;
}

std::vector<int> solid_parts(const TetMesh& mesh, int* count) {
  const int nt = static_cast<int>(mesh.tetrahedra.rows());
  std::vector<int> parent(nt);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::unordered_map<FaceKey, int, FaceHash> first_tet;
  first_tet.reserve(static_cast<size_t>(nt) * 2);
  for (int t = 0; t < nt; ++t)
    for (int skip = 0; skip < 4; ++skip) {
      FaceKey key{};
      for (int i = 0, k = 0; i < 4; ++i)
        if (i != skip) key.v[k++] = mesh.tetrahedra(t, i);
      std::sort(key.v.begin(), key.v.end());
      auto [it, inserted] = first_tet.try_emplace(key, t);
      if (!inserted) {
        const int a = find(it->second), b = find(t);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
  std::vector<int> label(nt, -1), id_of_root(nt, -1);
  int n = 0;
  for (int t = 0; t < nt; ++t) {
    const int r = find(t);
    if (id_of_root[r] < 0) id_of_root[r] = n++;
    label[t] = id_of_root[r];
  }
  if (count) *count = n;
  return label;
}

}  // namespace palpate
