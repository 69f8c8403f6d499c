#include "palpate/runtime/contact/deformed_surface.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>

#include "palpate/runtime/drawn_surface.hpp"

namespace palpate::detail {

using Eigen::Matrix3d;
using Eigen::Vector3d;

DeformedSurface::DeformedSurface(const SurfaceModel& model, const RotationField* warping)
    : model_(model), warping_(warping) {
  const DrawnSurface& surface = model.surface;
  compliance_count_ = model.compliance_vertex_count();
  const int n = compliance_count_;
  const int drawn = surface.vertex_count();
  const int triangles = surface.triangle_count();
  rest_.resize(static_cast<std::size_t>(drawn));
  box_min_ = Vector3d::Constant(std::numeric_limits<double>::infinity());
  box_max_ = -box_min_;
  for (int v = 0; v < drawn; ++v) {
    rest_[static_cast<std::size_t>(v)] = surface.rest_position(v);
    box_min_ = box_min_.cwiseMin(rest_[static_cast<std::size_t>(v)]);
    box_max_ = box_max_.cwiseMax(rest_[static_cast<std::size_t>(v)]);
  }
  // A vertex without a normal (in no triangle of non-zero area) pushes along z.
  vertex_normal_.resize(static_cast<std::size_t>(n));
  const Eigen::MatrixX3d surface_normals = vertex_normals(surface);
  for (int v = 0; v < n; ++v)
    vertex_normal_[static_cast<std::size_t>(v)] = surface_normals.row(v).squaredNorm() > 0
                                                      ? Vector3d(surface_normals.row(v).transpose())
                                                      : Vector3d::UnitZ();
  // Triangles around each drawn vertex (compressed rows).
  triangle_vertices_.assign(surface.triangles.begin(), surface.triangles.end());
  vertex_triangles_begin_.assign(static_cast<std::size_t>(drawn) + 1, 0);
  for (const int v : triangle_vertices_) ++vertex_triangles_begin_[static_cast<std::size_t>(v) + 1];
  for (int v = 0; v < drawn; ++v)
    vertex_triangles_begin_[static_cast<std::size_t>(v) + 1] +=
        vertex_triangles_begin_[static_cast<std::size_t>(v)];
  vertex_triangles_.resize(triangle_vertices_.size());
  std::vector<int> fill(vertex_triangles_begin_.begin(), vertex_triangles_begin_.end() - 1);
  for (int tri = 0; tri < triangles; ++tri)
    for (int c = 0; c < 3; ++c)
      vertex_triangles_[static_cast<std::size_t>(
          fill[static_cast<std::size_t>(triangle_vertices_[3 * static_cast<std::size_t>(tri) +
                                                           static_cast<std::size_t>(c)])]++)] = tri;
  // Each triangle's ball at rest and the largest √‖G^{vv}‖ of its
  // compliance vertices (far_from).
  triangle_centre_.resize(static_cast<std::size_t>(triangles));
  triangle_radius_.resize(static_cast<std::size_t>(triangles));
  triangle_softness_.assign(static_cast<std::size_t>(triangles), 0.0);
  double edges_m = 0;
  for (int tri = 0; tri < triangles; ++tri) {
    const auto tt = static_cast<std::size_t>(tri);
    const int* corner = corners(tri);
    Vector3d centre = Vector3d::Zero();
    for (int i = 0; i < 3; ++i) centre += rest(corner[i]) / 3;
    double radius2 = 0;
    for (int i = 0; i < 3; ++i) {
      radius2 = std::max(radius2, (rest(corner[i]) - centre).squaredNorm());
      if (corner[i] < n)
        triangle_softness_[tt] =
            std::max(triangle_softness_[tt], std::sqrt(model.G_block(corner[i], corner[i]).norm()));
      edges_m += (rest(corner[i]) - rest(corner[(i + 1) % 3])).norm();
    }
    triangle_centre_[tt] = centre;
    triangle_radius_[tt] = std::sqrt(radius2);
    max_softness_ = std::max(max_softness_, triangle_softness_[tt]);
  }
  grid_ = VertexGrid(rest_, triangles > 0 ? 1.5 * edges_m / (3.0 * triangles) : 0.0);
  position_.resize(static_cast<std::size_t>(drawn));
  position_seen_.assign(static_cast<std::size_t>(drawn), 0);
  near_vertices_.resize(static_cast<std::size_t>(drawn));
  near_bits_.assign((static_cast<std::size_t>(drawn) + 63) / 64, 0);
  triangle_seen_.assign(static_cast<std::size_t>(triangles), 0);
  triangle_hidden_.assign(static_cast<std::size_t>(triangles), 0);
  near_triangles_.resize(static_cast<std::size_t>(triangles));
  wanted_bits_.assign((static_cast<std::size_t>(n) + 63) / 64, 0);
  wanted_.resize(static_cast<std::size_t>(n));
  wanted_u_.resize(static_cast<std::size_t>(n));
  if (warping_ != nullptr) {
    PALPATE_DEMAND(warping_->vertex_count() == n);
    rotations_.emplace(*warping_, n);
  }
}

Vector3d DeformedSurface::vertex_normal_of(const int* corner) const {
  for (int i = 0; i < 3; ++i)
    if (corner[i] < compliance_count_) return vertex_normal_[static_cast<std::size_t>(corner[i])];
  return Vector3d::UnitZ();
}

void DeformedSurface::set_loads(int count, const int* index, const double* force, double energy) {
  load_count_ = count;
  load_index_ = index;
  load_force_ = force;
  load_energy_ = energy;
}

void DeformedSurface::next_epoch() {
  if (++epoch_ == 0) {
    std::fill(position_seen_.begin(), position_seen_.end(), 0);
    epoch_ = 1;
  }
  if (rotations_) rotations_->next_epoch();
}

Vector3d DeformedSurface::load_displacement(int v) const {
  Vector3d u = Vector3d::Zero();
  for (int l = 0; l < load_count_; ++l)
    u.noalias() += model_.G_block(v, load_index_[l]) *
                   Eigen::Map<const Vector3d>(&load_force_[3 * static_cast<std::size_t>(l)]);
  return u;
}

const Vector3d& DeformedSurface::rotation_vector(int v) {
  return rotations_->rotation(v, [this](int j) { return load_displacement(j); });
}

const Vector3d& DeformedSurface::deformed(int v) {
  const auto vv = static_cast<std::size_t>(v);
  if (position_seen_[vv] == epoch_) return position_[vv];
  position_seen_[vv] = epoch_;
  if (v >= compliance_count_)
    position_[vv] = rest_[vv];
  else if (warping_ == nullptr)
    position_[vv] = rest_[vv] + (background_ != nullptr && background_->count() > 0
                                     ? Vector3d(load_displacement(v) + background_->at(v))
                                     : load_displacement(v));
  else
    position_[vv] =
        rest_[vv] + integrated_rotation(rotation_vector(v)) *
                        rotations_->material(v, [this](int j) { return load_displacement(j); });
  return position_[vv];
}

// G^{v l} for one load l and every vertex v lies in G's three columns of l,
// read downwards with the vertices in ascending order, where deformed()
// alone reads three columns per vertex and load: a wide tip meets hundreds
// of vertices under tens of loads (docs/benchmarks-history.md, "The wide tick").
void DeformedSurface::deform_corners(std::span<const int> triangles) {
  if (warping_ != nullptr) return;
  int wanted_count = 0;
  for (const int tri : triangles)
    for (int i = 0; i < 3; ++i) {
      const int v = corners(tri)[i];
      if (v >= compliance_count_ || position_seen_[static_cast<std::size_t>(v)] == epoch_) continue;
      std::uint64_t& word = wanted_bits_[static_cast<std::size_t>(v) / 64];
      const std::uint64_t bit = std::uint64_t{1} << (v % 64);
      if ((word & bit) == 0) ++wanted_count;
      word |= bit;
    }
  if (wanted_count == 0) return;
  int k = 0;
  for (std::size_t w = 0; w < wanted_bits_.size(); ++w) {
    for (std::uint64_t word = wanted_bits_[w]; word != 0; word &= word - 1)
      wanted_[static_cast<std::size_t>(k++)] = static_cast<int>(64 * w) + std::countr_zero(word);
    wanted_bits_[w] = 0;
  }
  const auto wanted_n = static_cast<std::size_t>(k);
  for (std::size_t j = 0; j < wanted_n; ++j) wanted_u_[j].setZero();
  for (int l = 0; l < load_count_; ++l) {
    const int a = load_index_[l];
    const Vector3d f = Eigen::Map<const Vector3d>(&load_force_[3 * static_cast<std::size_t>(l)]);
    if (model_.float32()) {
      for (std::size_t j = 0; j < wanted_n; ++j)
        wanted_u_[j].noalias() += model_.G_block(wanted_[j], a) * f;
      continue;
    }
    // G's three columns of load a, from its row 0.
    const Eigen::Index ld = model_.G.rows();
    const double* columns = model_.G.data() + 3 * a * ld;
    Vector3d* u = wanted_u_.data();
    const int* v = wanted_.data();
    for (std::size_t j = 0; j < wanted_n; ++j)
      u[j].noalias() += Eigen::Map<const Matrix3d, 0, Eigen::OuterStride<>>(
                            columns + 3 * v[j], 3, 3, Eigen::OuterStride<>(ld)) *
                        f;
  }
  if (background_ != nullptr && background_->count() > 0)
    for (std::size_t j = 0; j < wanted_n; ++j) wanted_u_[j] += background_->at(wanted_[j]);
  for (std::size_t j = 0; j < wanted_n; ++j) {
    const auto v = static_cast<std::size_t>(wanted_[j]);
    position_[v] = rest_[v] + wanted_u_[j];
    position_seen_[v] = epoch_;
  }
}

double DeformedSurface::spread() const {
  return (1 + 1e-6) * std::sqrt(std::max(load_energy_, 0.0));
}

// A vertex's displacement is bounded by the loads' energy: for a unit e,
// eᵀ u_v = eᵀ G_{v·} f ≤ √(eᵀ G^{vv} e) √(fᵀ G f) (Cauchy–Schwarz in the
// inner product of G, symmetric positive definite), so
// |u_v| ≤ √(‖G^{vv}‖ fᵀ G f), and a point of the triangle moves no farther
// than its corners' largest bound. The margins (1e-6 relative, and 1e-6 of
// the reach) are far above round-off and G's asymmetry (1e-15): nothing the
// closest points would find near is dropped. Linear model only (the warped
// one meets its vertices' rotations in the order deformed() asks for them).
//
// The background's u_b adds to that bound. Where every compliance corner
// has a last known u_b (BackgroundLoads::last_known), the triangle is
// moved by their mean ū: a corner is then within the rest radius plus
// |u_i − ū| of the moved centre, and each has drifted since by at most
// √‖G^{vv}‖ times its drift; else it is bounded by its energy, as the
// loads' (the triangle inequality of the G-norm adds the two spreads).
// The known u_b carry the round-off of their sums (≪ 1e-6 of them).
bool DeformedSurface::far_from(int tri, const Vector3d& hinge, const Vector3d& axis, double length,
                               double reach, double spread) const {
  if (warping_ != nullptr) return false;
  const auto tt = static_cast<std::size_t>(tri);
  const Vector3d& c = triangle_centre_[tt];
  const double beyond = (1 + 1e-6) * reach + triangle_radius_[tt] + triangle_softness_[tt] * spread;
  const auto far = [&](const Vector3d& centre, double distance) {
    return (centre - closest_on_segment(hinge, axis, length, centre)).squaredNorm() >=
           distance * distance;
  };
  if (background_ == nullptr || background_->count() == 0) return far(c, beyond);
  // Either bound suffices: the energy's, from the triangle at rest, or the
  // last known u_b's, from the moved triangle.
  if (far(c, beyond + triangle_softness_[tt] * background_->spread())) return true;
  const int* corner = corners(tri);
  std::array<const Vector3d*, 3> u{};
  const Vector3d zero = Vector3d::Zero();
  double drift = 0;
  for (int i = 0; i < 3; ++i) {
    const auto ii = static_cast<std::size_t>(i);
    double d = 0;
    if (corner[i] >= compliance_count_)
      u[ii] = &zero;
    else if (!background_->last_known(corner[i], u[ii], d))
      return false;  // never computed: the energy's bound is all there is
    drift = std::max(drift, d);
  }
  const Vector3d mean = (*u[0] + *u[1] + *u[2]) / 3;
  double apart = 0, largest = 0;
  for (const Vector3d* ui : u) {
    apart = std::max(apart, (*ui - mean).norm());
    largest = std::max(largest, ui->norm());
  }
  return far(c + mean,
             beyond + apart + 1e-6 * largest + (1 + 1e-6) * triangle_softness_[tt] * drift);
}

std::span<const int> DeformedSurface::vertices_near(const Vector3d& hinge, const Vector3d& axis,
                                                    double length, double radius) {
  const double radius2 = radius * radius;
  const auto near = [&](const Vector3d& x) {
    return (x - closest_on_segment(hinge, axis, length, x)).squaredNorm() <= radius2;
  };
  std::size_t n = 0;
  const int vertices = static_cast<int>(rest_.size());
  // The grid's cells that the box around the segment (plus the radius and
  // a margin far above the round-off of the test) overlaps: a vertex
  // outside them is farther than the radius in one coordinate. Their
  // vertices are tested, marked, and taken in the order of the scan of
  // every vertex; a box over half the grid is the scan.
  const Vector3d end = hinge + length * axis;
  const Vector3d reach = Vector3d::Constant(radius * (1 + 1e-6));
  const std::array<int, 3> lo = grid_.cell_of(hinge.cwiseMin(end) - reach);
  const std::array<int, 3> hi = grid_.cell_of(hinge.cwiseMax(end) + reach);
  const std::int64_t cells =
      std::int64_t{hi[0] - lo[0] + 1} * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
  if (!(2 * cells < grid_.cell_count())) {
    for (int j = 0; j < vertices; ++j)
      if (near(rest_[static_cast<std::size_t>(j)])) near_vertices_[n++] = j;
    return {near_vertices_.data(), n};
  }
  for (int z = lo[2]; z <= hi[2]; ++z)
    for (int y = lo[1]; y <= hi[1]; ++y)
      for (int x = lo[0]; x <= hi[0]; ++x)
        for (const int j : grid_.vertices_in({x, y, z}))
          if (near(rest_[static_cast<std::size_t>(j)]))
            near_bits_[static_cast<std::size_t>(j) / 64] |= std::uint64_t{1} << (j % 64);
  for (std::size_t w = 0; w < near_bits_.size(); ++w) {
    for (std::uint64_t word = near_bits_[w]; word != 0; word &= word - 1)
      near_vertices_[n++] = static_cast<int>(64 * w) + std::countr_zero(word);
    near_bits_[w] = 0;
  }
  return {near_vertices_.data(), n};
}

std::span<int> DeformedSurface::triangles_around(std::span<const int> vertices) {
  if (++triangle_epoch_ == 0) {
    std::fill(triangle_seen_.begin(), triangle_seen_.end(), 0);
    triangle_epoch_ = 1;
  }
  std::size_t count = 0;
  for (const int v : vertices)
    for (int e = vertex_triangles_begin_[static_cast<std::size_t>(v)];
         e < vertex_triangles_begin_[static_cast<std::size_t>(v) + 1]; ++e) {
      const int tri = vertex_triangles_[static_cast<std::size_t>(e)];
      if (triangle_seen_[static_cast<std::size_t>(tri)] == triangle_epoch_) continue;
      triangle_seen_[static_cast<std::size_t>(tri)] = triangle_epoch_;
      if (triangle_hidden_[static_cast<std::size_t>(tri)] == 0) near_triangles_[count++] = tri;
    }
  return {near_triangles_.data(), count};
}

}  // namespace palpate::detail
