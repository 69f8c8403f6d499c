// Cutting the tensor-mass region (runtime/tensor_mass): the exact
// triangle–tetrahedron test against an independent one, the indexed
// queries against a scan, a sweep across the region leaving two parts that
// exchange no force, cutting through entirely, and 10,000 random cuts
// between explicit steps that keep the region finite, uninverted and within
// the energy the load put in (docs/model.md, "The tensor-mass model: a
// cuttable region"). The index itself (the internal tet_grid) first.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "../../lib/runtime/src/tet_grid.hpp"
#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/runtime/tensor_mass.hpp"
#include "runtime/tensor_mass_meshes.hpp"
#include "support/allocation_counter.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"
#include "support/time_scale.hpp"

namespace palpate {
namespace {

using namespace tensor_mass_test;

Matrix43d corners(const TensorMassModel& m, int t) {
  Matrix43d x;
  for (int k = 0; k < 4; ++k) x.row(k) = m.rest_positions_m().row(m.tetrahedra()(t, k));
  return x;
}

/// The remaining tetrahedra for which meets(corners) holds: a scan of all.
template <class Meets>
std::vector<int> scan(const TensorMassModel& m, Meets meets) {
  std::vector<int> out;
  for (int t = 0; t < m.tetrahedron_count(); ++t)
    if (!m.is_removed(t) && meets(corners(m, t))) out.push_back(t);
  return out;
}

/// The region of the robustness tests: 7 × 7 × 7 cubes of 4 mm (2,058
/// tetrahedra, 512 vertices, a 28 mm cube), liver, interior vertices moved
/// by up to 0.1 cell when @p jitter (a generic mesh for the queries).
constexpr int kBoxCells = 7;
constexpr double kBoxCell_m = 4e-3;
TetMesh big_box(bool jitter) {
  const double side = kBoxCells * kBoxCell_m;
  TetMesh mesh = testing::box_mesh(side, side, side, kBoxCells, kBoxCells, kBoxCells);
  if (jitter) {
    std::mt19937 rng(21);
    std::uniform_real_distribution<double> d(-0.1 * kBoxCell_m, 0.1 * kBoxCell_m);
    for (int i = 1; i < kBoxCells; ++i)
      for (int j = 1; j < kBoxCells; ++j)
        for (int k = 1; k < kBoxCells; ++k)
          mesh.vertices.row(testing::box_vertex(i, j, k, kBoxCells, kBoxCells)) +=
              Eigen::RowVector3d(d(rng), d(rng), d(rng));
  }
  return mesh;
}
std::vector<int> big_box_face_x0() {
  std::vector<int> out;
  for (int j = 0; j <= kBoxCells; ++j)
    for (int k = 0; k <= kBoxCells; ++k)
      out.push_back(testing::box_vertex(0, j, k, kBoxCells, kBoxCells));
  return out;
}

Vector3d random_unit(std::mt19937& rng) {
  std::normal_distribution<double> n(0, 1);
  Vector3d d;
  do d = Vector3d(n(rng), n(rng), n(rng));
  while (d.norm() < 1e-6);
  return d.normalized();
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
  const auto before = testing::allocations();
  for (std::size_t n = 0; n < sweeps.size(); ++n) {
    r.model.tetrahedra_swept_by_blade(sweeps[n][0], sweeps[n][1], got[n]);
    r.model.tetrahedra_crossed_by_segment(sweeps[n][0].a_m, sweeps[n][1].b_m, out);
    r.model.tetrahedra_met_by_triangle(sweeps[n][0].a_m, sweeps[n][0].b_m, sweeps[n][1].b_m, out);
  }
  int cut = 0;
  for (std::size_t n = 0; n < 10; ++n)
    cut += r.model.cut_swept_blade(sweeps[n][0], sweeps[n][1], removed);
  const auto allocations = testing::allocations() - before;
  EXPECT_EQ(allocations, 0u);
  EXPECT_EQ(got, expected);
  EXPECT_GT(cut, 0);
  for (std::size_t n = 0; n < 10; ++n)
    for (int t : expected[n]) EXPECT_TRUE(r.model.is_removed(t));
}

/// The part label of every remaining tetrahedron, with the side of x0 its
/// vertices are on (−1 below, +1 above, 0 straddling).
int side_of(const TensorMassModel& m, int t, double x0) {
  bool below = true, above = true;
  for (int k = 0; k < 4; ++k) {
    const double x = m.rest_positions_m()(m.tetrahedra()(t, k), 0);
    below = below && x < x0;
    above = above && x > x0;
  }
  return below ? -1 : above ? 1 : 0;
}

// 4. A blade swept over the whole cross-section x = 2.5 cm of the 4 cm cube
// held on x = 0 leaves two parts, one on each side; no force crosses the
// cut, and under a weight the free part falls as a rigid body while the
// held part stays within twice its static displacement.
TEST(TensorMassCut, SweepAcrossSeparatesTwoParts) {
  const TetMesh mesh = cube(false);
  constexpr double kX0 = 0.025, kG = 9.81;  // m, m/s²
  Region r(mesh, mesh.tetrahedra, face_x0(0), {1060, 20});
  EXPECT_EQ(r.model.connected_parts(), 1);
  // The blade spans z from −5 to 45 mm and moves in y from −5 to 45 mm in
  // ten ticks: the quadrilaterals tile the plane x = x0 over the section.
  std::vector<int> removed;
  removed.reserve(static_cast<std::size_t>(r.model.tetrahedron_count()));
  int total = 0;
  for (int tick = 0; tick < 10; ++tick) {
    const double y0 = -0.005 + 0.005 * tick, y1 = y0 + 0.005;
    total += r.model.cut_swept_blade({{kX0, y0, -0.005}, {kX0, y0, 0.045}},
                                     {{kX0, y1, -0.005}, {kX0, y1, 0.045}}, removed);
  }
  // The plane meets exactly the 16 cubes of the layer 2 cm ≤ x ≤ 3 cm.
  EXPECT_EQ(total, 16 * 6);
  ASSERT_EQ(r.model.connected_parts(), 2);
  const std::vector<int> label = r.model.part_labels();
  std::set<int> labels_below, labels_above;
  std::vector<int> part_of_vertex(r.model.vertex_count(), -1);
  for (int t = 0; t < r.model.tetrahedron_count(); ++t) {
    if (r.model.is_removed(t)) {
      EXPECT_EQ(label[t], -1);
      continue;
    }
    const int side = side_of(r.model, t, kX0);
    ASSERT_NE(side, 0) << "tetrahedron " << t << " straddles the cut";
    (side < 0 ? labels_below : labels_above).insert(label[t]);
    for (int k = 0; k < 4; ++k) {
      int& p = part_of_vertex[r.model.tetrahedra()(t, k)];
      EXPECT_TRUE(p < 0 || p == label[t]) << "a vertex in both parts";
      p = label[t];
    }
  }
  EXPECT_EQ(labels_below, std::set<int>{0});  // the held part has tetrahedron 0
  EXPECT_EQ(labels_above, std::set<int>{1});
  // No edge crosses the cut.
  for (const auto& [i, j] : r.model.edges())
    EXPECT_EQ(r.model.rest_positions_m()(i, 0) < kX0, r.model.rest_positions_m()(j, 0) < kX0);

  const double dt = 0.9 * r.model.stable_time_step().element_time_step_s;
  const int nv = r.model.vertex_count();
  const auto below = [&](int v) { return r.model.rest_positions_m()(v, 0) < kX0; };

  // A load on the free side only: the held side does not move at all.
  VectorXd load = VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v)
    if (!below(v)) load.segment<3>(3 * v) = Vector3d(0.001, 0.002, -0.005);  // N
  for (int n = 0; n < 500; ++n) r.model.step(dt, load);
  double free_moved = 0;
  for (int v = 0; v < nv; ++v) {
    const Vector3d u = r.model.displacement_m().segment<3>(3 * v);
    if (below(v))
      EXPECT_EQ(u, Vector3d::Zero()) << "vertex " << v;  // exactly: no term reaches it
    else
      free_moved = std::max(free_moved, u.norm());
  }
  EXPECT_GT(free_moved, 1e-3);  // 0.25 N on 17 g for 0.1 s: centimetres

  // A weight m_v g on every vertex, from rest.
  const VectorXd zero = VectorXd::Zero(3 * nv);
  r.model.set_state(zero, zero);
  VectorXd weight = VectorXd::Zero(3 * nv);
  for (int v = 0; v < nv; ++v) weight[3 * v + 2] = -r.model.mass_kg(v) * kG;
  // The held part's static answer u_s = K_A⁻¹ f on its moving DOFs.
  std::vector<int> held_tets, held_moving;
  for (int t = 0; t < r.model.tetrahedron_count(); ++t)
    if (!r.model.is_removed(t) && side_of(r.model, t, kX0) < 0) held_tets.push_back(t);
  for (int v : moving_vertices(r.model))
    if (below(v)) held_moving.push_back(v);
  const auto dofs = dofs_of(held_moving);
  const MatrixXd k_a = full_stiffness(mesh, rows(mesh.tetrahedra, held_tets))(dofs, dofs);
  const VectorXd u_s = k_a.llt().solve(weight(dofs));
  const double static_norm = std::sqrt(u_s.dot(k_a * u_s));
  // The free part translates: every vertex follows the scalar recurrence of
  // the step for a = −g (the elastic force of a translation is round-off).
  const double c0 = 1 / (dt * dt), c1 = 20 / (2 * dt);
  double q = 0, q_prev = 0, largest_held = 0, worst_rigid = 0;
  const int steps = 2000;
  for (int n = 0; n < steps; ++n) {
    const VectorXd u_before = r.model.displacement_m()(dofs);
    r.model.step(dt, weight);
    const double next = (-kG + 2 * c0 * q - (c0 - c1) * q_prev) / (c0 + c1);
    q_prev = q;
    q = next;
    // The held part from rest under a constant load: the discrete energy
    // identity gives |ū|_K ≤ 2 |u_s|_K at the half steps (docs/model.md).
    const VectorXd mid = 0.5 * (u_before + r.model.displacement_m()(dofs));
    largest_held = std::max(largest_held, std::sqrt(mid.dot(k_a * mid)));
    for (int v = 0; v < nv; ++v)
      if (!below(v))
        worst_rigid = std::max(
            worst_rigid, (r.model.displacement_m().segment<3>(3 * v) - Vector3d(0, 0, q)).norm());
  }
  std::printf(
      "cut in two: the free part fell %.4g m in %d steps (rigid to %.3g of it); held part "
      "|ū|_K up to %.3f |u_s|_K\n",
      -q, steps, worst_rigid / std::abs(q), largest_held / static_norm);
  EXPECT_LT(q, -1e-3);
  // Translation's elastic force is ~10⁻¹⁶ ‖K‖ |u| per step: 10⁻⁹ relative.
  EXPECT_LE(worst_rigid, 1e-9 * std::abs(q));
  EXPECT_LE(largest_held, 2 * static_norm * (1 + 1e-9));
  EXPECT_GE(largest_held, 0.5 * static_norm);  // it did carry its weight
}

// 5. Cutting through entirely: every tetrahedron removed leaves a defined,
// inert model.
TEST(TensorMassCut, CuttingThroughEntirely) {
  const TetMesh mesh = cube(true);
  Region r(mesh, mesh.tetrahedra, face_x0(0));
  const int nv = r.model.vertex_count(), nt = r.model.tetrahedron_count();
  const double dt = 0.9 * r.model.stable_time_step().element_time_step_s;
  const VectorXd load = VectorXd::Constant(3 * nv, -1e-3);
  for (int n = 0; n < 50; ++n) r.model.step(dt, load);
  const std::uint64_t version = r.model.boundary_version();
  // Half by a blade sweeping through the middle, the rest one by one.
  std::vector<int> removed;
  const int swept = r.model.cut_swept_blade({{-0.01, -0.01, 0.02}, {-0.01, 0.05, 0.02}},
                                            {{0.05, -0.01, 0.02}, {0.05, 0.05, 0.02}}, removed);
  EXPECT_GT(swept, 0);
  std::vector<int> order(nt);
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), std::mt19937(5));
  for (int t : order)
    if (!r.model.is_removed(t)) r.model.remove_tetrahedron(t);

  const TensorMassModel& m = r.model;
  EXPECT_EQ(m.remaining_tetrahedra(), 0);
  EXPECT_EQ(m.boundary_version(), version + static_cast<std::uint64_t>(nt));
  EXPECT_TRUE(m.boundary_triangles().empty());
  EXPECT_EQ(m.edge_count(), 0);
  EXPECT_EQ(m.connected_parts(), 0);
  EXPECT_EQ(m.part_labels(), std::vector<int>(nt, -1));
  for (int v = 0; v < nv; ++v) {
    EXPECT_TRUE(m.is_detached(v)) << "vertex " << v;
    EXPECT_EQ(m.mass_kg(v), 0.0);
    EXPECT_EQ(m.vertex_tensor(v), Eigen::Matrix3d::Zero());
  }
  // Nothing left to meet, nothing to cut.
  EXPECT_TRUE(m.tetrahedra_crossed_by_segment({0, 0, 0}, {0.04, 0.04, 0.04}).empty());
  EXPECT_EQ(r.model.cut_swept_blade({{0, 0, 0}, {0, 0.04, 0.04}},
                                    {{0.04, 0, 0}, {0.04, 0.04, 0.04}}, removed),
            0);
  // Nothing moves: ω_max 0 and any step stable.
  const StableTimeStep bound = m.stable_time_step();
  EXPECT_EQ(bound.omega_max_rad_s, 0.0);
  EXPECT_TRUE(std::isinf(bound.critical_time_step_s) && std::isinf(bound.element_time_step_s));
  // The step leaves every displacement where the cuts left it.
  const VectorXd u = m.displacement_m();
  EXPECT_GT(u.norm(), 0);
  r.model.step(dt, load);
  r.model.step(dt, -load);
  EXPECT_EQ(m.displacement_m(), u);
  EXPECT_EQ(m.previous_displacement_m(), u);
  VectorXd f(3 * nv);
  m.internal_force(u, f);
  EXPECT_EQ(f, VectorXd::Zero(3 * nv));
  // Removing again is refused, naming the tetrahedron.
  testing::expect_error<InputError>([&] { r.model.remove_tetrahedron(17); },
                                    {"tetrahedron 17", "already removed"});
  EXPECT_EQ(m.boundary_version(), version + static_cast<std::uint64_t>(nt));
}

/// Deformed signed volume over rest volume of tetrahedron t.
double volume_ratio(const TensorMassModel& m, const VectorXd& u, int t) {
  Vector3d x[4];
  for (int k = 0; k < 4; ++k) {
    const int v = m.tetrahedra()(t, k);
    x[k] = m.rest_positions_m().row(v).transpose() + u.segment<3>(3 * v);
  }
  const Matrix43d rest = corners(m, t);
  const Vector3d r0 = rest.row(0).transpose();
  const double rest_volume =
      (rest.row(1).transpose() - r0)
          .dot((rest.row(2).transpose() - r0).cross(rest.row(3).transpose() - r0));
  return (x[1] - x[0]).dot((x[2] - x[0]).cross(x[3] - x[0])) / rest_volume;
}

// 6. 10,000 random cuts (strokes of a blade of 2–10 mm moving 0.2–1.5 mm a
// tick, turning a little) on the 2,058-tetrahedron box held on x = 0,
// interleaved with explicit steps at 0.9 of the element step under a body
// load of 1 m/s² (a tenth of gravity: the heaviest part hanging on one
// tetrahedron strains it about 2 %, so no element inverts for physical
// reasons) and damping γ = 20/s; every seventh cut also removes a random
// tetrahedron by index, refused when already removed. The region is built
// again when a quarter of it remains. Checked after every cut and step:
//  - no exception but that refusal; u finite; every remaining tetrahedron's
//    deformed signed volume > 0;
//  - energy: with v = (u⁺ − u)/Δt and H = ½ vᵀ M v + ½ u⁺ᵀ K u, centred
//    differences give H⁺ − H = f·(u⁺ − u⁻)/2 − (γ/4Δt)|u⁺ − u⁻|²_M, so
//    H ≤ W, the work of the load so far; a cut lowers H (it removes
//    ½ v_tᵀ(M_t − Δt²K^t/4)v_t + ½ ū_tᵀK^tū_t ≥ 0 when Δt is below the
//    element step). And H = ½ vᵀ(M − Δt²K/4)v + ½ ūᵀKū (ū = (u⁺ + u)/2)
//    ≥ (1 − Ω²/4) E, E = ½ vᵀMv + ½ ūᵀKū the energy at the half step,
//    Ω = Δt ω_element ≤ 1.8: E ≤ W / (1 − 0.81).
TEST(TensorMassCut, RandomCutsStayPhysical) {
  const TetMesh mesh = big_box(false);
  const auto fixed = big_box_face_x0();
  const auto ke =
      element_stiffnesses(mesh, mesh.tetrahedra, std::vector<Lame>(mesh.tetrahedra.rows(), kLiver));
  const TensorMassMaterial material{1060, 20};
  constexpr int kCuts = 10000;
  constexpr double kAccel = 1.0;  // m/s², along −z
  // Under the sanitizers (PALPATE_TEST_TIME_SCALE > 1: Eigen checked and
  // instrumented, some 50 times slower) one step between cuts and the
  // energies and volumes checked at every 20th cut; the cuts stay 10,000,
  // the work W is summed at every step.
  const bool slow = testing::time_scale() > 1;
  const int steps_per_cut = slow ? 1 : 4, check_every = slow ? 20 : 1;
  const double side = kBoxCells * kBoxCell_m;

  std::mt19937 rng(2026);
  std::uniform_real_distribution<double> unit(0, 1);
  std::unique_ptr<TensorMassModel> model;
  double dt = 0, energy_factor = 0, work = 0;
  const int nv = static_cast<int>(mesh.vertices.rows()),
            nt = static_cast<int>(mesh.tetrahedra.rows());
  VectorXd force(3 * nv), ku(3 * nv), mid(3 * nv), velocity(3 * nv);
  std::vector<int> removed;
  removed.reserve(static_cast<std::size_t>(nt));
  // Counts.
  int episodes = 0, refused = 0, direct = 0, stroke_ticks = 0, checks = 0;
  long swept_away = 0, steps = 0;
  double worst_h_over_w = 0, worst_e_over_w = 0, least_volume = 1, largest_u = 0;
  Blade blade;
  Vector3d move = Vector3d::Zero(), turn_axis = Vector3d::UnitX();
  double turn = 0;

  // H = ½ vᵀMv + ½ u⁺ᵀKu and E = ½ vᵀMv + ½ ūᵀKū of the model's state.
  const auto energies = [&](const TensorMassModel& m) {
    const VectorXd& u1 = m.displacement_m();
    const VectorXd& u0 = m.previous_displacement_m();
    velocity = (u1 - u0) / dt;
    double kinetic = 0;
    for (int v = 0; v < nv; ++v)
      kinetic += 0.5 * m.mass_kg(v) * velocity.segment<3>(3 * v).squaredNorm();
    m.apply_stiffness(u0, ku);
    const double shadow = kinetic + 0.5 * u1.dot(ku);
    mid = 0.5 * (u1 + u0);
    m.apply_stiffness(mid, ku);
    return std::array<double, 2>{shadow, kinetic + 0.5 * mid.dot(ku)};
  };
  // What is wrong with the state, or nothing.
  const auto check_state = [&](const TensorMassModel& m) -> std::string {
    const VectorXd& u = m.displacement_m();
    if (!u.allFinite()) return "a non-finite displacement";
    largest_u = std::max(largest_u, u.cwiseAbs().maxCoeff());
    for (int t = 0; t < nt; ++t) {
      if (m.is_removed(t)) continue;
      const double ratio = volume_ratio(m, u, t);
      least_volume = std::min(least_volume, ratio);
      if (!(ratio > 0)) return "tetrahedron " + std::to_string(t) + " inverted";
    }
    return "";
  };

  for (int cut = 0; cut < kCuts; ++cut) {
    if (!model || model->remaining_tetrahedra() < nt / 4) {
      model =
          std::make_unique<TensorMassModel>(mesh.vertices, mesh.tetrahedra, ke, material, fixed);
      // The element bound only: one power iteration is enough.
      const StableTimeStep bound = model->stable_time_step(1e-6, 1);
      dt = 0.9 * bound.element_time_step_s;
      const double omega_dt = dt * bound.element_omega_rad_s;  // 1.8
      energy_factor = 1 / (1 - omega_dt * omega_dt / 4);
      work = 0;
      ++episodes;
    }
    TensorMassModel& m = *model;
    if (stroke_ticks == 0) {  // a new stroke
      const Vector3d centre =
          Vector3d(unit(rng), unit(rng), unit(rng)) * 1.1 * side - Vector3d::Constant(0.05 * side);
      const double length = 0.002 + 0.008 * unit(rng), speed = 0.0002 + 0.0013 * unit(rng);
      const Vector3d along = random_unit(rng);
      blade = {centre - 0.5 * length * along, centre + 0.5 * length * along};
      move = speed * random_unit(rng);
      turn_axis = random_unit(rng);
      turn = 0.1 * (unit(rng) - 0.5);  // rad a tick
      stroke_ticks = 3 + static_cast<int>(13 * unit(rng));
    }
    const Vector3d centre = 0.5 * (blade.a_m + blade.b_m) + move;
    const Eigen::AngleAxisd rotation(turn, turn_axis);
    const Vector3d half = rotation * (0.5 * (blade.b_m - blade.a_m));
    const Blade next{centre - half, centre + half};
    --stroke_ticks;

    const bool checked = cut % check_every == 0;
    const double h_before = checked ? energies(m)[0] : 0.0;
    try {
      swept_away += m.cut_swept_blade(blade, next, removed);
      if (cut % 7 == 0) {
        const int t = static_cast<int>(unit(rng) * nt);
        const bool was_removed = m.is_removed(t);
        ++direct;
        try {
          m.remove_tetrahedron(t);
          EXPECT_FALSE(was_removed) << "tetrahedron " << t << " removed twice";
        } catch (const InputError& e) {
          ++refused;
          EXPECT_TRUE(was_removed) << e.what();
          EXPECT_NE(std::string(e.what()).find("tetrahedron " + std::to_string(t) +
                                               " is already removed"),
                    std::string::npos)
              << e.what();
        }
      }
    } catch (const std::exception& e) {
      FAIL() << "cut " << cut << ": " << e.what();
    }
    blade = next;
    if (checked) {
      ++checks;
      // A cut takes energy away, never adds it (round-off: 10⁻⁹ of W).
      const double h_after = energies(m)[0];
      ASSERT_LE(h_after, h_before + 1e-9 * work) << "cut " << cut;
      const std::string after_cut = check_state(m);
      ASSERT_EQ(after_cut, "") << "after cut " << cut;
    }

    for (int s = 0; s < steps_per_cut; ++s) {
      force.setZero();
      for (int v = 0; v < nv; ++v)
        if (!m.is_fixed(v)) force[3 * v + 2] = -m.mass_kg(v) * kAccel;
      const VectorXd& u_minus = m.previous_displacement_m();
      // W += f·(u⁺ − u⁻)/2: u⁻ read before the step overwrites it.
      const double before_dot = force.dot(u_minus);
      m.step(dt, force);
      ++steps;
      work += 0.5 * (force.dot(m.displacement_m()) - before_dot);
      if (!checked) continue;
      const std::string after_step = check_state(m);
      ASSERT_EQ(after_step, "") << "after step " << steps << ", cut " << cut;
      const auto [shadow, energy] = energies(m);
      ASSERT_LE(shadow, work * (1 + 1e-9) + 1e-30) << "cut " << cut << ", step " << steps;
      ASSERT_LE(energy, energy_factor * work * (1 + 1e-9) + 1e-30) << "cut " << cut;
      if (work > 0) {
        worst_h_over_w = std::max(worst_h_over_w, shadow / work);
        worst_e_over_w = std::max(worst_e_over_w, energy / work);
      }
    }
  }
  std::printf(
      "%d cuts (%d steps each, Δt %.3g µs, %d checked): %ld tetrahedra swept away, %d removals "
      "by index (%d refused: already removed), %d regions, %ld steps; H/W up to %.4f, E/W up "
      "to %.4f (bound %.3f); least volume ratio %.4f; largest |u| %.3g mm\n",
      kCuts, steps_per_cut, dt * 1e6, checks, swept_away, direct, refused, episodes, steps,
      worst_h_over_w, worst_e_over_w, energy_factor, least_volume, largest_u * 1e3);
  EXPECT_GT(swept_away, 5000);  // the cuts did cut
  EXPECT_GT(refused, 0);
  EXPECT_GT(episodes, 2);
}

}  // namespace
}  // namespace palpate
