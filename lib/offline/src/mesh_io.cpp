#include "palpate/offline/mesh_io.hpp"

#include <fmt/format.h>
#include <gmsh.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <mutex>
#include <unordered_map>

#include "palpate/core/error.hpp"

namespace palpate {

namespace {

// Gmsh is one global state: one session at a time, with its terminal output
// silenced and its log captured so that errors become exceptions.
class GmshSession {
 public:
  GmshSession() : lock_(mutex()) {
    gmsh::initialize(0, nullptr, false);
    gmsh::option::setNumber("General.Terminal", 0);
    gmsh::option::setNumber("General.Verbosity", 2);
    gmsh::logger::start();
  }
  ~GmshSession() {
    gmsh::logger::stop();
    gmsh::finalize();
  }
  GmshSession(const GmshSession&) = delete;
  GmshSession& operator=(const GmshSession&) = delete;

  /// The first error Gmsh logged since the last call, or "".
  static std::string take_error() {
    std::vector<std::string> log;
    gmsh::logger::get(log);
    for (const auto& line : log)
      if (line.rfind("Error", 0) == 0) {
        std::string msg = line.substr(line.find(':') == std::string::npos ? 0 : line.find(':') + 1);
        while (!msg.empty() && msg.front() == ' ') msg.erase(msg.begin());
        return msg;
      }
    return {};
  }

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  std::lock_guard<std::mutex> lock_;
};

std::string lower_extension(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext;
}

void require_readable(const std::filesystem::path& file) {
  std::error_code ec;
  if (!std::filesystem::exists(file, ec))
    throw InputError(fmt::format("{}: no such file", file.string()));
  if (std::filesystem::is_directory(file, ec))
    throw InputError(fmt::format("{}: is a directory, not a mesh file", file.string()));
  std::ifstream in(file, std::ios::binary);
  if (!in || in.peek() == std::ifstream::traits_type::eof())
    throw InputError(fmt::format("{}: cannot be read, or is empty", file.string()));
}

// Fills the closed surface just merged into the model with tetrahedra, the
// way Gmsh's tutorial t13 remeshes an STL: classify the triangles into
// patches, give them a parametrization, and mesh the enclosed volume.
void fill_surface(const std::filesystem::path& file, double size) {
  gmsh::model::mesh::classifySurfaces(40 * M_PI / 180, true, true, M_PI);
  gmsh::model::mesh::createGeometry();
  gmsh::vectorpair surfaces;
  gmsh::model::getEntities(surfaces, 2);
  if (surfaces.empty())
    throw InputError(fmt::format("{}: no triangles found to fill", file.string()));
  std::vector<int> tags;
  for (const auto& [dim, tag] : surfaces) tags.push_back(tag);
  const int loop = gmsh::model::geo::addSurfaceLoop(tags);
  gmsh::model::geo::addVolume({loop});
  gmsh::model::geo::synchronize();
  gmsh::option::setNumber("Mesh.MeshSizeMax", size);
  gmsh::option::setNumber("Mesh.MeshSizeMin", size / 4);
  gmsh::model::mesh::generate(3);
  if (auto err = GmshSession::take_error(); !err.empty())
    throw InputError(
        fmt::format("{}: Gmsh could not fill the surface with tetrahedra: {}; "
                    "the surface must be closed and free of self-intersections",
                    file.string(), err));
}

}  // namespace

LengthUnit parse_length_unit(const std::string& name) {
  if (name == "m") return {"m", 1.0};
  if (name == "cm") return {"cm", 0.01};
  if (name == "mm") return {"mm", 0.001};
  throw InputError(fmt::format("mesh unit '{}' is not accepted: use m, cm or mm", name));
}

namespace {

TetMesh read_with_gmsh(const std::filesystem::path& file, const MeshReadOptions& options) {
  const std::string ext = lower_extension(file);
  if (ext == ".stl") {
    gmsh::merge(file.string());
  } else {
    gmsh::open(file.string());
  }
  if (auto err = GmshSession::take_error(); !err.empty())
    throw InputError(fmt::format("{}: Gmsh cannot read it: {}", file.string(), err));

  if (ext == ".stl") {
    double size = options.fill_size;
    if (!(size >= 0) || !std::isfinite(size))
      throw InputError(
          fmt::format("fill size {} is not accepted: use a length > 0 in the "
                      "mesh's unit, or 0 for automatic",
                      size));
    if (size == 0) {
      std::vector<double> bbox(6);
      gmsh::model::getBoundingBox(-1, -1, bbox[0], bbox[1], bbox[2], bbox[3], bbox[4], bbox[5]);
      size = std::hypot(bbox[3] - bbox[0], bbox[4] - bbox[1], bbox[5] - bbox[2]) / 20;
    }
    fill_surface(file, size);
  }

  TetMesh mesh;
  mesh.source = file.string();

  std::vector<std::size_t> node_tags;
  std::vector<double> coords, params;
  gmsh::model::mesh::getNodes(node_tags, coords, params, -1, -1, false, false);
  std::vector<std::size_t> order(node_tags.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return node_tags[a] < node_tags[b]; });
  std::unordered_map<std::size_t, int> index_of_tag;
  index_of_tag.reserve(node_tags.size());
  mesh.vertices.resize(static_cast<Eigen::Index>(node_tags.size()), 3);
  for (size_t r = 0; r < order.size(); ++r) {
    const size_t i = order[r];
    if (!index_of_tag.emplace(node_tags[i], static_cast<int>(r)).second) continue;
    for (int a = 0; a < 3; ++a)
      mesh.vertices(static_cast<Eigen::Index>(r), a) = coords[3 * i + a] * options.unit.to_metres;
  }

  std::vector<int> types;
  gmsh::model::mesh::getElementTypes(types, 3);
  for (int type : types)
    if (type != 4) {
      std::string name;
      int dim, order_, nodes, primary;
      std::vector<double> local;
      gmsh::model::mesh::getElementProperties(type, name, dim, order_, nodes, local, primary);
      throw InputError(
          fmt::format("{}: holds {} elements; palpate accepts linear (4-node) "
                      "tetrahedra only (re-mesh into first-order tetrahedra)",
                      file.string(), name));
    }

  std::vector<std::size_t> elem_tags, elem_nodes;
  gmsh::model::mesh::getElementsByType(4, elem_tags, elem_nodes);
  mesh.tetrahedra.resize(static_cast<Eigen::Index>(elem_tags.size()), 4);
  std::unordered_map<std::size_t, Eigen::Index> tet_of_tag;
  tet_of_tag.reserve(elem_tags.size());
  for (size_t t = 0; t < elem_tags.size(); ++t) {
    tet_of_tag[elem_tags[t]] = static_cast<Eigen::Index>(t);
    for (int i = 0; i < 4; ++i) {
      auto it = index_of_tag.find(elem_nodes[4 * t + i]);
      // An unknown node tag becomes an out-of-range index that validation reports.
      mesh.tetrahedra(static_cast<Eigen::Index>(t), i) = it == index_of_tag.end() ? -1 : it->second;
    }
  }
  mesh.tet_group = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());

  gmsh::vectorpair groups;
  gmsh::model::getPhysicalGroups(groups);
  for (const auto& [dim, tag] : groups) {
    std::string name;
    gmsh::model::getPhysicalName(dim, tag, name);
    if (name.empty()) name = fmt::format("#{}", tag);
    if (dim == 3) {
      mesh.group_names[tag] = name;
      std::vector<int> entities;
      gmsh::model::getEntitiesForPhysicalGroup(dim, tag, entities);
      for (int entity : entities) {
        std::vector<std::size_t> tags, nodes;
        gmsh::model::mesh::getElementsByType(4, tags, nodes, entity);
        for (auto et : tags)
          if (auto it = tet_of_tag.find(et); it != tet_of_tag.end())
            mesh.tet_group[it->second] = tag;
      }
    }
    std::vector<std::size_t> tags;
    std::vector<double> xyz;
    gmsh::model::mesh::getNodesForPhysicalGroup(dim, tag, tags, xyz);
    auto& ids = mesh.group_vertices[name];
    for (auto nt : tags)
      if (auto it = index_of_tag.find(nt); it != index_of_tag.end()) ids.push_back(it->second);
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    // A named group answers to its tag too ("#2").
    if (name[0] != '#') mesh.group_vertices[fmt::format("#{}", tag)] = ids;
  }
  return mesh;
}

// Gmsh 4.8 reports some failures by throwing the message as a std::string.
template <typename Error, typename F>
auto guarded(const std::string& context, F f) {
  try {
    return f();
  } catch (const InputError&) {
    throw;
  } catch (const SystemError&) {
    throw;
  } catch (const std::string& message) {
    throw Error(fmt::format("{}: {}", context, message));
  } catch (const std::exception& e) {
    throw Error(fmt::format("{}: {}", context, e.what()));
  }
}

}  // namespace

TetMesh read_mesh(const std::filesystem::path& file, const MeshReadOptions& options) {
  require_readable(file);
  GmshSession session;
  return guarded<InputError>(fmt::format("{}: Gmsh cannot read it", file.string()),
                             [&] { return read_with_gmsh(file, options); });
}

namespace {

void generate_sample_organ(const std::filesystem::path& file, double mesh_size_m) {
  gmsh::model::add("palpate-sample-organ");
  // Liver-sized ellipsoid: a unit sphere scaled to semi-axes 80 × 50 × 40 mm.
  const int body = gmsh::model::occ::addSphere(0, 0, 0, 1);
  gmsh::model::occ::dilate({{3, body}}, 0, 0, 0, 0.080, 0.050, 0.040);
  const int tumour = gmsh::model::occ::addSphere(0.030, -0.005, 0.0, 0.015);
  gmsh::vectorpair out;
  std::vector<gmsh::vectorpair> map;
  gmsh::model::occ::fragment({{3, body}}, {{3, tumour}}, out, map);
  gmsh::model::occ::synchronize();
  // After the fragment, map[1] holds the tumour and map[0] the body pieces.
  std::vector<int> tumour_vols, parenchyma_vols;
  for (const auto& [dim, tag] : map[1]) tumour_vols.push_back(tag);
  for (const auto& [dim, tag] : map[0])
    if (std::find(tumour_vols.begin(), tumour_vols.end(), tag) == tumour_vols.end())
      parenchyma_vols.push_back(tag);
  gmsh::model::addPhysicalGroup(3, parenchyma_vols, 1);
  gmsh::model::setPhysicalName(3, 1, "parenchyma");
  gmsh::model::addPhysicalGroup(3, tumour_vols, 2);
  gmsh::model::setPhysicalName(3, 2, "tumour");
  // The tumour is resolved by at least four elements across its radius.
  const int ball = gmsh::model::mesh::field::add("Ball");
  gmsh::model::mesh::field::setNumber(ball, "XCenter", 0.030);
  gmsh::model::mesh::field::setNumber(ball, "YCenter", -0.005);
  gmsh::model::mesh::field::setNumber(ball, "ZCenter", 0.0);
  gmsh::model::mesh::field::setNumber(ball, "Radius", 0.018);
  gmsh::model::mesh::field::setNumber(ball, "VIn", std::min(mesh_size_m, 0.015 / 4));
  gmsh::model::mesh::field::setNumber(ball, "VOut", mesh_size_m);
  gmsh::model::mesh::field::setAsBackgroundMesh(ball);
  gmsh::option::setNumber("Mesh.MeshSizeMax", mesh_size_m);
  gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 0);
  gmsh::option::setNumber("Mesh.MeshSizeExtendFromBoundary", 0);
  gmsh::option::setNumber("Mesh.Algorithm3D", 1);
  gmsh::option::setNumber("Mesh.RandomSeed", 1);
  gmsh::model::mesh::generate(3);
  gmsh::option::setNumber("Mesh.MshFileVersion", 4.1);
  gmsh::option::setNumber("Mesh.Binary", 0);
  gmsh::option::setNumber("Mesh.SaveAll", 0);
  gmsh::write(file.string());
  if (auto err = GmshSession::take_error(); !err.empty())
    throw SystemError(
        fmt::format("{}: Gmsh could not generate the sample organ: {}", file.string(), err));
  if (!std::filesystem::exists(file))
    throw SystemError(fmt::format("{}: Gmsh did not write the sample organ", file.string()));
}

}  // namespace

void write_sample_organ(const std::filesystem::path& file, double mesh_size_m) {
  if (!(mesh_size_m > 0))
    throw InputError(
        fmt::format("sample organ mesh size {} m is not accepted: use a length > 0", mesh_size_m));
  GmshSession session;
  guarded<SystemError>(fmt::format("{}: Gmsh could not generate the sample organ", file.string()),
                       [&] { generate_sample_organ(file, mesh_size_m); });
}

void convert_mesh_file(const std::filesystem::path& input, const std::filesystem::path& output,
                       double msh_version) {
  require_readable(input);
  GmshSession session;
  guarded<SystemError>(
      fmt::format("{} → {}: Gmsh could not convert", input.string(), output.string()), [&] {
        gmsh::open(input.string());
        gmsh::option::setNumber("Mesh.MshFileVersion", msh_version);
        gmsh::option::setNumber("Mesh.Binary", 0);
        gmsh::option::setNumber("Mesh.SaveAll", 1);
        gmsh::write(output.string());
      });
  if (auto err = GmshSession::take_error(); !err.empty())
    throw SystemError(
        fmt::format("{} → {}: Gmsh could not convert: {}", input.string(), output.string(), err));
}

}  // namespace palpate
