// The tensor-mass region's topology: the adjacency a cut updates locally
// (vertex and edge → tetrahedra, faces), the tensors re-summed from it, the
// boundary, removal, and the connected parts a cut leaves (docs/model/tensor-mass.md,
// "The tensor-mass model: a cuttable region"; the queries of what a blade
// meets are tensor_mass_query.cpp's).

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "palpate/core/error.hpp"
#include "palpate/runtime/tensor_mass.hpp"

namespace palpate {
namespace {

using Eigen::Matrix3d;

constexpr const char* kTensorMassCutWhat = "tensor-mass region";

/// The face opposite local vertex k, ordered so that (b − a) × (c − a) points
/// out of a positively oriented tetrahedron.
constexpr std::array<std::array<int, 3>, 4> kFaceOpposite = {
    {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}};
/// The six edges as pairs of local vertices.
constexpr std::array<std::array<int, 2>, 6> kLocalEdges = {
    {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}}};

int local_index(const Eigen::MatrixX4i& t, int tet, int v) {
  for (int k = 0; k < 4; ++k)
    if (t(tet, k) == v) return k;
  return -1;
}

/// CSR of item → tetrahedra from (item, tet) pairs; item counts known.
void build_csr(int items, const std::vector<std::array<int, 2>>& pairs, std::vector<int>& begin,
               std::vector<int>& list) {
  begin.assign(items + 1, 0);
  for (const auto& p : pairs) ++begin[p[0] + 1];
  for (int i = 0; i < items; ++i) begin[i + 1] += begin[i];
  list.resize(pairs.size());
  std::vector<int> next(begin.begin(), begin.end() - 1);
  for (const auto& p : pairs) list[next[p[0]]++] = p[1];  // pairs come in tet order
}

}  // namespace

void TensorMassModel::build_topology() {
  const int nv = static_cast<int>(rest_m_.rows());
  const int nt = static_cast<int>(tets_.rows());
  // Vertex → tetrahedra.
  std::vector<std::array<int, 2>> pairs;
  pairs.reserve(4 * nt);
  for (int t = 0; t < nt; ++t)
    for (int k = 0; k < 4; ++k) pairs.push_back({tets_(t, k), t});
  std::stable_sort(pairs.begin(), pairs.end(),
                   [](const auto& a, const auto& b) { return a[0] < b[0]; });
  build_csr(nv, pairs, vertex_tets_begin_, vertex_tets_);

  // Edges: the sorted distinct vertex pairs; ids in (i, j) order, so a lookup
  // is a binary search and the force pass walks memory in order.
  std::vector<std::array<int, 3>> edge_keys;  // i, j, tet
  edge_keys.reserve(6 * nt);
  for (int t = 0; t < nt; ++t)
    for (const auto& e : kLocalEdges) {
      const int a = tets_(t, e[0]), b = tets_(t, e[1]);
      edge_keys.push_back({std::min(a, b), std::max(a, b), t});
    }
  std::sort(edge_keys.begin(), edge_keys.end());
  pairs.clear();
  for (const auto& key : edge_keys) {
    if (edge_vertices_.empty() || edge_vertices_.back() != std::array<int, 2>{key[0], key[1]})
      edge_vertices_.push_back({key[0], key[1]});
    pairs.push_back({static_cast<int>(edge_vertices_.size()) - 1, key[2]});
  }
  const int ne = static_cast<int>(edge_vertices_.size());
  build_csr(ne, pairs, edge_tets_begin_, edge_tets_);
  tet_edges_.resize(nt);
  for (int t = 0; t < nt; ++t)
    for (int e = 0; e < 6; ++e)
      tet_edges_[t][e] = find_edge(tets_(t, kLocalEdges[e][0]), tets_(t, kLocalEdges[e][1]));

  // Faces, to keep the boundary: a face of one tetrahedron is on it.
  std::vector<std::array<int, 5>> face_keys;  // sorted vertices, tet, local k
  face_keys.reserve(4 * nt);
  for (int t = 0; t < nt; ++t)
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> f = {tets_(t, kFaceOpposite[k][0]), tets_(t, kFaceOpposite[k][1]),
                              tets_(t, kFaceOpposite[k][2])};
      std::sort(f.begin(), f.end());
      face_keys.push_back({f[0], f[1], f[2], t, k});
    }
  std::sort(face_keys.begin(), face_keys.end());
  tet_faces_.resize(nt);
  for (std::size_t q = 0; q < face_keys.size(); ++q) {
    const auto& key = face_keys[q];
    const bool same = q > 0 && std::equal(key.begin(), key.begin() + 3, face_keys[q - 1].begin());
    if (!same) {
      face_tets_.push_back({key[3], -1});
    } else if (face_tets_.back()[1] < 0) {
      face_tets_.back()[1] = key[3];
    } else {
      throw InputError(
          fmt::format("{}: the face ({}, {}, {}) belongs to tetrahedra {}, {} and {}; "
                      "a face of at most two tetrahedra is accepted",
                      kTensorMassCutWhat, key[0], key[1], key[2], face_tets_.back()[0],
                      face_tets_.back()[1], key[3]));
    }
    tet_faces_[key[3]][key[4]] = static_cast<int>(face_tets_.size()) - 1;
  }

  // The state built the way a cut rebuilds it, so that a cut model and one
  // built from the remaining tetrahedra agree.
  tet_alive_.assign(nt, 1);
  remaining_tets_ = nt;
  vertex_tensor_.assign(nv, Matrix3d::Zero());
  mass_kg_.assign(nv, 0.0);
  vertex_tet_count_.assign(nv, 0);
  for (int v = 0; v < nv; ++v) resum_vertex(v);
  edge_tet_count_.assign(ne, 0);
  live_edges_.resize(ne);
  live_edge_id_.resize(ne);
  edge_slot_.resize(ne);
  for (int e = 0; e < ne; ++e) {
    live_edges_[e].i = edge_vertices_[e][0];
    live_edges_[e].j = edge_vertices_[e][1];
    live_edge_id_[e] = e;
    edge_slot_[e] = e;
    resum_edge(e);
  }
  boundary_.reserve(face_tets_.size());
  boundary_face_id_.reserve(face_tets_.size());
  face_slot_.assign(face_tets_.size(), -1);
  for (int f = 0; f < static_cast<int>(face_tets_.size()); ++f)
    if (face_tets_[f][1] < 0) add_boundary_face(f, face_tets_[f][0]);
}

int TensorMassModel::find_edge(int i, int j) const {
  const std::array<int, 2> key = {std::min(i, j), std::max(i, j)};
  const auto it = std::lower_bound(edge_vertices_.begin(), edge_vertices_.end(), key);
  return it != edge_vertices_.end() && *it == key ? static_cast<int>(it - edge_vertices_.begin())
                                                  : -1;
}

// K_vv = Σ_t K^t_(kk) and m_v = ρ Σ_t V_t / 4 over the remaining tetrahedra t
// around v (k the local index of v in t): summed afresh, never by subtraction.
void TensorMassModel::resum_vertex(int v) {
  Matrix3d k = Matrix3d::Zero();
  double volume_m3 = 0;
  int count = 0;
  for (int q = vertex_tets_begin_[v]; q < vertex_tets_begin_[v + 1]; ++q) {
    const int t = vertex_tets_[q];
    if (tet_alive_[t] == 0) continue;
    const int a = local_index(tets_, t, v);
    k += element_k_[t].block<3, 3>(3 * a, 3 * a);
    volume_m3 += tet_volume_m3_[t];
    ++count;
  }
  vertex_tensor_[v] = k;
  mass_kg_[v] = density_kg_m3_ * volume_m3 / 4;
  vertex_tet_count_[v] = count;
}

// K_ij = Σ_t K^t_(ab) over the remaining tetrahedra sharing the edge; an edge
// none uses leaves the compact list the force pass reads.
void TensorMassModel::resum_edge(int edge) {
  const auto [i, j] = edge_vertices_[edge];
  Matrix3d k = Matrix3d::Zero();
  int count = 0;
  for (int q = edge_tets_begin_[edge]; q < edge_tets_begin_[edge + 1]; ++q) {
    const int t = edge_tets_[q];
    if (tet_alive_[t] == 0) continue;
    k += element_k_[t].block<3, 3>(3 * local_index(tets_, t, i), 3 * local_index(tets_, t, j));
    ++count;
  }
  edge_tet_count_[edge] = count;
  const int slot = edge_slot_[edge];
  if (count > 0) {
    live_edges_[slot].k_ij = k;
    return;
  }
  const int last = static_cast<int>(live_edges_.size()) - 1;
  live_edges_[slot] = live_edges_[last];
  live_edge_id_[slot] = live_edge_id_[last];
  edge_slot_[live_edge_id_[slot]] = slot;
  live_edges_.pop_back();
  live_edge_id_.pop_back();
  edge_slot_[edge] = -1;
}

void TensorMassModel::add_boundary_face(int face, int tet) {
  int k = 0;
  while (tet_faces_[tet][k] != face) ++k;
  face_slot_[face] = static_cast<int>(boundary_.size());
  boundary_.push_back({tets_(tet, kFaceOpposite[k][0]), tets_(tet, kFaceOpposite[k][1]),
                       tets_(tet, kFaceOpposite[k][2])});
  boundary_face_id_.push_back(face);
}

void TensorMassModel::drop_boundary_face(int face) {
  const int slot = face_slot_[face];
  boundary_[slot] = boundary_.back();
  boundary_face_id_[slot] = boundary_face_id_.back();
  face_slot_[boundary_face_id_[slot]] = slot;
  boundary_.pop_back();
  boundary_face_id_.pop_back();
  face_slot_[face] = -1;
}

std::vector<std::array<int, 2>> TensorMassModel::edges() const {
  std::vector<std::array<int, 2>> out;
  out.reserve(live_edges_.size());
  for (const auto& e : live_edges_) out.push_back({e.i, e.j});
  return out;
}

bool TensorMassModel::edge_tensor(int i, int j, Eigen::Matrix3d& k_ij) const {
  const int e = find_edge(i, j);
  if (e < 0 || edge_slot_[e] < 0) return false;
  const Matrix3d& k = live_edges_[edge_slot_[e]].k_ij;
  k_ij = i < j ? k : Matrix3d(k.transpose());
  return true;
}

int TensorMassModel::tetrahedra_at_edge(int i, int j) const {
  const int e = find_edge(i, j);
  return e < 0 ? 0 : edge_tet_count_[e];
}

void TensorMassModel::remove_tetrahedron(int tet) {
  if (tet < 0 || tet >= tetrahedron_count())
    throw InputError(fmt::format("{}: tetrahedron {} does not exist; indices 0..{} are accepted",
                                 kTensorMassCutWhat, tet, tetrahedron_count() - 1));
  if (tet_alive_[tet] == 0)
    throw InputError(
        fmt::format("{}: tetrahedron {} is already removed; a remaining tetrahedron "
                    "is accepted",
                    kTensorMassCutWhat, tet));
  tet_alive_[tet] = 0;
  --remaining_tets_;
  for (int k = 0; k < 4; ++k) resum_vertex(tets_(tet, k));
  for (int e : tet_edges_[tet]) resum_edge(e);
  for (int face : tet_faces_[tet]) {
    if (face_slot_[face] >= 0) {
      drop_boundary_face(face);  // it was the region's skin: now no tetrahedron has it
    } else {
      const auto& two = face_tets_[face];
      add_boundary_face(face, two[0] == tet ? two[1] : two[0]);  // the cut exposes it
    }
  }
  ++boundary_version_;
}

// Faces shared by two remaining tetrahedra join them; a search from each
// tetrahedron not yet labelled labels its part.
std::vector<int> TensorMassModel::part_labels() const {
  const int nt = tetrahedron_count();
  std::vector<int> label(nt, -1), stack;
  int parts = 0;
  for (int seed = 0; seed < nt; ++seed) {
    if (tet_alive_[seed] == 0 || label[seed] >= 0) continue;
    label[seed] = parts;
    stack.push_back(seed);
    while (!stack.empty()) {
      const int t = stack.back();
      stack.pop_back();
      for (const int face : tet_faces_[t]) {
        const auto& two = face_tets_[face];
        const int other = two[0] == t ? two[1] : two[0];
        if (other >= 0 && tet_alive_[other] != 0 && label[other] < 0) {
          label[other] = parts;
          stack.push_back(other);
        }
      }
    }
    ++parts;
  }
  return label;
}

int TensorMassModel::connected_parts() const {
  const std::vector<int> label = part_labels();
  return label.empty() ? 0 : *std::max_element(label.begin(), label.end()) + 1;
}

}  // namespace palpate
