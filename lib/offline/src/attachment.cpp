#include "palpate/offline/attachment.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <charconv>
#include <fstream>
#include <unordered_map>

#include "palpate/core/error.hpp"
#include "palpate/offline/mesh_io.hpp"

namespace palpate {

std::vector<int> read_vertex_id_file(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw InputError(fmt::format("{}: cannot open the vertex id file", file.string()));
  std::vector<int> ids;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) continue;
    const auto last = line.find_last_not_of(" \t\r");
    const std::string token = line.substr(first, last - first + 1);
    int id = 0;
    auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), id);
    if (ec != std::errc() || end != token.data() + token.size() || id < 0)
      throw InputError(
          fmt::format("{}:{}: '{}' is not a vertex index; expected one 0-based "
                      "integer per line",
                      file.string(), number, token));
    ids.push_back(id);
  }
  return ids;
}

std::vector<int> select_fixed_vertices(const TetMesh& mesh, const AttachmentSpec& spec) {
  const Eigen::Index nv = mesh.vertices.rows();
  std::vector<bool> fixed(nv, false);
  // Messages about regions speak the unit they were given in.
  const std::string& unit = spec.unit;
  const double scale = 1 / parse_length_unit(unit).to_metres;
  const Eigen::Vector3d lo = scale * mesh.vertices.colwise().minCoeff().transpose();
  const Eigen::Vector3d hi = scale * mesh.vertices.colwise().maxCoeff().transpose();
  const std::string extent =
      fmt::format("the mesh spans ({:.4g}, {:.4g}, {:.4g}) to ({:.4g}, {:.4g}, {:.4g}) {}", lo.x(),
                  lo.y(), lo.z(), hi.x(), hi.y(), hi.z(), unit);
  auto point = [&](const Eigen::Vector3d& x) {
    return fmt::format("({:.6g}, {:.6g}, {:.6g})", scale * x.x(), scale * x.y(), scale * x.z());
  };

  for (const auto& name : spec.groups) {
    auto it = mesh.group_vertices.find(name);
    if (it == mesh.group_vertices.end()) {
      std::string known;
      for (const auto& [g, v] : mesh.group_vertices) known += (known.empty() ? "" : ", ") + g;
      throw InputError(
          fmt::format("{}: attachment group '{}' is not a physical group of the mesh "
                      "(its groups: {})",
                      mesh.source, name, known.empty() ? "none" : known));
    }
    if (it->second.empty())
      throw InputError(fmt::format("{}: attachment group '{}' holds no vertex of a tetrahedron",
                                   mesh.source, name));
    for (int v : it->second) fixed[v] = true;
  }

  if (!spec.ids_file.empty()) {
    const auto max_source = std::max<Eigen::Index>(mesh.source_vertex_count, nv) - 1;
    std::unordered_map<int, int> index_of_source;
    for (Eigen::Index v = 0; v < nv; ++v) index_of_source[mesh.source_ids[v]] = static_cast<int>(v);
    const std::vector<int> listed = read_vertex_id_file(spec.ids_file);
    int selected = 0;
    for (int id : listed) {
      auto it = index_of_source.find(id);
      if (it == index_of_source.end()) {
        if (id > max_source)
          throw InputError(
              fmt::format("{}: vertex index {} is out of range: the mesh's nodes "
                          "are numbered 0..{}",
                          spec.ids_file.string(), id, max_source));
        continue;  // a node no tetrahedron uses: dropped with a warning, nothing to hold
      }
      fixed[it->second] = true;
      ++selected;
    }
    if (selected == 0)
      throw InputError(fmt::format(
          "{}: the vertex id file selects no vertex of a tetrahedron ({}); expected 0-based "
          "indices of the mesh file's nodes, one per line",
          spec.ids_file.string(),
          listed.empty() ? "it lists none" : "every index it lists is a node no tetrahedron uses"));
  }

  auto select = [&](auto inside, const std::string& what) {
    int count = 0;
    for (Eigen::Index v = 0; v < nv; ++v)
      if (inside(Eigen::Vector3d(mesh.vertices.row(v).transpose()))) {
        fixed[v] = true;
        ++count;
      }
    if (count == 0)
      throw InputError(fmt::format("attachment {} selects no vertex; {}", what, extent));
  };
  for (const auto& b : spec.boxes)
    select(
        [&](const Eigen::Vector3d& x) {
          return (x.array() >= b.min.array()).all() && (x.array() <= b.max.array()).all();
        },
        fmt::format("box {} to {} {}", point(b.min), point(b.max), unit));
  for (const auto& s : spec.spheres)
    select([&](const Eigen::Vector3d& x) { return (x - s.center).norm() <= s.radius; },
           fmt::format("sphere at {} {} of radius {:.6g} {}", point(s.center), unit,
                       scale * s.radius, unit));
  for (const auto& h : spec.half_spaces) {
    if (!(h.normal.norm() > 0))
      throw InputError("attachment half-space: the normal must be a non-zero vector");
    select([&](const Eigen::Vector3d& x) { return (x - h.point).dot(h.normal) >= 0; },
           fmt::format("half-space through {} {} with normal ({}, {}, {})", point(h.point), unit,
                       h.normal.x(), h.normal.y(), h.normal.z()));
  }

  std::vector<int> ids;
  for (Eigen::Index v = 0; v < nv; ++v)
    if (fixed[v]) ids.push_back(static_cast<int>(v));
  return ids;
}

void check_attachment_stops_rigid_motion(const TetMesh& mesh, const std::vector<int>& fixed) {
  int parts = 0;
  const std::vector<int> part_of_tet = solid_parts(mesh, &parts);
  std::vector<bool> is_fixed(static_cast<size_t>(mesh.vertices.rows()), false);
  for (int v : fixed) is_fixed[static_cast<size_t>(v)] = true;
  // The fixed vertices of each part (a vertex shared by parts counts for each).
  std::vector<std::vector<int>> fixed_in(static_cast<size_t>(parts));
  std::vector<Eigen::Index> first_tet(static_cast<size_t>(parts), -1);
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    const auto p = static_cast<size_t>(part_of_tet[static_cast<size_t>(t)]);
    if (first_tet[p] < 0) first_tet[p] = t;
    for (int i = 0; i < 4; ++i)
      if (is_fixed[static_cast<size_t>(mesh.tetrahedra(t, i))])
        fixed_in[p].push_back(mesh.tetrahedra(t, i));
  }
  for (int p = 0; p < parts; ++p) {
    auto& f = fixed_in[static_cast<size_t>(p)];
    std::sort(f.begin(), f.end());
    f.erase(std::unique(f.begin(), f.end()), f.end());
    std::string where;
    if (parts > 1)
      where = fmt::format(
          " in part {} of {} (the part holding tetrahedron {}; parts touching only at a "
          "vertex or an edge can turn about it)",
          p + 1, parts, first_tet[static_cast<size_t>(p)]);
    bool spread = false;
    if (f.size() >= 3) {
      // The scatter of the fixed points about their mean: its second
      // eigenvalue is the square of the second singular value of the
      // centred points, zero when they all lie on one line. (A 3×3 symmetric
      // eigensolver: an SVD of the n×3 points cost a minute of compilation
      // under ASan for the same answer.)
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (const auto v : f) mean += mesh.vertices.row(v).transpose();
      mean /= static_cast<double>(f.size());
      Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
      for (const auto v : f) {
        const Eigen::Vector3d d = mesh.vertices.row(v).transpose() - mean;
        scatter += d * d.transpose();
      }
      const Eigen::Vector3d ev =
          Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter, Eigen::EigenvaluesOnly)
              .eigenvalues();          // ascending
      spread = ev[1] > 1e-12 * ev[2];  // σ₂ > 1e-6 σ₁: not all on one line
    }
    if (!spread)
      throw InputError(fmt::format(
          "{}: the attachment fixes {} {}{}{}, which cannot stop the rigid motions: fix at "
          "least 3 vertices not on one line in every part of the organ",
          mesh.source, f.size(), f.size() == 1 ? "vertex" : "vertices",
          f.size() >= 3 ? " all on one line" : "", where));
  }
}

}  // namespace palpate
