// Attachment (attachment.hpp) on small boxes: each kind of region, groups
// and id files select exactly the vertices worked out by hand from the grid;
// unknown groups, out-of-range ids and empty regions are refused naming
// them; too few or collinear fixed vertices are refused, in every part.

#include "palpate/offline/attachment.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::box_mesh;
using testing::box_vertex;
using testing::expect_error;
using testing::TempDir;

// A 0.1 × 0.05 × 0.04 m box of 4 × 2 × 2 cells: vertex (i, j, k) at
// (0.025 i, 0.025 j, 0.02 k).
constexpr int kBoxNx = 4, kBoxNy = 2, kBoxNz = 2;

TetMesh box() {
  TetMesh mesh = box_mesh(0.1, 0.05, 0.04, kBoxNx, kBoxNy, kBoxNz);
  mesh.source = "box.msh";
  return mesh;
}

int vertex(int i, int j, int k) { return box_vertex(i, j, k, kBoxNx, kBoxNy); }

/// Sorted vertex ids of the grid vertices (i, j, k) for which @p keep is true.
template <typename Keep>
std::vector<int> grid_vertices(Keep keep) {
  std::set<int> ids;
  for (int k = 0; k <= kBoxNz; ++k)
    for (int j = 0; j <= kBoxNy; ++j)
      for (int i = 0; i <= kBoxNx; ++i)
        if (keep(i, j, k)) ids.insert(vertex(i, j, k));
  return {ids.begin(), ids.end()};
}

void spit(const std::filesystem::path& p, const std::string& text) { std::ofstream(p) << text; }

/// @p a and @p b in one mesh, b's vertices that coincide exactly with one of
/// a's merged into it (so the parts touch there).
TetMesh combine(const TetMesh& a, TetMesh b, const Eigen::Vector3d& shift) {
  for (Eigen::Index v = 0; v < b.vertices.rows(); ++v) b.vertices.row(v) += shift.transpose();
  TetMesh mesh = a;
  std::vector<int> index_of_b(static_cast<std::size_t>(b.vertices.rows()), -1);
  std::vector<Eigen::RowVector3d> added;
  for (Eigen::Index v = 0; v < b.vertices.rows(); ++v) {
    for (Eigen::Index w = 0; w < a.vertices.rows(); ++w)
      if (a.vertices.row(w) == b.vertices.row(v))
        index_of_b[static_cast<std::size_t>(v)] = static_cast<int>(w);
    if (index_of_b[static_cast<std::size_t>(v)] < 0) {
      index_of_b[static_cast<std::size_t>(v)] =
          static_cast<int>(a.vertices.rows() + static_cast<Eigen::Index>(added.size()));
      added.push_back(b.vertices.row(v));
    }
  }
  mesh.vertices.conservativeResize(a.vertices.rows() + static_cast<Eigen::Index>(added.size()), 3);
  for (std::size_t i = 0; i < added.size(); ++i)
    mesh.vertices.row(a.vertices.rows() + static_cast<Eigen::Index>(i)) = added[i];
  mesh.tetrahedra.conservativeResize(a.tetrahedra.rows() + b.tetrahedra.rows(), 4);
  for (Eigen::Index t = 0; t < b.tetrahedra.rows(); ++t)
    for (int c = 0; c < 4; ++c)
      mesh.tetrahedra(a.tetrahedra.rows() + t, c) =
          index_of_b[static_cast<std::size_t>(b.tetrahedra(t, c))];
  mesh.tet_group = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());
  mesh.source_ids = Eigen::VectorXi::LinSpaced(mesh.vertices.rows(), 0,
                                               static_cast<int>(mesh.vertices.rows()) - 1);
  mesh.source = "two boxes";
  return mesh;
}

TEST(Attachment, EachRegionSelectsExactlyItsVertices) {
  const TetMesh mesh = box();
  {
    AttachmentSpec spec;  // the face x = 0, with a margin far below the spacing
    spec.boxes.push_back({{-1e-6, -1, -1}, {1e-6, 1, 1}});
    EXPECT_EQ(select_fixed_vertices(mesh, spec),
              grid_vertices([](int i, int, int) { return i == 0; }));
  }
  {
    AttachmentSpec spec;  // a box around the cells' middle layer, bounds between grid lines
    spec.boxes.push_back({{0.03, 0.01, 0.01}, {0.08, 0.04, 0.03}});
    EXPECT_EQ(select_fixed_vertices(mesh, spec), grid_vertices([](int i, int j, int k) {
                return i >= 2 && i <= 3 && j == 1 && k == 1;
              }));
  }
  {
    // A ball at the far corner of radius 0.026 m: the corner and its three
    // axis neighbours (0.025, 0.025, 0.02 m away); the nearest others are
    // √(0.025² + 0.02²) ≈ 0.032 m away.
    AttachmentSpec spec;
    spec.spheres.push_back({{0.1, 0.05, 0.04}, 0.026});
    const std::vector<int> expected{vertex(3, 2, 2), vertex(4, 1, 2), vertex(4, 2, 1),
                                    vertex(4, 2, 2)};
    std::vector<int> sorted = expected;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(select_fixed_vertices(mesh, spec), sorted);
  }
  {
    // (x − p)·n ≥ 0: x ≥ 0.09 m whatever the normal's length.
    AttachmentSpec spec;
    spec.half_spaces.push_back({{0.09, 0, 0}, {2.5, 0, 0}});
    EXPECT_EQ(select_fixed_vertices(mesh, spec),
              grid_vertices([](int i, int, int) { return i == kBoxNx; }));
  }
  {
    // z ≤ 0.01 m: the normal points down.
    AttachmentSpec spec;
    spec.half_spaces.push_back({{0, 0, 0.01}, {0, 0, -1}});
    EXPECT_EQ(select_fixed_vertices(mesh, spec),
              grid_vertices([](int, int, int k) { return k == 0; }));
  }
}

TEST(Attachment, ThePartsOfASpecAreUnited) {
  const TetMesh mesh = box();
  AttachmentSpec spec;
  spec.boxes.push_back({{-1e-6, -1, -1}, {1e-6, 1, 1}});   // x = 0
  spec.half_spaces.push_back({{0, 0, 0.01}, {0, 0, -1}});  // z = 0, overlapping x = 0
  spec.spheres.push_back({{0.1, 0.05, 0.04}, 1e-6});       // one corner
  EXPECT_EQ(select_fixed_vertices(mesh, spec), grid_vertices([](int i, int j, int k) {
              return i == 0 || k == 0 || (i == kBoxNx && j == kBoxNy && k == kBoxNz);
            }));
}

TEST(Attachment, GroupsSelectTheirVertices) {
  TetMesh mesh = box();
  mesh.group_vertices["ligament"] = {vertex(0, 0, 0), vertex(0, 2, 0), vertex(0, 1, 2)};
  mesh.group_vertices["#7"] = {vertex(4, 0, 0)};
  mesh.group_vertices["empty"] = {};
  AttachmentSpec spec;
  spec.groups = {"ligament", "#7"};
  std::vector<int> expected{vertex(0, 0, 0), vertex(0, 2, 0), vertex(0, 1, 2), vertex(4, 0, 0)};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(select_fixed_vertices(mesh, spec), expected);

  spec.groups = {"ligament", "vessel"};
  expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                           {"box.msh", "'vessel'", "#7, empty, ligament"});
  spec.groups = {"empty"};
  expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                           {"box.msh", "'empty'", "no vertex"});
}

TEST(Attachment, IdFilesAreReadInTheFilesNodeNumbering) {
  TempDir dir;
  const auto ids = dir / "ids.txt";
  spit(ids, "# held vertices\n3\n\n  17 # a comment\n\t5\t\r\n#\n3\n");
  EXPECT_EQ(read_vertex_id_file(ids), (std::vector<int>{3, 17, 5, 3}));

  // The mesh's vertex v was node v + 2 of the file (two unused nodes were
  // dropped at the start, one in the middle: node 10 is nobody's).
  TetMesh mesh = box();
  const int nv = static_cast<int>(mesh.vertices.rows());
  for (int v = 0; v < nv; ++v) mesh.source_ids[v] = v + 2 + (v >= 8 ? 1 : 0);
  mesh.source_vertex_count = nv + 3;
  AttachmentSpec spec;
  spec.ids_file = ids;
  // Nodes 3, 17, 5 are vertices 1, 14, 3.
  EXPECT_EQ(select_fixed_vertices(mesh, spec), (std::vector<int>{1, 3, 14}));
  // A node no tetrahedron uses (dropped) holds nothing; not an error.
  spit(ids, "10\n0\n4\n");
  EXPECT_EQ(select_fixed_vertices(mesh, spec), (std::vector<int>{2}));
  // Beyond the file's last node: refused with the range.
  spit(ids, "4\n" + std::to_string(nv + 3) + "\n");
  expect_error<InputError>(
      [&] { select_fixed_vertices(mesh, spec); },
      {ids.string(), "vertex index " + std::to_string(nv + 3), "0.." + std::to_string(nv + 2)});
}

TEST(Attachment, BadIdFilesAreRefusedNamingTheFileAndLine) {
  TempDir dir;
  const auto ids = dir / "ids.txt";
  spit(ids, "1\n2\nthree\n");
  expect_error<InputError>([&] { read_vertex_id_file(ids); }, {ids.string() + ":3:", "'three'"});
  spit(ids, "# ok\n-4\n");
  expect_error<InputError>([&] { read_vertex_id_file(ids); }, {ids.string() + ":2:", "'-4'"});
  spit(ids, "12 13\n");
  expect_error<InputError>([&] { read_vertex_id_file(ids); }, {ids.string() + ":1:", "'12 13'"});
  spit(ids, "99999999999\n");
  expect_error<InputError>([&] { read_vertex_id_file(ids); }, {ids.string() + ":1:"});
  expect_error<InputError>([&] { read_vertex_id_file(dir / "none.txt"); },
                           {(dir / "none.txt").string(), "cannot open"});
}

TEST(Attachment, ARegionSelectingNothingIsRefusedWithTheMeshsExtent) {
  const TetMesh mesh = box();
  const std::string extent = "the mesh spans (0, 0, 0) to (0.1, 0.05, 0.04) m";
  {
    AttachmentSpec spec;  // millimetres taken for metres: far outside
    spec.boxes.push_back({{-5, -5, -5}, {-1, -1, -1}});
    expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                             {"attachment box", "selects no vertex", extent});
  }
  {
    AttachmentSpec spec;  // between grid vertices
    spec.spheres.push_back({{0.0125, 0.0125, 0.01}, 0.005});
    expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                             {"attachment sphere", "radius 0.005", "selects no vertex", extent});
  }
  {
    AttachmentSpec spec;
    spec.half_spaces.push_back({{0.2, 0, 0}, {1, 0, 0}});
    expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                             {"attachment half-space", "selects no vertex", extent});
    spec.half_spaces[0] = {{0.05, 0, 0}, {0, 0, 0}};
    expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                             {"half-space", "non-zero"});
  }
  {
    // One empty region among good ones is still refused.
    AttachmentSpec spec;
    spec.boxes.push_back({{-1e-6, -1, -1}, {1e-6, 1, 1}});
    spec.boxes.push_back({{1, 1, 1}, {2, 2, 2}});
    expect_error<InputError>([&] { select_fixed_vertices(mesh, spec); },
                             {"attachment box", "(1, 1, 1)"});
  }
}

TEST(Attachment, ThreeVerticesNotOnOneLineAreNeeded) {
  const TetMesh mesh = box();
  // The face x = 0: nine vertices spread over a plane.
  EXPECT_NO_THROW(check_attachment_stops_rigid_motion(
      mesh, grid_vertices([](int i, int, int) { return i == 0; })));
  // A triangle is the least.
  EXPECT_NO_THROW(check_attachment_stops_rigid_motion(
      mesh, {vertex(0, 0, 0), vertex(1, 0, 0), vertex(0, 1, 0)}));

  expect_error<InputError>([&] { check_attachment_stops_rigid_motion(mesh, {}); },
                           {"box.msh", "fixes 0 vertices", "at least 3"});
  expect_error<InputError>(
      [&] {
        check_attachment_stops_rigid_motion(mesh, {vertex(0, 0, 0), vertex(4, 2, 2)});
      },
      {"box.msh", "fixes 2 vertices"});
  // An edge of the box: five vertices on the line y = z = 0.
  expect_error<InputError>(
      [&] {
        check_attachment_stops_rigid_motion(
            mesh, grid_vertices([](int, int j, int k) { return j == 0 && k == 0; }));
      },
      {"box.msh", "fixes 5 vertices all on one line"});
  // A diagonal line through the box.
  expect_error<InputError>(
      [&] {
        check_attachment_stops_rigid_motion(mesh,
                                            {vertex(0, 0, 0), vertex(2, 1, 1), vertex(4, 2, 2)});
      },
      {"fixes 3 vertices all on one line"});
}

TEST(Attachment, EachDisconnectedPartNeedsItsOwnAttachment) {
  const TetMesh one = box_mesh(0.1, 0.05, 0.04, 2, 2, 2);  // 48 tetrahedra, 27 vertices
  const TetMesh two = combine(one, one, {0.3, 0, 0});      // apart
  ASSERT_EQ(two.vertices.rows(), 54);
  std::vector<int> first_face, second_face;
  for (int k = 0; k <= 2; ++k)
    for (int j = 0; j <= 2; ++j) {
      first_face.push_back(box_vertex(0, j, k, 2, 2));
      second_face.push_back(27 + box_vertex(0, j, k, 2, 2));
    }
  expect_error<InputError>([&] { check_attachment_stops_rigid_motion(two, first_face); },
                           {"two boxes", "fixes 0 vertices", "in part 2 of 2", "tetrahedron 48"});
  expect_error<InputError>([&] { check_attachment_stops_rigid_motion(two, second_face); },
                           {"two boxes", "fixes 0 vertices", "in part 1 of 2", "tetrahedron 0"});
  std::vector<int> both = first_face;
  both.insert(both.end(), second_face.begin(), second_face.end());
  EXPECT_NO_THROW(check_attachment_stops_rigid_motion(two, both));

  // Touching along an edge only (x = 0.1, y = 0.05), the second box can turn
  // about it: the first box's clamped face x = 0.1 gives it only the three
  // vertices of that edge, on one line.
  const TetMesh hinged = combine(one, one, {0.1, 0.05, 0});
  ASSERT_EQ(hinged.vertices.rows(), 54 - 3);
  std::vector<int> far_face;
  for (int k = 0; k <= 2; ++k)
    for (int j = 0; j <= 2; ++j) far_face.push_back(box_vertex(2, j, k, 2, 2));
  expect_error<InputError>([&] { check_attachment_stops_rigid_motion(hinged, far_face); },
                           {"fixes 3 vertices all on one line", "in part 2 of 2"});
}

}  // namespace
}  // namespace palpate
