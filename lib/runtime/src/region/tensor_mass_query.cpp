// The tensor-mass region's cut queries: which remaining tetrahedra a
// cutting blade meets, in the rest geometry (docs/model/tensor-mass.md, "The
// tensor-mass model: a cuttable region", "The swept blade"): the exact
// segment and triangle tests, and the spatial index (tet_grid.hpp) that
// gives them their candidates.

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "palpate/runtime/region/tet_grid.hpp"
#include "palpate/runtime/tensor_mass.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;

/// Touching counts: two sets closer than this fraction of the coordinates'
/// size (about 10⁴ round-offs) are taken to meet.
constexpr double kTouch = 1e-12;

/// The face opposite local vertex k of a tetrahedron (any orientation: the
/// tests below orient the normals themselves).
constexpr std::array<std::array<int, 3>, 4> kFaces = {{{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}}};
/// The six edges as pairs of local vertices.
constexpr std::array<std::array<int, 2>, 6> kEdges = {
    {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}}};

Vector3d corner(const Matrix43d& x, int k) { return x.row(k).transpose(); }

/// min and max of n · p over the points.
template <std::size_t N>
std::array<double, 2> projection(const Vector3d& n, const std::array<Vector3d, N>& points) {
  double lo = n.dot(points[0]), hi = lo;
  for (std::size_t i = 1; i < N; ++i) {
    const double s = n.dot(points[i]);
    lo = std::min(lo, s);
    hi = std::max(hi, s);
  }
  return {lo, hi};
}

/// Whether the triangle (points relative to a cube's centre, m) meets the
/// cube of half side @p half_m: the separating-axis test with the cube's
/// three axes, the triangle's normal and the nine cross products of its
/// edges with the axes (Akenine-Möller, "Fast 3D triangle-box overlap
/// testing", JGT 6(1), 2001). Exact in the sense that a separation found
/// is one; the callers enlarge the cube to cover round-off.
bool triangle_meets_cube(const std::array<Vector3d, 3>& tri, double half_m) {
  const auto separated = [&](const Vector3d& n) {
    const auto [lo, hi] = projection(n, tri);
    const double radius = half_m * n.cwiseAbs().sum();
    return lo > radius || hi < -radius;
  };
  for (int k = 0; k < 3; ++k)
    if (separated(Vector3d::Unit(k))) return false;
  const std::array<Vector3d, 3> edge = {tri[1] - tri[0], tri[2] - tri[1], tri[0] - tri[2]};
  if (separated(edge[0].cross(edge[1]))) return false;
  for (const Vector3d& e : edge)
    for (int k = 0; k < 3; ++k)
      if (separated(e.cross(Vector3d::Unit(k)))) return false;
  return true;
}

std::array<Vector3d, 3> relative(const Vector3d& p, const Vector3d& q, const Vector3d& r,
                                 const Vector3d& origin) {
  return {p - origin, q - origin, r - origin};
}

}  // namespace

// Cyrus–Beck: the segment x(s) = a + s (b − a), s ∈ [0, 1], is inside the
// tetrahedron where n_f·(x(s) − p_f) ≤ 0 for its four outward face normals.
bool segment_meets_tetrahedron(const Eigen::Vector3d& a_m, const Eigen::Vector3d& b_m,
                               const Matrix43d& corners_m) {
  if (!(a_m.allFinite() && b_m.allFinite() && corners_m.allFinite())) return false;
  const Vector3d d = b_m - a_m;
  double lo = 0, hi = 1;
  for (int k = 0; k < 4 && lo <= hi; ++k) {
    const Vector3d p = corner(corners_m, kFaces[k][0]);
    Vector3d n = (corner(corners_m, kFaces[k][1]) - p).cross(corner(corners_m, kFaces[k][2]) - p);
    if (n.dot(corner(corners_m, k) - p) > 0) n = -n;  // outward: away from the opposite vertex
    // Touching counts: a tolerance of round-off relative to the sizes.
    const double slack = kTouch * n.norm() * (d.norm() + (a_m - p).norm());
    const double start = n.dot(a_m - p), rate = n.dot(d);
    if (std::abs(rate) <= 1e-300) {
      if (start > slack) hi = -1;
    } else if (rate > 0) {
      hi = std::min(hi, (slack - start) / rate);
    } else {
      lo = std::max(lo, (slack - start) / rate);
    }
  }
  return lo <= hi;
}

bool triangle_meets_tetrahedron(const Eigen::Vector3d& p_m, const Eigen::Vector3d& q_m,
                                const Eigen::Vector3d& r_m, const Matrix43d& corners_m) {
  if (!(p_m.allFinite() && q_m.allFinite() && r_m.allFinite() && corners_m.allFinite()))
    return false;
  // Relative to a corner, so that the round-off is that of the sizes at
  // play, not of the coordinates' distance from the origin.
  const Vector3d origin = corner(corners_m, 0);
  const std::array<Vector3d, 3> tri = relative(p_m, q_m, r_m, origin);
  std::array<Vector3d, 4> tet;
  for (int k = 0; k < 4; ++k) tet[static_cast<std::size_t>(k)] = corner(corners_m, k) - origin;
  double size = 0;
  for (const Vector3d& x : tri) size = std::max(size, x.norm());
  for (const Vector3d& x : tet) size = std::max(size, x.norm());
  // A separation by more than the round-off of the projections (|n| size
  // times a few ε) is one; an axis of zero length (parallel edges, a
  // degenerate triangle) separates nothing and is skipped by the test.
  const auto separated = [&](const Vector3d& n) {
    const double slack = kTouch * size * n.norm();
    const auto [tri_lo, tri_hi] = projection(n, tri);
    const auto [tet_lo, tet_hi] = projection(n, tet);
    return tri_hi < tet_lo - slack || tet_hi < tri_lo - slack;
  };
  for (const auto& f : kFaces)
    if (separated((tet[f[1]] - tet[f[0]]).cross(tet[f[2]] - tet[f[0]]))) return false;
  const std::array<Vector3d, 3> edge = {tri[1] - tri[0], tri[2] - tri[1], tri[0] - tri[2]};
  if (separated(edge[0].cross(edge[1]))) return false;
  for (const Vector3d& e : edge)
    for (const auto& te : kEdges)
      if (separated(e.cross(tet[te[1]] - tet[te[0]]))) return false;
  return true;
}

Matrix43d TensorMassModel::rest_corners(int tet) const {
  Matrix43d x;
  for (int k = 0; k < 4; ++k) x.row(k) = rest_m_.row(tets_(tet, k));
  return x;
}

// Each candidate is tested once: a tetrahedron is listed in up to 8 cells
// (more when it is large), and the stamp says it was seen by this query.
template <class CellTest, class TetTest>
void TensorMassModel::collect(const Eigen::Vector3d& lo_m, const Eigen::Vector3d& hi_m,
                              CellTest cell_meets, TetTest tet_meets, std::vector<int>& out) const {
  out.clear();
  const detail::TetGrid& grid = *grid_;
  // Cells and the query's box enlarged far above the coordinates' round-off
  // (10⁻⁹ of the sizes at play) and far below the element size: a cell that
  // holds a touching point of a candidate is never culled.
  const double slack = 1e-9 * ((grid.upper_m() - grid.lower_m()).norm() + (hi_m - lo_m).norm() +
                               lo_m.cwiseAbs().maxCoeff() + hi_m.cwiseAbs().maxCoeff());
  if (((lo_m.array() - slack) > grid.upper_m().array()).any() ||
      ((hi_m.array() + slack) < grid.lower_m().array()).any())
    return;
  if (++stamp_ == 0) {  // wrapped after 2³² queries: start the stamps again
    std::fill(tet_stamp_.begin(), tet_stamp_.end(), 0U);
    stamp_ = 1;
  }
  const auto a = grid.cell_of(lo_m - Vector3d::Constant(slack));
  const auto b = grid.cell_of(hi_m + Vector3d::Constant(slack));
  const double half_m = grid.half_side_m() + slack;
  for (int z = a[2]; z <= b[2]; ++z)
    for (int y = a[1]; y <= b[1]; ++y)
      for (int x = a[0]; x <= b[0]; ++x) {
        const detail::TetGrid::Cell cell{x, y, z};
        if (!cell_meets(grid.cell_centre(cell), half_m)) continue;
        for (const int t : grid.tetrahedra_in(cell)) {
          std::uint32_t& seen = tet_stamp_[static_cast<std::size_t>(t)];
          if (seen == stamp_) continue;
          seen = stamp_;
          if (tet_alive_[static_cast<std::size_t>(t)] != 0 && tet_meets(rest_corners(t)))
            out.push_back(t);
        }
      }
  std::sort(out.begin(), out.end());
}

void TensorMassModel::tetrahedra_crossed_by_segment(const Eigen::Vector3d& a_m,
                                                    const Eigen::Vector3d& b_m,
                                                    std::vector<int>& out) const {
  if (!(a_m.allFinite() && b_m.allFinite())) {
    out.clear();
    return;
  }
  collect(
      a_m.cwiseMin(b_m), a_m.cwiseMax(b_m),
      [&](const Vector3d& centre, double half_m) {
        return triangle_meets_cube(relative(a_m, b_m, b_m, centre), half_m);
      },
      [&](const Matrix43d& x) { return segment_meets_tetrahedron(a_m, b_m, x); }, out);
}

std::vector<int> TensorMassModel::tetrahedra_crossed_by_segment(const Eigen::Vector3d& a_m,
                                                                const Eigen::Vector3d& b_m) const {
  std::vector<int> out;
  tetrahedra_crossed_by_segment(a_m, b_m, out);
  return out;
}

void TensorMassModel::tetrahedra_met_by_triangle(const Eigen::Vector3d& p_m,
                                                 const Eigen::Vector3d& q_m,
                                                 const Eigen::Vector3d& r_m,
                                                 std::vector<int>& out) const {
  if (!(p_m.allFinite() && q_m.allFinite() && r_m.allFinite())) {
    out.clear();
    return;
  }
  collect(
      p_m.cwiseMin(q_m).cwiseMin(r_m), p_m.cwiseMax(q_m).cwiseMax(r_m),
      [&](const Vector3d& centre, double half_m) {
        return triangle_meets_cube(relative(p_m, q_m, r_m, centre), half_m);
      },
      [&](const Matrix43d& x) { return triangle_meets_tetrahedron(p_m, q_m, r_m, x); }, out);
}

std::vector<int> TensorMassModel::tetrahedra_met_by_triangle(const Eigen::Vector3d& p_m,
                                                             const Eigen::Vector3d& q_m,
                                                             const Eigen::Vector3d& r_m) const {
  std::vector<int> out;
  tetrahedra_met_by_triangle(p_m, q_m, r_m, out);
  return out;
}

void TensorMassModel::tetrahedra_swept_by_blade(const Blade& before, const Blade& after,
                                                std::vector<int>& out) const {
  // The quadrilateral p q r s = (before.a, before.b, after.b, after.a), as
  // the triangles p q r and p r s.
  const Vector3d &p = before.a_m, &q = before.b_m, &r = after.b_m, &s = after.a_m;
  if (!(p.allFinite() && q.allFinite() && r.allFinite() && s.allFinite())) {
    out.clear();
    return;
  }
  collect(
      p.cwiseMin(q).cwiseMin(r).cwiseMin(s), p.cwiseMax(q).cwiseMax(r).cwiseMax(s),
      [&](const Vector3d& centre, double half_m) {
        return triangle_meets_cube(relative(p, q, r, centre), half_m) ||
               triangle_meets_cube(relative(p, r, s, centre), half_m);
      },
      [&](const Matrix43d& x) {
        return triangle_meets_tetrahedron(p, q, r, x) || triangle_meets_tetrahedron(p, r, s, x);
      },
      out);
}

std::vector<int> TensorMassModel::tetrahedra_swept_by_blade(const Blade& before,
                                                            const Blade& after) const {
  std::vector<int> out;
  tetrahedra_swept_by_blade(before, after, out);
  return out;
}

int TensorMassModel::cut_swept_blade(const Blade& before, const Blade& after,
                                     std::vector<int>& removed) {
  tetrahedra_swept_by_blade(before, after, removed);
  // All remaining (the query skips the removed): no removal can refuse.
  for (const int t : removed) remove_tetrahedron(t);
  return static_cast<int>(removed.size());
}

}  // namespace palpate
