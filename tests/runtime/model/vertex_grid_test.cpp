// The grid of the drawn vertices at rest (ToolContactEngine's candidates):
// the cells between those of a box's corners hold every vertex in the box,
// each vertex is in exactly one cell, ascending, and the grid stays bounded.

#include "palpate/runtime/model/vertex_grid.hpp"

#include <gtest/gtest.h>

#include <random>
#include <set>
#include <vector>

namespace palpate::detail {
namespace {

using Eigen::Vector3d;

/// Points on a 60 mm ellipsoid's surface (a surface, like the organ's), and
/// a few on top of each other.
std::vector<Vector3d> surface_points(int count, std::mt19937& random) {
  std::normal_distribution<double> normal;
  std::vector<Vector3d> points;
  for (int i = 0; i < count; ++i) {
    const Vector3d d = Vector3d(normal(random), normal(random), normal(random)).normalized();
    points.push_back(Vector3d(0.06 * d.x(), 0.04 * d.y(), 0.03 * d.z()) + Vector3d(0.1, -0.2, 0.3));
  }
  for (int i = 0; i < 5; ++i) points.push_back(points[static_cast<std::size_t>(i)]);
  return points;
}

TEST(VertexGrid, TheCellsOfABoxsCornersHoldEveryVertexInTheBox) {
  std::mt19937 random(17);
  const std::vector<Vector3d> points = surface_points(2000, random);
  const VertexGrid grid(points, 0.007);
  std::uniform_real_distribution<double> where(-0.1, 0.1), size(0.0, 0.05);
  int inside = 0;
  for (int trial = 0; trial < 500; ++trial) {
    // Boxes around the organ, partly or wholly outside the grid too.
    const Vector3d lo =
        Vector3d(0.1, -0.2, 0.3) + Vector3d(where(random), where(random), where(random));
    const Vector3d hi = lo + Vector3d(size(random), size(random), size(random));
    const auto a = grid.cell_of(lo), b = grid.cell_of(hi);
    std::set<int> met;
    for (int z = a[2]; z <= b[2]; ++z)
      for (int y = a[1]; y <= b[1]; ++y)
        for (int x = a[0]; x <= b[0]; ++x)
          for (const int j : grid.vertices_in({x, y, z})) met.insert(j);
    for (int j = 0; j < static_cast<int>(points.size()); ++j) {
      const Vector3d& p = points[static_cast<std::size_t>(j)];
      if ((p.array() >= lo.array()).all() && (p.array() <= hi.array()).all()) {
        ++inside;
        EXPECT_EQ(met.count(j), 1U) << "vertex " << j << " in box " << trial;
      }
    }
  }
  EXPECT_GT(inside, 1000);  // the boxes did hold vertices
}

TEST(VertexGrid, EachVertexIsInOneCellAscending) {
  std::mt19937 random(3);
  const std::vector<Vector3d> points = surface_points(500, random);
  const VertexGrid grid(points, 0.01);
  std::vector<int> seen(points.size(), 0);
  const auto last = grid.cell_of(Vector3d::Constant(1e9));
  for (int z = 0; z <= last[2]; ++z)
    for (int y = 0; y <= last[1]; ++y)
      for (int x = 0; x <= last[0]; ++x) {
        const auto cell = grid.vertices_in({x, y, z});
        for (std::size_t i = 0; i < cell.size(); ++i) {
          ++seen[static_cast<std::size_t>(cell[i])];
          if (i > 0) {
            EXPECT_LT(cell[i - 1], cell[i]);
          }
          EXPECT_EQ(grid.cell_of(points[static_cast<std::size_t>(cell[i])]),
                    (std::array<int, 3>{x, y, z}));
        }
      }
  for (std::size_t j = 0; j < points.size(); ++j) EXPECT_EQ(seen[j], 1) << "vertex " << j;
}

TEST(VertexGrid, ATinyCellIsEnlargedToABoundedGrid) {
  std::mt19937 random(5);
  const std::vector<Vector3d> points = surface_points(100, random);
  const VertexGrid grid(points, 1e-6);  // 10^15 cells if taken as given
  EXPECT_LE(grid.cell_count(), 1 << 18);
  EXPECT_GT(grid.cell_count(), 1 << 15);                                    // not collapsed either
  const VertexGrid one(std::vector<Vector3d>(3, Vector3d(1, 2, 3)), 0.01);  // one place
  EXPECT_EQ(one.cell_count(), 1);
  EXPECT_EQ(one.vertices_in({0, 0, 0}).size(), 3U);
}

}  // namespace
}  // namespace palpate::detail
