// Mesh reading (every format through Gmsh), validation errors, boundary
// extraction, STL filling and the sample organ.

#include "palpate/offline/mesh.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <fstream>
#include <functional>

#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::box_mesh;
using testing::TempDir;
using testing::write_msh22;

double total_volume(const TetMesh& mesh) {
  double v = 0;
  Matrix43d P;
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    for (int i = 0; i < 4; ++i) P.row(i) = mesh.vertices.row(mesh.tetrahedra(t, i));
    v += signed_volume(P);
  }
  return v;
}

Eigen::MatrixX3d sorted_rows(const Eigen::MatrixX3d& X) {
  std::vector<std::array<double, 3>> rows(static_cast<size_t>(X.rows()));
  for (Eigen::Index i = 0; i < X.rows(); ++i)
    rows[static_cast<size_t>(i)] = {X(i, 0), X(i, 1), X(i, 2)};
  std::sort(rows.begin(), rows.end());
  Eigen::MatrixX3d S(X.rows(), 3);
  for (Eigen::Index i = 0; i < X.rows(); ++i)
    S.row(i) << rows[static_cast<size_t>(i)][0], rows[static_cast<size_t>(i)][1],
        rows[static_cast<size_t>(i)][2];
  return S;
}

void expect_input_error(const std::function<void()>& f,
                        std::initializer_list<std::string> fragments) {
  testing::expect_error<InputError>(f, fragments);
}

TEST(Boundary, OfABoxIsClosedOutwardAndComplete) {
  const TetMesh mesh = box_mesh(0.3, 0.2, 0.1, 3, 2, 1);
  const Boundary b = extract_boundary(mesh);
  EXPECT_EQ(b.triangles.rows(), 2 * 2 * (3 * 2 + 2 * 1 + 3 * 1));
  // Divergence theorem: ∮ x·n dA = 3 V for outward normals.
  double flux = 0;
  for (Eigen::Index i = 0; i < b.triangles.rows(); ++i) {
    const Eigen::Vector3d a = mesh.vertices.row(b.triangles(i, 0)),
                          c = mesh.vertices.row(b.triangles(i, 1)),
                          d = mesh.vertices.row(b.triangles(i, 2));
    flux += ((a + c + d) / 3).dot(0.5 * (c - a).cross(d - a));
  }
  EXPECT_NEAR(flux, 3 * 0.3 * 0.2 * 0.1, 1e-12);
  // Every vertex of a 3 × 2 × 1 grid is on the surface.
  EXPECT_EQ(std::count(b.on_surface.begin(), b.on_surface.end(), true), mesh.vertices.rows());
}

TEST(Validation, DropsUnreferencedVerticesWithTheirSourceIndex) {
  TetMesh mesh = box_mesh(1, 1, 1, 1, 1, 1);
  Eigen::MatrixX3d more(mesh.vertices.rows() + 1, 3);
  more.topRows(3) = mesh.vertices.topRows(3);
  more.row(3) << 5, 5, 5;  // unreferenced, at file index 3
  more.bottomRows(mesh.vertices.rows() - 3) = mesh.vertices.bottomRows(mesh.vertices.rows() - 3);
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
    for (int i = 0; i < 4; ++i)
      if (mesh.tetrahedra(t, i) >= 3) ++mesh.tetrahedra(t, i);
  mesh.vertices = more;
  mesh.source_ids.resize(0);
  const MeshCheck check = validate_and_compact(mesh);
  ASSERT_EQ(check.dropped_vertices.size(), 1u);
  EXPECT_EQ(check.dropped_vertices[0], 3);
  EXPECT_EQ(mesh.vertices.rows(), 8);
  EXPECT_EQ(mesh.source_ids[3], 4);
  EXPECT_NEAR(total_volume(mesh), 1.0, 1e-12);
}

TEST(Validation, RejectsEachKindOfBadMeshWithItsLocation) {
  const TetMesh good = box_mesh(1, 1, 1, 1, 1, 1);
  {
    TetMesh m = good;
    m.tetrahedra.resize(0, 4);
    expect_input_error([&] { validate_and_compact(m); }, {"no tetrahedra"});
  }
  {
    TetMesh m = good;
    m.vertices(2, 1) = std::nan("");
    expect_input_error([&] { validate_and_compact(m); }, {"vertex 2", "non-finite"});
  }
  {
    TetMesh m = good;
    m.vertices(5, 0) = INFINITY;
    expect_input_error([&] { validate_and_compact(m); }, {"vertex 5", "non-finite"});
  }
  {
    TetMesh m = good;
    m.tetrahedra(4, 2) = 99;
    expect_input_error([&] { validate_and_compact(m); },
                       {"tetrahedron 4", "vertex 99", "out of range", "0..7"});
  }
  {
    TetMesh m = good;
    std::swap(m.tetrahedra(3, 0), m.tetrahedra(3, 1));
    expect_input_error([&] { validate_and_compact(m); }, {"tetrahedron 3", "inverted"});
  }
  {
    TetMesh m = good;
    m.tetrahedra(1, 3) = m.tetrahedra(1, 0);
    expect_input_error([&] { validate_and_compact(m); }, {"tetrahedron 1", "twice"});
  }
  {
    TetMesh m = good;
    // Flatten one tetrahedron onto a plane: move its apex into its base.
    m.vertices.conservativeResize(9, 3);
    m.vertices.row(8) = (m.vertices.row(m.tetrahedra(0, 0)) + m.vertices.row(m.tetrahedra(0, 1)) +
                         m.vertices.row(m.tetrahedra(0, 2))) /
                        3;
    m.tetrahedra(0, 3) = 8;
    m.source_ids.resize(0);
    expect_input_error([&] { validate_and_compact(m); }, {"tetrahedron 0", "zero volume"});
  }
  {
    // Finite coordinates whose volume overflows (NaN) passed both volume
    // tests before (found by fuzz_tet_mesh).
    TetMesh m = good;
    m.vertices *= 1e200;
    expect_input_error([&] { validate_and_compact(m); }, {"tetrahedron 0", "overflows"});
  }
  {
    // A tetrahedron given twice (found by fuzz_tet_mesh: a mesh of doubled
    // tetrahedra had no boundary at all).
    TetMesh m = good;
    m.tetrahedra.conservativeResize(m.tetrahedra.rows() + 1, 4);
    m.tetrahedra.row(m.tetrahedra.rows() - 1) = m.tetrahedra.row(2);
    m.tet_group.resize(0);
    expect_input_error([&] { validate_and_compact(m); },
                       {"tetrahedra 2 and 6", "same four vertices"});
  }
}

TEST(Boundary, RejectsNonManifoldMeshes) {
  // Two cubes sharing only an edge: that edge has four boundary triangles.
  TetMesh a = box_mesh(1, 1, 1, 1, 1, 1);
  TetMesh b = box_mesh(1, 1, 1, 1, 1, 1);
  b.vertices.rowwise() += Eigen::RowVector3d(1, 1, 0);
  TetMesh two;
  two.source = "two-cubes";
  two.vertices.resize(16, 3);
  two.vertices << a.vertices, b.vertices;
  two.tetrahedra.resize(12, 4);
  two.tetrahedra << a.tetrahedra, (b.tetrahedra.array() + 8).matrix();
  // Weld b's edge x=1,y=1 (its vertices 0 and 4 at z=0,1) to a's (3 and 7).
  for (Eigen::Index t = 6; t < 12; ++t)
    for (int i = 0; i < 4; ++i) {
      if (two.tetrahedra(t, i) == 8) two.tetrahedra(t, i) = 3;
      if (two.tetrahedra(t, i) == 12) two.tetrahedra(t, i) = 7;
    }
  validate_and_compact(two);
  expect_input_error([&] { extract_boundary(two); }, {"not a 2-manifold", "edge"});

  // A face shared by three tetrahedra: (0, 1, 7) is interior to the cube.
  TetMesh m = box_mesh(1, 1, 1, 1, 1, 1);
  m.vertices.conservativeResize(9, 3);
  m.vertices.row(8) << 2, -1, 0;
  m.tetrahedra.conservativeResize(7, 4);
  m.tetrahedra.row(6) << m.tetrahedra(0, 0), m.tetrahedra(0, 1), m.tetrahedra(0, 3), 8;
  if (signed_volume((Matrix43d() << m.vertices.row(m.tetrahedra(6, 0)),
                     m.vertices.row(m.tetrahedra(6, 1)), m.vertices.row(m.tetrahedra(6, 2)),
                     m.vertices.row(8))
                        .finished()) < 0)
    std::swap(m.tetrahedra(6, 0), m.tetrahedra(6, 1));
  m.source_ids.resize(0);
  m.source = "three";
  validate_and_compact(m);
  expect_input_error([&] { extract_boundary(m); }, {"shared by more than two tetrahedra"});
}

TEST(MeshIo, ReadsMshV2V4MeditAndVtkAlike) {
  TempDir dir;
  TetMesh box = box_mesh(0.2, 0.1, 0.1, 4, 2, 2);
  for (Eigen::Index t = 0; t < box.tetrahedra.rows(); ++t) box.tet_group[t] = t < 24 ? 1 : 2;
  box.group_names = {{1, "parenchyma"}, {2, "tumour"}};
  write_msh22(box, dir / "box.msh");
  convert_mesh_file(dir / "box.msh", dir / "box4.msh", 4.1);
  convert_mesh_file(dir / "box.msh", dir / "box.mesh");
  convert_mesh_file(dir / "box.msh", dir / "box.vtk");
  for (const char* name : {"box.msh", "box4.msh", "box.mesh", "box.vtk"}) {
    SCOPED_TRACE(name);
    TetMesh m = read_mesh(dir / name, {});
    validate_and_compact(m);
    ASSERT_EQ(m.vertices.rows(), box.vertices.rows());
    ASSERT_EQ(m.tetrahedra.rows(), box.tetrahedra.rows());
    // Medit and VTK files carry no node tags: Gmsh may write the nodes in
    // another order, so compare the vertex sets.
    EXPECT_LE((sorted_rows(m.vertices) - sorted_rows(box.vertices)).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_NEAR(total_volume(m), 0.2 * 0.1 * 0.1, 1e-14);
    if (std::string(name).find(".msh") != std::string::npos) {
      EXPECT_EQ(m.group_names.at(1), "parenchyma");
      EXPECT_EQ(m.group_names.at(2), "tumour");
      EXPECT_EQ((m.tet_group.array() == 2).count(), box.tetrahedra.rows() - 24);
    }
  }
  // Millimetres are converted to metres.
  MeshReadOptions mm;
  mm.unit = parse_length_unit("mm");
  const TetMesh small = read_mesh(dir / "box.msh", mm);
  EXPECT_NEAR(small.vertices.col(0).maxCoeff(), 0.2e-3, 1e-18);
}

TEST(MeshIo, RejectsMissingUnreadableAndForeignFiles) {
  TempDir dir;
  expect_input_error([&] { read_mesh(dir / "nope.msh", {}); }, {"nope.msh", "no such file"});
  expect_input_error([&] { read_mesh(dir.path(), {}); }, {"directory"});
  std::ofstream(dir / "empty.msh").close();
  expect_input_error([&] { read_mesh(dir / "empty.msh", {}); }, {"empty"});
  std::ofstream(dir / "junk.msh") << "this is not a mesh\n";
  EXPECT_THROW(
      {
        TetMesh m = read_mesh(dir / "junk.msh", {});
        validate_and_compact(m);
      },
      InputError);
  expect_input_error([&] { parse_length_unit("inch"); }, {"inch", "m, cm or mm"});
}

TEST(MeshIo, FillsAClosedStlSurfaceWithTetrahedra) {
  TempDir dir;
  // The boundary of a 40 mm box, written as ASCII STL in millimetres.
  const TetMesh box = box_mesh(40, 30, 20, 4, 3, 2);
  const Boundary b = extract_boundary(box);
  {
    std::ofstream stl(dir / "box.stl");
    stl << "solid box\n";
    for (Eigen::Index i = 0; i < b.triangles.rows(); ++i) {
      stl << " facet normal 0 0 0\n  outer loop\n";
      for (int k = 0; k < 3; ++k) {
        const auto x = box.vertices.row(b.triangles(i, k));
        stl << "   vertex " << x(0) << " " << x(1) << " " << x(2) << "\n";
      }
      stl << "  endloop\n endfacet\n";
    }
    stl << "endsolid box\n";
  }
  MeshReadOptions options;
  options.unit = parse_length_unit("mm");
  options.fill_size = 8;
  TetMesh m = read_mesh(dir / "box.stl", options);
  validate_and_compact(m);
  EXPECT_GT(m.tetrahedra.rows(), 50);
  EXPECT_NEAR(total_volume(m), 40e-3 * 30e-3 * 20e-3, 1e-9 * 24e-6);
  EXPECT_NO_THROW(extract_boundary(m));
}

TEST(SampleOrgan, IsALiverSizedManifoldWithATumour) {
  TempDir dir;
  write_sample_organ(dir / "organ.msh", 0.02);
  TetMesh m = read_mesh(dir / "organ.msh", {});
  validate_and_compact(m);
  EXPECT_NO_THROW(extract_boundary(m));
  ASSERT_EQ(m.group_names.size(), 2u);
  EXPECT_EQ(m.group_names.at(1), "parenchyma");
  EXPECT_EQ(m.group_names.at(2), "tumour");
  // Ellipsoid of semi-axes 80, 50, 40 mm: V = 4/3 π abc = 670.2 cm³; the
  // inscribed polyhedron of a coarse mesh is a few percent smaller.
  const double exact = 4.0 / 3.0 * M_PI * 0.08 * 0.05 * 0.04;
  EXPECT_NEAR(total_volume(m), exact, 0.08 * exact);
  // Tumour ball of radius 15 mm.
  double tumour = 0;
  Matrix43d P;
  for (Eigen::Index t = 0; t < m.tetrahedra.rows(); ++t)
    if (m.tet_group[t] == 2) {
      for (int i = 0; i < 4; ++i) P.row(i) = m.vertices.row(m.tetrahedra(t, i));
      tumour += signed_volume(P);
    }
  const double ball = 4.0 / 3.0 * M_PI * 0.015 * 0.015 * 0.015;
  EXPECT_NEAR(tumour, ball, 0.08 * ball);
}

}  // namespace
}  // namespace palpate
