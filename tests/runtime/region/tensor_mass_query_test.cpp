// The tensor-mass region's queries (runtime/tensor_mass: the segment, the
// triangle and the swept blade; lib/runtime/src/region/tensor_mass_query.cpp): the
// index itself (the internal tet_grid) first, the exact triangle–tetrahedron
// test against an independent one and on hand-made cases, the indexed
// queries against a scan of every tetrahedron (docs/model/tensor-mass.md, "The swept
// blade"). What a cut does: tensor_mass_cut_test.cpp.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "palpate/runtime/region/tet_grid.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "runtime/tensor_mass_meshes.hpp"
#include "support/allocation_counter.hpp"
#include "support/test_meshes.hpp"
#include "support/time_scale.hpp"

namespace palpate {
namespace {

using namespace tensor_mass_test;

/// The remaining tetrahedra for which meets(corners) holds: a scan of all.
template <class Meets>
std::vector<int> scan(const TensorMassModel& m, Meets meets) {
  std::vector<int> out;
  for (int t = 0; t < m.tetrahedron_count(); ++t)
    if (!m.is_removed(t) && meets(corners(m, t))) out.push_back(t);
  return out;
}

/// Whether the segment a–b crosses the triangle p q r (Möller & Trumbore,
/// JGT 2(1), 1997, boundaries included); false when they are parallel.
bool segment_crosses_triangle(const Vector3d& a, const Vector3d& b, const Vector3d& p,
                              const Vector3d& q, const Vector3d& r) {
  const Vector3d d = b - a, e1 = q - p, e2 = r - p, h = d.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) <= 1e-300) return false;
  const Vector3d s = a - p;
  const double u = s.dot(h) / det;
  const Vector3d g = s.cross(e1);
  const double v = d.dot(g) / det, w = e2.dot(g) / det;
  return u >= 0 && v >= 0 && u + v <= 1 && w >= 0 && w <= 1;
}

// 0. Each tetrahedron is listed, once, in every cell that holds a point of
// it (its corners, its centroid, random points), the lists ascending, the
// cells from cell_of(lo) to cell_of(hi) covering any box.
TEST(TensorMassCut, GridListsEachTetrahedronInTheCellsOfItsPoints) {
  const TetMesh mesh = big_box(true);
  const detail::TetGrid grid(mesh.vertices, mesh.tetrahedra);
  const int nt = static_cast<int>(mesh.tetrahedra.rows());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int t = 0; t < nt; ++t) {
    Eigen::Vector4d w;
    for (int n = 0; n < 6; ++n) {
      // Corners, the centroid, then a random point (barycentric weights).
      if (n < 4)
        w = Eigen::Vector4d::Unit(n);
      else if (n == 4)
        w.setConstant(0.25);
      else
        w = Eigen::Vector4d(unit(rng), unit(rng), unit(rng), unit(rng)).normalized().cwiseAbs2();
      Vector3d x = Vector3d::Zero();
      for (int k = 0; k < 4; ++k) x += w[k] * mesh.vertices.row(mesh.tetrahedra(t, k)).transpose();
      const auto list = grid.tetrahedra_in(grid.cell_of(x));
      EXPECT_EQ(std::count(list.begin(), list.end(), t), 1) << "tetrahedron " << t;
    }
  }
  std::size_t entries = 0;
  const auto dims = grid.dims();
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        const detail::TetGrid::Cell cell{x, y, z};
        // The centre of a cell is in it.
        EXPECT_EQ(grid.cell_of(grid.cell_centre(cell)), cell);
        const auto list = grid.tetrahedra_in(cell);
        EXPECT_TRUE(std::is_sorted(list.begin(), list.end()));
        EXPECT_TRUE(std::adjacent_find(list.begin(), list.end()) == list.end());
        entries += list.size();
      }
  EXPECT_EQ(entries, grid.entry_count());
  // About the element size: each tetrahedron in a few cells, not dozens.
  std::printf("tetrahedron grid: %lld cells, %.2f per tetrahedron\n",
              static_cast<long long>(grid.cell_count()),
              static_cast<double>(grid.entry_count()) / nt);
  EXPECT_LE(grid.entry_count(), static_cast<std::size_t>(27 * nt));
  EXPECT_GE(grid.cell_count(), 64);
}

// 1. The separating-axis test against an independent characterisation: a
// triangle meets a tetrahedron if and only if one of its edges meets the
// tetrahedron (Cyrus–Beck, checked by sampling in tensor_mass_test.cpp) or
// one of the tetrahedron's edges crosses it (the triangle ∩ tetrahedron is
// a convex polygon; if no triangle edge reaches the tetrahedron, its
// boundary lies on the tetrahedron's faces and its corners on their edges).
TEST(TensorMassCut, TriangleTestAgreesWithEdgeCrossings) {
  const TetMesh mesh = cube(true);
  const Region r(mesh, mesh.tetrahedra, {});
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> where(-0.005, 0.045), size(0.0005, 0.03);
  int met = 0, pairs = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Vector3d centre(where(rng), where(rng), where(rng));
    const double s = size(rng);
    const Vector3d p = centre + s * random_unit(rng), q = centre + s * random_unit(rng),
                   t = centre + s * random_unit(rng);
    for (int tet = 0; tet < r.model.tetrahedron_count(); ++tet) {
      const Matrix43d x = corners(r.model, tet);
      bool expected = segment_meets_tetrahedron(p, q, x) || segment_meets_tetrahedron(q, t, x) ||
                      segment_meets_tetrahedron(t, p, x);
      static constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
      for (const auto& e : kEdge)
        expected = expected || segment_crosses_triangle(x.row(e[0]).transpose(),
                                                        x.row(e[1]).transpose(), p, q, t);
      // Random coordinates: no pair is within round-off of touching.
      EXPECT_EQ(triangle_meets_tetrahedron(p, q, t, x), expected)
          << "triangle " << trial << ", tetrahedron " << tet;
      met += expected ? 1 : 0;
      ++pairs;
    }
  }
  std::printf("%d of %d triangle–tetrahedron pairs meet\n", met, pairs);
  EXPECT_GT(met, 2000);  // both answers well represented
  EXPECT_GT(pairs - met, 2000);
}

// 2. Hand-made cases on the unit corner tetrahedron: contained, slicing,
// touching a face, an edge or a vertex (counted), and just apart (not).
TEST(TensorMassCut, TriangleTestOnHandMadeCases) {
  Matrix43d x;
  x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  const auto meets = [&](Vector3d p, Vector3d q, Vector3d r) {
    // The answer does not depend on the triangle's orientation or first vertex.
    const bool a = triangle_meets_tetrahedron(p, q, r, x);
    EXPECT_EQ(triangle_meets_tetrahedron(q, r, p, x), a);
    EXPECT_EQ(triangle_meets_tetrahedron(p, r, q, x), a);
    return a;
  };
  // Inside, touching nothing.
  EXPECT_TRUE(meets({0.1, 0.1, 0.1}, {0.2, 0.1, 0.1}, {0.1, 0.2, 0.15}));
  // A large triangle slicing the middle, no vertex inside either.
  EXPECT_TRUE(meets({-5, -5, 0.25}, {5, -5, 0.25}, {0, 5, 0.25}));
  EXPECT_FALSE(meets({-5, -5, 1.25}, {5, -5, 1.25}, {0, 5, 1.25}));
  // In the plane of the face z = 0, overlapping it; then 1 µm below.
  EXPECT_TRUE(meets({0.2, 0.2, 0}, {2, 0.2, 0}, {0.2, 2, 0}));
  EXPECT_FALSE(meets({0.2, 0.2, -1e-6}, {2, 0.2, -1e-6}, {0.2, 2, -1e-6}));
  // Touching the vertex (1, 0, 0) only; then 10⁻⁹ away (far above round-off).
  EXPECT_TRUE(meets({1, 0, 0}, {2, -1, 0.5}, {2, 1, -0.5}));
  EXPECT_FALSE(meets({1 + 1e-9, 0, 0}, {2, -1, 0.5}, {2, 1, -0.5}));
  // Across the edge (1, 0, 0)–(0, 1, 0) from outside, touching its midpoint;
  // then moved 10⁻⁹ outward along (1, 1, 0).
  const Vector3d mid(0.5, 0.5, 0), out = Vector3d(1, 1, 0).normalized();
  const Vector3d along(0, 0, 1), across = Vector3d(1, 1, -1).normalized();
  EXPECT_TRUE(meets(mid, mid + out + along, mid + out - along + 0.1 * across));
  EXPECT_FALSE(meets(mid + 1e-9 * out, mid + out + along, mid + out - along + 0.1 * across));
  // A thin triangle across the edge (0, 0, 0)–(1, 0, 0), passing 10⁻³
  // beyond it: no face normal nor the triangle's separates them, the cross
  // product of that edge and the triangle's long edge does; then 10⁻³ inside.
  const Vector3d by(0, -1, -1);
  const Vector3d c = Vector3d(0.5, 0, 0) + 1e-3 * by.normalized();
  const Vector3d dir = Vector3d(0, 1, -1).normalized();
  EXPECT_FALSE(meets(c - dir, c + dir, c + dir + Vector3d(1e-3, 0, 0) + 1e-4 * by));
  EXPECT_TRUE(
      meets(c - dir - 2e-3 * by, c + dir - 2e-3 * by, c + dir - 2e-3 * by + Vector3d(1e-3, 0, 0)));
  // Degenerate triangles: a segment through, a point inside and outside.
  EXPECT_TRUE(meets({-1, 0.2, 0.2}, {2, 0.2, 0.2}, {2, 0.2, 0.2}));
  EXPECT_TRUE(meets({0.2, 0.2, 0.2}, {0.2, 0.2, 0.2}, {0.2, 0.2, 0.2}));
  EXPECT_FALSE(meets({0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}));
  // Non-finite input meets nothing.
  EXPECT_FALSE(meets({NAN, 0.2, 0.2}, {2, 0.2, 0.2}, {2, 0.3, 0.2}));
  EXPECT_FALSE(segment_meets_tetrahedron({INFINITY, 0, 0}, {0.2, 0.2, 0.2}, x));
}

/// A random blade movement: sizes from within one cell to across the
/// region, partly or wholly outside, twisted, some not moving at all.
std::array<Blade, 2> random_sweep(std::mt19937& rng, int kind) {
  const double side = kBoxCells * kBoxCell_m;
  std::uniform_real_distribution<double> where(-0.2 * side, 1.2 * side), unit(0, 1);
  const double length = std::pow(10.0, -3.5 + 2.0 * unit(rng));  // 0.3 mm .. 3 cm
  const double travel = std::pow(10.0, -4.0 + 2.0 * unit(rng));  // 0.1 mm .. 1 cm
  const Vector3d centre(where(rng), where(rng), where(rng));
  const Vector3d along = random_unit(rng), move = random_unit(rng);
  Blade before{centre - 0.5 * length * along, centre + 0.5 * length * along};
  Blade after{before.a_m + travel * move, before.b_m + travel * move};
  if (kind == 1) after.b_m += 0.3 * length * random_unit(rng);  // twisted: not planar
  if (kind == 2) after = before;                                // the blade stopped
  return {before, after};
}

// 3. The index changes nothing: each query equals the scan of every
// tetrahedron with the same exact test, removed tetrahedra skipped; and the
// caller-owned forms allocate nothing.
TEST(TensorMassCut, IndexedQueriesEqualTheScan) {
  const TetMesh mesh = big_box(true);
  Region r(mesh, mesh.tetrahedra, {});
  std::mt19937 rng(41);
  std::uniform_int_distribution<int> any_tet(0, r.model.tetrahedron_count() - 1);
  for (int n = 0; n < 300; ++n) {
    const int t = any_tet(rng);
    if (!r.model.is_removed(t)) r.model.remove_tetrahedron(t);
  }
  long segment_hits = 0, triangle_hits = 0, quad_hits = 0;
  // Fewer under the sanitizers (the scans are slow there).
  const int trials = testing::time_scale() > 1 ? 150 : 600;
  for (int trial = 0; trial < trials; ++trial) {
    const auto [before, after] = random_sweep(rng, trial % 3);
    const Vector3d &p = before.a_m, &q = before.b_m, &s = after.b_m, &w = after.a_m;
    const auto segment = r.model.tetrahedra_crossed_by_segment(p, q);
    EXPECT_EQ(segment,
              scan(r.model, [&](const Matrix43d& x) { return segment_meets_tetrahedron(p, q, x); }))
        << "segment " << trial;
    const auto triangle = r.model.tetrahedra_met_by_triangle(p, q, s);
    EXPECT_EQ(
        triangle,
        scan(r.model, [&](const Matrix43d& x) { return triangle_meets_tetrahedron(p, q, s, x); }))
        << "triangle " << trial;
    const auto quad = r.model.tetrahedra_swept_by_blade(before, after);
    EXPECT_EQ(quad, scan(r.model,
                         [&](const Matrix43d& x) {
                           return triangle_meets_tetrahedron(p, q, s, x) ||
                                  triangle_meets_tetrahedron(p, s, w, x);
                         }))
        << "quad " << trial;
    segment_hits += std::ssize(segment);
    triangle_hits += std::ssize(triangle);
    quad_hits += std::ssize(quad);
  }
  std::printf("%d queries each: %ld segment, %ld triangle, %ld swept-quad hits\n", trials,
              segment_hits, triangle_hits, quad_hits);
  EXPECT_GT(segment_hits, trials / 2);  // the queries did meet tetrahedra (about 2 each)
  EXPECT_GT(quad_hits, 2 * trials);     // (about 4 each)

  // A blade that did not move cuts its segment's tetrahedra (the degenerate
  // quadrilateral), up to touching within round-off: none here.
  const Blade still{{0.003, 0.011, 0.017}, {0.026, 0.021, 0.004}};
  EXPECT_EQ(r.model.tetrahedra_swept_by_blade(still, still),
            r.model.tetrahedra_crossed_by_segment(still.a_m, still.b_m));
  const Blade nan{{NAN, 0, 0}, {0.01, 0.01, 0.01}};
  EXPECT_TRUE(r.model.tetrahedra_swept_by_blade(nan, still).empty());

  // The tick's forms, into reserved vectors: no allocation, same answers.
  std::vector<int> out, removed;
  out.reserve(static_cast<std::size_t>(r.model.tetrahedron_count()));
  removed.reserve(out.capacity());
  std::vector<std::array<Blade, 2>> sweeps;
  std::vector<std::vector<int>> expected;
  for (int n = 0; n < 50; ++n) {
    sweeps.push_back(random_sweep(rng, n % 3));
    expected.push_back(r.model.tetrahedra_swept_by_blade(sweeps.back()[0], sweeps.back()[1]));
  }
  std::vector<std::vector<int>> got(sweeps.size());
  for (auto& g : got) g.reserve(out.capacity());
  const auto before = testing::allocations_here();
  for (std::size_t n = 0; n < sweeps.size(); ++n) {
    r.model.tetrahedra_swept_by_blade(sweeps[n][0], sweeps[n][1], got[n]);
    r.model.tetrahedra_crossed_by_segment(sweeps[n][0].a_m, sweeps[n][1].b_m, out);
    r.model.tetrahedra_met_by_triangle(sweeps[n][0].a_m, sweeps[n][0].b_m, sweeps[n][1].b_m, out);
  }
  int cut = 0;
  for (std::size_t n = 0; n < 10; ++n)
    cut += r.model.cut_swept_blade(sweeps[n][0], sweeps[n][1], removed);
  const auto allocations = testing::allocations_here() - before;
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(got, expected);
  EXPECT_GT(cut, 0);
  for (std::size_t n = 0; n < 10; ++n)
    for (int t : expected[n]) EXPECT_TRUE(r.model.is_removed(t));
}

}  // namespace
}  // namespace palpate
