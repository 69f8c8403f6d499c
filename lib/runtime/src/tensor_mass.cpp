#include "palpate/runtime/tensor_mass.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"

namespace palpate {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr const char* kWhat = "tensor-mass region";

/// The face opposite local vertex k, ordered so that (b − a) × (c − a) points
/// out of a positively oriented tetrahedron.
constexpr std::array<std::array<int, 3>, 4> kFaceOpposite = {
    {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}};
/// The six edges as pairs of local vertices.
constexpr std::array<std::array<int, 2>, 6> kLocalEdges = {
    {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}}};

Vector3d row(const Eigen::MatrixX3d& m, int r) { return m.row(r).transpose(); }

double tet_volume(const Eigen::MatrixX3d& x, const Eigen::MatrixX4i& t, int tet) {
  const Vector3d p0 = row(x, t(tet, 0));
  return (row(x, t(tet, 1)) - p0).dot((row(x, t(tet, 2)) - p0).cross(row(x, t(tet, 3)) - p0)) / 6.0;
}

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

TensorMassModel::TensorMassModel(CRef<Eigen::MatrixX3d> rest_positions_m,
                                 CRef<Eigen::MatrixX4i> tetrahedra,
                                 const std::vector<Matrix12d>& element_stiffness_n_per_m,
                                 const TensorMassMaterial& material,
                                 const std::vector<int>& fixed_vertices)
    : rest_m_(rest_positions_m), tets_(tetrahedra), element_k_(element_stiffness_n_per_m) {
  const int nv = static_cast<int>(rest_m_.rows());
  const int nt = static_cast<int>(tets_.rows());
  if (!(material.density_kg_m3 > 0) || !std::isfinite(material.density_kg_m3))
    throw InputError(
        fmt::format("{}: density {} kg/m³; a finite density > 0 is accepted "
                    "(soft tissue: about 1060 kg/m³)",
                    kWhat, material.density_kg_m3));
  if (!(material.mass_damping_per_s >= 0) || !std::isfinite(material.mass_damping_per_s))
    throw InputError(fmt::format("{}: mass damping γ = {} 1/s; a finite γ ≥ 0 is accepted", kWhat,
                                 material.mass_damping_per_s));
  density_kg_m3_ = material.density_kg_m3;
  damping_per_s_ = material.mass_damping_per_s;
  for (int v = 0; v < nv; ++v)
    if (!rest_m_.row(v).allFinite())
      throw InputError(
          fmt::format("{}: vertex {} has a non-finite rest position ({}, {}, {}) m; "
                      "finite coordinates in metres are accepted",
                      kWhat, v, rest_m_(v, 0), rest_m_(v, 1), rest_m_(v, 2)));
  if (static_cast<int>(element_k_.size()) != nt)
    throw InputError(
        fmt::format("{}: {} element stiffnesses for {} tetrahedra; one 12 × 12 "
                    "matrix per tetrahedron is accepted",
                    kWhat, element_k_.size(), nt));
  tet_volume_m3_.resize(nt);
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k)
      if (tets_(t, k) < 0 || tets_(t, k) >= nv)
        throw InputError(
            fmt::format("{}: tetrahedron {} has vertex index {}; indices 0..{} "
                        "(the rows of the rest positions) are accepted",
                        kWhat, t, tets_(t, k), nv - 1));
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        if (tets_(t, a) == tets_(t, b))
          throw InputError(
              fmt::format("{}: tetrahedron {} uses vertex {} twice; four distinct "
                          "vertices are accepted",
                          kWhat, t, tets_(t, a)));
    tet_volume_m3_[t] = tet_volume(rest_m_, tets_, t);
    if (!(tet_volume_m3_[t] > 0))
      throw InputError(fmt::format(
          "{}: tetrahedron {} (vertices {}, {}, {}, {}) has volume {} m³; "
          "positively oriented tetrahedra (volume > 0) are accepted",
          kWhat, t, tets_(t, 0), tets_(t, 1), tets_(t, 2), tets_(t, 3), tet_volume_m3_[t]));
    const Matrix12d& k = element_k_[t];
    if (!k.allFinite())
      throw InputError(
          fmt::format("{}: the element stiffness of tetrahedron {} has a non-finite "
                      "entry; finite values in N/m are accepted",
                      kWhat, t));
    // Round-off of the element formula is ~10⁻¹⁶ of its largest entry.
    const double asymmetry = (k - k.transpose()).cwiseAbs().maxCoeff();
    if (asymmetry > 1e-10 * k.cwiseAbs().maxCoeff())
      throw InputError(
          fmt::format("{}: the element stiffness of tetrahedron {} is not symmetric "
                      "(|K − Kᵀ| up to {:.3g} of its largest entry {:.3g} N/m); "
                      "symmetric to 1e-10 relative is accepted",
                      kWhat, t, asymmetry / k.cwiseAbs().maxCoeff(), k.cwiseAbs().maxCoeff()));
  }
  fixed_.assign(nv, 0);
  for (int v : fixed_vertices) {
    if (v < 0 || v >= nv)
      throw InputError(fmt::format("{}: fixed vertex {} does not exist; indices 0..{} are accepted",
                                   kWhat, v, nv - 1));
    if (fixed_[v] != 0)
      throw InputError(
          fmt::format("{}: fixed vertex {} is listed twice; distinct vertices are "
                      "accepted",
                      kWhat, v));
    fixed_[v] = 1;
  }

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
      throw InputError(fmt::format(
          "{}: the face ({}, {}, {}) belongs to tetrahedra {}, {} and {}; "
          "a face of at most two tetrahedra is accepted",
          kWhat, key[0], key[1], key[2], face_tets_.back()[0], face_tets_.back()[1], key[3]));
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

  u_ = Eigen::VectorXd::Zero(3 * nv);
  u_previous_ = u_;
  force_ = u_;
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

// (K u)_i = K_ii u_i + Σ_j K_ij u_j: one pass over the vertices, one over the
// edges, each edge giving K_ij u_j to i and K_ijᵀ u_i to j.
void TensorMassModel::add_stiffness_product(CRef<Eigen::VectorXd> u,
                                            Eigen::Ref<Eigen::VectorXd> out, double sign) const {
  PALPATE_DEMAND(u.size() == 3 * vertex_count() && out.size() == 3 * vertex_count());
  const double* x = u.data();
  double* y = out.data();
  const int nv = vertex_count();
  for (int v = 0; v < nv; ++v)
    Eigen::Map<Vector3d>(y + 3 * v) +=
        sign * (vertex_tensor_[v] * Eigen::Map<const Vector3d>(x + 3 * v));
  for (const LiveEdge& e : live_edges_) {
    Eigen::Map<Vector3d>(y + 3 * e.i) += sign * (e.k_ij * Eigen::Map<const Vector3d>(x + 3 * e.j));
    Eigen::Map<Vector3d>(y + 3 * e.j) +=
        sign * (e.k_ij.transpose() * Eigen::Map<const Vector3d>(x + 3 * e.i));
  }
}

void TensorMassModel::apply_stiffness(CRef<Eigen::VectorXd> u_m,
                                      Eigen::Ref<Eigen::VectorXd> ku_n) const {
  ku_n.setZero();
  add_stiffness_product(u_m, ku_n, 1.0);
}

void TensorMassModel::internal_force(CRef<Eigen::VectorXd> u_m,
                                     Eigen::Ref<Eigen::VectorXd> f_n) const {
  f_n.setZero();
  add_stiffness_product(u_m, f_n, -1.0);
}

void TensorMassModel::set_interface_coupling(const std::vector<int>& interface_vertices,
                                             CRef<Eigen::MatrixXd> stiffness_n_per_m) {
  const int nv = vertex_count();
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(interface_vertices.size());
  std::vector<char> seen(nv, 0);
  for (int v : interface_vertices) {
    if (v < 0 || v >= nv)
      throw InputError(
          fmt::format("{}: interface vertex {} does not exist; indices 0..{} are "
                      "accepted",
                      kWhat, v, nv - 1));
    if (seen[v] != 0)
      throw InputError(
          fmt::format("{}: interface vertex {} is listed twice; distinct vertices are "
                      "accepted",
                      kWhat, v));
    if (fixed_[v] != 0)
      throw InputError(
          fmt::format("{}: interface vertex {} is fixed; an interface vertex must be "
                      "free (the rest of the organ holds it through S)",
                      kWhat, v));
    seen[v] = 1;
  }
  if (stiffness_n_per_m.rows() != n || stiffness_n_per_m.cols() != n)
    throw InputError(
        fmt::format("{}: the interface stiffness S is {} × {} for {} interface "
                    "vertices; 3n × 3n = {} × {} is accepted",
                    kWhat, stiffness_n_per_m.rows(), stiffness_n_per_m.cols(),
                    interface_vertices.size(), n, n));
  if (!stiffness_n_per_m.allFinite())
    throw InputError(
        fmt::format("{}: the interface stiffness S has a non-finite entry; finite "
                    "values in N/m are accepted",
                    kWhat));
  if (n > 0) {
    const double largest = stiffness_n_per_m.cwiseAbs().maxCoeff();
    const double asymmetry =
        (stiffness_n_per_m - stiffness_n_per_m.transpose()).cwiseAbs().maxCoeff();
    if (asymmetry > 1e-10 * largest)
      throw InputError(
          fmt::format("{}: the interface stiffness S is not symmetric (|S − Sᵀ| up to "
                      "{:.3g} of its largest entry); symmetric to 1e-10 relative is "
                      "accepted",
                      kWhat, asymmetry / largest));
    // An indefinite S would feed energy in: the explicit step would diverge
    // whatever Δt. The tolerance is the eigensolver's round-off.
    const double least =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(stiffness_n_per_m, Eigen::EigenvaluesOnly)
            .eigenvalues()
            .minCoeff();
    if (least < -1e-10 * largest * static_cast<double>(n))
      throw InputError(
          fmt::format("{}: the interface stiffness S has the eigenvalue {:.6g} N/m; "
                      "a positive semi-definite S is accepted",
                      kWhat, least));
  }
  interface_ = interface_vertices;
  coupling_ = stiffness_n_per_m;
  offset_m_ = Eigen::VectorXd::Zero(n);
  gap_m_ = offset_m_;
  coupling_force_n_ = offset_m_;
}

void TensorMassModel::set_interface_offset(CRef<Eigen::VectorXd> offset_m) {
  PALPATE_DEMAND(offset_m.size() == offset_m_.size());
  offset_m_ = offset_m;
}

void TensorMassModel::add_coupling_force(CRef<Eigen::VectorXd> u_m,
                                         Eigen::Ref<Eigen::VectorXd> f_n) {
  if (interface_.empty()) return;
  const int n = static_cast<int>(interface_.size());
  for (int k = 0; k < n; ++k) gap_m_.segment<3>(3 * k) = u_m.segment<3>(3 * interface_[k]);
  gap_m_ -= offset_m_;
  coupling_force_n_.noalias() = coupling_ * gap_m_;
  for (int k = 0; k < n; ++k)
    f_n.segment<3>(3 * interface_[k]) -= coupling_force_n_.segment<3>(3 * k);
}

void TensorMassModel::step(double time_step_s, CRef<Eigen::VectorXd> external_force_n) {
  PALPATE_DEMAND(time_step_s > 0 && external_force_n.size() == u_.size());
  force_ = external_force_n;
  add_stiffness_product(u_, force_, -1.0);
  add_coupling_force(u_, force_);
  // m (u⁺ − 2u + u⁻)/Δt² + γ m (u⁺ − u⁻)/(2Δt) = f, solved for u⁺ per vertex.
  const double c0 = 1 / (time_step_s * time_step_s), c1 = damping_per_s_ / (2 * time_step_s);
  const double inv = 1 / (c0 + c1);
  const int nv = vertex_count();
  for (int v = 0; v < nv; ++v) {
    auto u = u_.segment<3>(3 * v);
    auto u_prev = u_previous_.segment<3>(3 * v);
    if (fixed_[v] != 0 || vertex_tet_count_[v] == 0) {
      u_prev = u;  // held: fixed at zero, detached where the cut left it
      continue;
    }
    const Vector3d next =
        inv * (force_.segment<3>(3 * v) / mass_kg_[v] + 2 * c0 * u - (c0 - c1) * u_prev);
    u_prev = u;
    u = next;
  }
}

void TensorMassModel::set_state(CRef<Eigen::VectorXd> u_m, CRef<Eigen::VectorXd> u_previous_m) {
  if (u_m.size() != u_.size() || u_previous_m.size() != u_.size())
    throw InputError(fmt::format("{}: a state of sizes {} and {}; 3 × {} vertices = {} is accepted",
                                 kWhat, u_m.size(), u_previous_m.size(), vertex_count(),
                                 u_.size()));
  u_ = u_m;
  u_previous_ = u_previous_m;
  for (int v = 0; v < vertex_count(); ++v)
    if (fixed_[v] != 0) {
      u_.segment<3>(3 * v).setZero();
      u_previous_.segment<3>(3 * v).setZero();
    }
}

StableTimeStep TensorMassModel::stable_time_step(double tolerance, int max_iterations) const {
  const int nv = vertex_count();
  // M^-1/2 on the moving DOFs, zero elsewhere: the operator
  // A = M^-1/2 (K + S) M^-1/2 restricted to them is symmetric, with the
  // eigenvalues ω² of M⁻¹ (K + S).
  Eigen::VectorXd scale = Eigen::VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v)
    if (fixed_[v] == 0 && vertex_tet_count_[v] > 0)
      scale.segment<3>(3 * v).setConstant(1 / std::sqrt(mass_kg_[v]));
  const auto apply = [&](const Eigen::VectorXd& y, Eigen::VectorXd& z) {
    const Eigen::VectorXd w = scale.cwiseProduct(y);
    apply_stiffness(w, z);
    if (!interface_.empty()) {
      Eigen::VectorXd g(3 * interface_.size());
      for (std::size_t k = 0; k < interface_.size(); ++k)
        g.segment<3>(3 * k) = w.segment<3>(3 * interface_[k]);
      const Eigen::VectorXd sg = coupling_ * g;
      for (std::size_t k = 0; k < interface_.size(); ++k)
        z.segment<3>(3 * interface_[k]) += sg.segment<3>(3 * k);
    }
    z = scale.cwiseProduct(z);
  };

  StableTimeStep out;
  // A fixed start with no symmetry of the mesh (so not orthogonal to the
  // top mode in practice): a linear congruential sequence in (0.5, 1.5).
  Eigen::VectorXd y(3 * nv), z(3 * nv);
  std::uint64_t state = 0x9e3779b97f4a7c15ULL;
  for (Eigen::Index i = 0; i < y.size(); ++i) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    y[i] = (scale[i] != 0) ? 0.5 + static_cast<double>(state >> 11) * 0x1.0p-53 : 0.0;
  }
  if (y.norm() == 0) return out;  // nothing moves
  y.normalize();
  double rho = 0;
  for (out.iterations = 1; out.iterations <= max_iterations; ++out.iterations) {
    apply(y, z);
    rho = y.dot(z);  // Rayleigh quotient, ‖y‖ = 1
    out.relative_residual = rho > 0 ? (z - rho * y).norm() / rho : 0;
    if (rho <= 0 || out.relative_residual <= tolerance) {
      out.converged = true;
      break;
    }
    y = z / z.norm();
  }
  out.iterations = std::min(out.iterations, max_iterations);
  out.omega_max_rad_s = std::sqrt(std::max(rho, 0.0));

  // Gershgorin on M⁻¹ (K + S), moving rows and columns only.
  Eigen::VectorXd row_sum = Eigen::VectorXd::Zero(3 * nv);
  const auto moving = [&](int v) { return scale[3 * v] != 0; };
  for (int v = 0; v < nv; ++v)
    if (moving(v)) row_sum.segment<3>(3 * v) += vertex_tensor_[v].cwiseAbs().rowwise().sum();
  for (const LiveEdge& e : live_edges_) {
    if (moving(e.i) && moving(e.j)) {
      row_sum.segment<3>(3 * e.i) += e.k_ij.cwiseAbs().rowwise().sum();
      row_sum.segment<3>(3 * e.j) += e.k_ij.cwiseAbs().colwise().sum().transpose();
    }
  }
  for (std::size_t a = 0; a < interface_.size(); ++a)
    for (std::size_t b = 0; b < interface_.size(); ++b)
      if (moving(interface_[a]) && moving(interface_[b]))
        row_sum.segment<3>(3 * interface_[a]) +=
            coupling_.block<3, 3>(3 * a, 3 * b).cwiseAbs().rowwise().sum();
  double bound = 0;
  for (int v = 0; v < nv; ++v)
    if (moving(v)) bound = std::max(bound, row_sum.segment<3>(3 * v).maxCoeff() / mass_kg_[v]);
  out.gershgorin_omega_rad_s = std::sqrt(bound);

  const double inf = std::numeric_limits<double>::infinity();
  out.critical_time_step_s = out.omega_max_rad_s > 0 ? 2 / out.omega_max_rad_s : inf;
  out.gershgorin_time_step_s = bound > 0 ? 2 / out.gershgorin_omega_rad_s : inf;
  return out;
}

void TensorMassModel::remove_tetrahedron(int tet) {
  if (tet < 0 || tet >= tetrahedron_count())
    throw InputError(fmt::format("{}: tetrahedron {} does not exist; indices 0..{} are accepted",
                                 kWhat, tet, tetrahedron_count() - 1));
  if (tet_alive_[tet] == 0)
    throw InputError(
        fmt::format("{}: tetrahedron {} is already removed; a remaining tetrahedron "
                    "is accepted",
                    kWhat, tet));
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

// Cyrus–Beck: the segment x(s) = a + s (b − a), s ∈ [0, 1], is inside the
// tetrahedron where n_f·(x(s) − p_f) ≤ 0 for its four outward face normals.
std::vector<int> TensorMassModel::tetrahedra_crossed_by_segment(const Eigen::Vector3d& a_m,
                                                                const Eigen::Vector3d& b_m) const {
  std::vector<int> out;
  const Vector3d d = b_m - a_m;
  for (int t = 0; t < tetrahedron_count(); ++t) {
    if (tet_alive_[t] == 0) continue;
    double lo = 0, hi = 1;
    for (int k = 0; k < 4 && lo <= hi; ++k) {
      const Vector3d p = row(rest_m_, tets_(t, kFaceOpposite[k][0]));
      const Vector3d n = (row(rest_m_, tets_(t, kFaceOpposite[k][1])) - p)
                             .cross(row(rest_m_, tets_(t, kFaceOpposite[k][2])) - p);
      // Touching counts: a tolerance of round-off relative to the sizes.
      const double slack = 1e-12 * n.norm() * (d.norm() + (a_m - p).norm());
      const double start = n.dot(a_m - p), rate = n.dot(d);
      if (std::abs(rate) <= 1e-300) {
        if (start > slack) hi = -1;
      } else if (rate > 0) {
        hi = std::min(hi, (slack - start) / rate);
      } else {
        lo = std::max(lo, (slack - start) / rate);
      }
    }
    if (lo <= hi) out.push_back(t);
  }
  return out;
}

}  // namespace palpate
