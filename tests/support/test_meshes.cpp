#include "test_meshes.hpp"

#include <unistd.h>

#include <array>
#include <fstream>
#include <random>
#include <set>
#include <stdexcept>

#include "palpate/offline/fem.hpp"

namespace palpate::testing {

TetMesh box_mesh(double lx, double ly, double lz, int nx, int ny, int nz) {
  TetMesh mesh;
  mesh.source = "box";
  mesh.vertices.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        mesh.vertices.row(box_vertex(i, j, k, nx, ny)) << lx * i / nx, ly * j / ny, lz * k / nz;
  // Kuhn: one tetrahedron per path from corner 000 to 111 along the axes.
  static constexpr std::array<std::array<int, 3>, 6> kPaths = {
      {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  mesh.tetrahedra.resize(6 * nx * ny * nz, 4);
  int t = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& path : kPaths) {
          std::array<int, 3> c = {i, j, k};
          std::array<int, 4> v;
          v[0] = box_vertex(c[0], c[1], c[2], nx, ny);
          for (int s = 0; s < 3; ++s) {
            ++c[path[s]];
            v[s + 1] = box_vertex(c[0], c[1], c[2], nx, ny);
          }
          Matrix43d P;
          for (int q = 0; q < 4; ++q) P.row(q) = mesh.vertices.row(v[q]);
          if (signed_volume(P) < 0) std::swap(v[2], v[3]);
          mesh.tetrahedra.row(t++) << v[0], v[1], v[2], v[3];
        }
  mesh.tet_group = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());
  mesh.source_ids = Eigen::VectorXi::LinSpaced(mesh.vertices.rows(), 0,
                                               static_cast<int>(mesh.vertices.rows()) - 1);
  return mesh;
}

ComplianceModel two_tetrahedra_model() {
  ComplianceModel m;
  m.vertices_m.resize(5, 3);
  m.vertices_m << 0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01, 0.01, 0.01, 0.01;
  m.tetrahedra.resize(2, 4);
  m.tetrahedra << 0, 1, 2, 3, 1, 4, 2, 3;
  m.tet_material = Eigen::VectorXi::Zero(2);
  m.materials = {{"organ", 85e3, 0.45}};
  m.surface_triangles.resize(6, 3);
  m.surface_triangles << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 4, 1, 4, 3, 2, 3, 4;
  m.fixed_vertices = Eigen::VectorXi::Constant(1, 0);
  m.source_vertex_ids = Eigen::VectorXi::LinSpaced(5, 0, 4);
  m.compliance_vertices = Eigen::VectorXi::LinSpaced(4, 1, 4);
  m.softness_m_per_n = Eigen::VectorXd::Zero(5);
  return m;
}

void write_msh22(const TetMesh& mesh, const std::filesystem::path& file) {
  std::ofstream out(file);
  out.precision(17);
  out << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
  std::set<int> groups;
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
    groups.insert(mesh.tet_group.size() ? mesh.tet_group[t] : 0);
  out << "$PhysicalNames\n" << groups.size() << "\n";
  for (int g : groups) {
    auto it = mesh.group_names.find(g);
    out << "3 " << (g == 0 ? 99 : g) << " \"";
    if (it != mesh.group_names.end())
      out << it->second;
    else
      out << 'g' << g;  // not "g" + to_string(g): GCC 12's -Wrestrict misfires on it
    out << "\"\n";
  }
  out << "$EndPhysicalNames\n$Nodes\n" << mesh.vertices.rows() << "\n";
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    out << v + 1 << " " << mesh.vertices(v, 0) << " " << mesh.vertices(v, 1) << " "
        << mesh.vertices(v, 2) << "\n";
  out << "$EndNodes\n$Elements\n" << mesh.tetrahedra.rows() << "\n";
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    const int g = mesh.tet_group.size() ? mesh.tet_group[t] : 0;
    const int phys = g == 0 ? 99 : g;
    out << t + 1 << " 4 2 " << phys << " " << phys;
    for (int i = 0; i < 4; ++i) out << " " << mesh.tetrahedra(t, i) + 1;
    out << "\n";
  }
  out << "$EndElements\n";
}

TempDir::TempDir() {
  std::random_device rd;
  path_ = std::filesystem::temp_directory_path() /
          ("palpate-test-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

}  // namespace palpate::testing
