// vertex_normals (drawn_surface.hpp) against closed forms: the octahedron's
// and boxes' outward normals, invariance under a rigid motion, zero rows
// where no triangle of non-zero area meets a vertex, and the area weighting.

#include "palpate/runtime/drawn_surface.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <random>
#include <vector>

namespace palpate {
namespace {

// The normals are unit vectors computed from a handful of products and sums
// of O(1) coordinates: each component is within ~10 ε ≈ 2e-15 of the exact
// value. 1e-13 leaves a margin and still catches a wrong weight or sign.
constexpr double kDrawnTolerance = 1e-13;

struct Builder {
  DrawnSurface surface;
  int add(const Eigen::Vector3d& p) {
    surface.vertex_ids.push_back(static_cast<std::uint32_t>(surface.vertex_ids.size() + 100));
    surface.rest_positions_m.insert(surface.rest_positions_m.end(), {p.x(), p.y(), p.z()});
    return static_cast<int>(surface.vertex_ids.size()) - 1;
  }
  void triangle(int a, int b, int c) {
    surface.triangles.insert(surface.triangles.end(),
                             {static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b),
                              static_cast<std::uint32_t>(c)});
  }
  /// Adds (a, b, c) or (a, c, b), whichever has its normal along @p outward.
  void outward(int a, int b, int c, const Eigen::Vector3d& outward) {
    const Eigen::Vector3d pa = surface.rest_position(a);
    const Eigen::Vector3d n = (surface.rest_position(b) - pa).cross(surface.rest_position(c) - pa);
    if (n.dot(outward) > 0)
      triangle(a, b, c);
    else
      triangle(a, c, b);
  }
};

/// The octahedron |x| + |y| + |z| = r: vertices ±r e_i.
DrawnSurface octahedron(double r) {
  Builder b;
  for (int axis = 0; axis < 3; ++axis)
    for (const double sign : {1.0, -1.0}) b.add(sign * r * Eigen::Vector3d::Unit(axis));
  // Vertex 2·axis is +e_axis, 2·axis + 1 is −e_axis. One face per octant.
  for (int sx = 0; sx < 2; ++sx)
    for (int sy = 0; sy < 2; ++sy)
      for (int sz = 0; sz < 2; ++sz)
        b.outward(sx, 2 + sy, 4 + sz, Eigen::Vector3d(sx ? -1 : 1, sy ? -1 : 1, sz ? -1 : 1));
  return b.surface;
}

/// The box [−a, a] × [−b, b] × [−c, c]: 8 corners, then a centre vertex per
/// face (6), each face cut into 4 triangles about its centre. Every such
/// triangle of face ±x has area b·c (base 2b, height c, or base 2c, height
/// b), and every corner is in two triangles of each of its three faces.
DrawnSurface box_surface(double a, double b, double c) {
  Builder s;
  const Eigen::Vector3d half(a, b, c);
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) s.add(Eigen::Vector3d(i ? a : -a, j ? b : -b, k ? c : -c));
  auto corner = [](int i, int j, int k) { return i + 2 * j + 4 * k; };
  for (int axis = 0; axis < 3; ++axis)
    for (const int side : {0, 1}) {
      const Eigen::Vector3d normal = (side ? 1.0 : -1.0) * Eigen::Vector3d::Unit(axis);
      const int centre = s.add(normal.cwiseProduct(half));
      // The face's corners in cyclic order around it.
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      std::array<int, 4> ring{};
      const std::array<std::array<int, 2>, 4> uv{{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
      for (int q = 0; q < 4; ++q) {
        std::array<int, 3> ijk{};
        ijk[static_cast<std::size_t>(axis)] = side;
        ijk[static_cast<std::size_t>(u)] = uv[static_cast<std::size_t>(q)][0];
        ijk[static_cast<std::size_t>(v)] = uv[static_cast<std::size_t>(q)][1];
        ring[static_cast<std::size_t>(q)] = corner(ijk[0], ijk[1], ijk[2]);
      }
      for (int q = 0; q < 4; ++q)
        s.outward(centre, ring[static_cast<std::size_t>(q)],
                  ring[static_cast<std::size_t>((q + 1) % 4)], normal);
    }
  return s.surface;
}

void expect_rows_near(const Eigen::MatrixX3d& got, const Eigen::MatrixX3d& expected) {
  ASSERT_EQ(got.rows(), expected.rows());
  for (Eigen::Index v = 0; v < got.rows(); ++v)
    EXPECT_LT((got.row(v) - expected.row(v)).norm(), kDrawnTolerance)
        << "vertex " << v << ": " << got.row(v) << " expected " << expected.row(v);
}

TEST(VertexNormals, OfAnOctahedronPointAlongTheVertices) {
  // Each vertex ±r e_i meets four faces of equal area whose normals
  // (±1, ±1, ±1)/√3 sum along ±e_i.
  const DrawnSurface s = octahedron(0.02);
  ASSERT_EQ(s.triangle_count(), 8);
  Eigen::MatrixX3d expected(6, 3);
  for (int v = 0; v < 6; ++v) expected.row(v) = s.rest_position(v).normalized().transpose();
  expect_rows_near(vertex_normals(s), expected);
}

TEST(VertexNormals, OfABoxAreTheFaceNormalsAndTheAreaWeightedCornerNormals) {
  for (const Eigen::Vector3d& half :
       {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(0.01, 0.02, 0.03)}) {
    const DrawnSurface s = box_surface(half.x(), half.y(), half.z());
    ASSERT_EQ(s.vertex_count(), 14);
    ASSERT_EQ(s.triangle_count(), 24);
    const Eigen::MatrixX3d normals = vertex_normals(s);
    // Corner (sx a, sy b, sz c): two triangles of area bc on face ±x, ca on
    // ±y, ab on ±z, so n ∝ (sx bc, sy ca, sz ab) ∝ (sx/a, sy/b, sz/c). For
    // a cube, (±1, ±1, ±1)/√3.
    Eigen::MatrixX3d expected(14, 3);
    for (int v = 0; v < 8; ++v) {
      const Eigen::Vector3d p = s.rest_position(v);
      expected.row(v) = p.cwiseQuotient(half).cwiseQuotient(half).normalized().transpose();
    }
    for (int v = 8; v < 14; ++v)  // face centres: the face's normal
      expected.row(v) = s.rest_position(v).cwiseQuotient(half).transpose();
    expect_rows_near(normals, expected);
    if (half == Eigen::Vector3d(1, 1, 1)) {
      EXPECT_NEAR(std::abs(normals(0, 0)), 1 / std::sqrt(3.0), kDrawnTolerance);
    }
  }
}

TEST(VertexNormals, TurnWithTheSurface) {
  // Rotated and moved rigidly, the surface has its normals rotated.
  std::mt19937 rng(42);
  std::normal_distribution<double> gauss;
  const Eigen::Quaterniond q =
      Eigen::Quaterniond(gauss(rng), gauss(rng), gauss(rng), gauss(rng)).normalized();
  const Eigen::Matrix3d R = q.toRotationMatrix();
  const Eigen::Vector3d shift(0.3, -0.2, 0.7);
  for (DrawnSurface s : {octahedron(0.05), box_surface(0.01, 0.02, 0.03)}) {
    const Eigen::MatrixX3d before = vertex_normals(s);
    for (int v = 0; v < s.vertex_count(); ++v) {
      const Eigen::Vector3d p = R * s.rest_position(v) + shift;
      std::copy(p.data(), p.data() + 3, &s.rest_positions_m[3 * static_cast<std::size_t>(v)]);
    }
    // The coordinates now carry the shift's round-off (~1e-16 m on
    // 0.01 m edges, relative 1e-14): the normals move by as much.
    const Eigen::MatrixX3d after = vertex_normals(s);
    for (int v = 0; v < s.vertex_count(); ++v)
      EXPECT_LT((after.row(v).transpose() - R * before.row(v).transpose()).norm(), 1e-12)
          << "vertex " << v;
  }
}

TEST(VertexNormals, AreZeroWhereNoTriangleOfNonZeroAreaMeetsAVertex) {
  Builder b;
  const int o = b.add({0, 0, 0}), x = b.add({1, 0, 0}), y = b.add({0, 1, 0});
  b.triangle(o, x, y);
  const int lonely = b.add({5, 5, 5});  // in no triangle
  // A degenerate triangle: three points on a line.
  const int p = b.add({0, 0, 2}), q = b.add({1, 1, 2}), r = b.add({3, 3, 2});
  b.triangle(p, q, r);
  // A vertex in a triangle whose area is 0 because two corners coincide.
  const int s = b.add({7, 0, 0}), t = b.add({7, 0, 0}), w = b.add({7, 1, 0});
  b.triangle(s, t, w);
  const Eigen::MatrixX3d normals = vertex_normals(b.surface);
  for (int v : {o, x, y})
    EXPECT_LT((normals.row(v) - Eigen::RowVector3d(0, 0, 1)).norm(), kDrawnTolerance);
  for (int v : {lonely, p, q, r, s, t, w})
    EXPECT_EQ(normals.row(v), Eigen::RowVector3d::Zero()) << "vertex " << v;
}

TEST(VertexNormals, OppositeFacesOfAFlatSheetCancel) {
  // The same triangle both ways round: (b − a) × (c − a) and its exact
  // negative sum to zero, so its corners have no normal.
  Builder b;
  const int a = b.add({0.1, 0.2, 0.3}), c = b.add({0.4, 0.2, 0.1}), d = b.add({0.2, 0.5, 0.3});
  b.triangle(a, c, d);
  b.triangle(a, d, c);
  const Eigen::MatrixX3d normals = vertex_normals(b.surface);
  for (int v : {a, c, d}) EXPECT_EQ(normals.row(v), Eigen::RowVector3d::Zero());
}

TEST(VertexNormals, WeighTheTrianglesByTheirAreas) {
  // Vertex o in a large triangle (legs L in the z = 0 plane, normal +z,
  // area L²/2) and a small one (legs s in the y = 0 plane, normal +y, area
  // s²/2): n_o = (0, s², L²)/√(s⁴ + L⁴), not the plain average (0, 1, 1)/√2.
  const double L = 2.0, s = 0.5;
  Builder b;
  const int o = b.add({0, 0, 0});
  const int lx = b.add({L, 0, 0}), ly = b.add({0, L, 0});
  const int sz = b.add({0, 0, s}), sx = b.add({s, 0, 0});
  b.triangle(o, lx, ly);  // (L, 0, 0) × (0, L, 0) = (0, 0, L²)
  b.triangle(o, sz, sx);  // (0, 0, s) × (s, 0, 0) = (0, s², 0)
  const Eigen::MatrixX3d normals = vertex_normals(b.surface);
  const Eigen::RowVector3d expected =
      Eigen::RowVector3d(0, s * s, L * L) / std::sqrt(std::pow(s, 4) + std::pow(L, 4));
  EXPECT_LT((normals.row(o) - expected).norm(), kDrawnTolerance) << normals.row(o);
  // The vertices of one triangle only have that triangle's normal.
  EXPECT_LT((normals.row(lx) - Eigen::RowVector3d(0, 0, 1)).norm(), kDrawnTolerance);
  EXPECT_LT((normals.row(sx) - Eigen::RowVector3d(0, 1, 0)).norm(), kDrawnTolerance);
  // Unit rows.
  for (int v = 0; v < normals.rows(); ++v) EXPECT_NEAR(normals.row(v).norm(), 1.0, kDrawnTolerance);
}

}  // namespace
}  // namespace palpate
