#include "palpate/runtime/surface_model.hpp"

#include "palpate/core/error.hpp"
#include "palpate/file/compliance_file.hpp"

namespace palpate {

SurfaceModel load_surface_model(std::string id, const std::filesystem::path& path,
                                bool keep_float32) {
  SurfaceModel model;
  model.id = std::move(id);
  model.path = path;
  const ComplianceModel file = keep_float32 ? read_compliance_file(path, &model.G, &model.G32)
                                            : read_compliance_file(path, &model.G);
  model.material_summary = file.material_summary;
  model.input_hash = file.input_hash;
  if (file.cut_region) {
    model.cut_region_spec = file.cut_region->spec;
    model.cut_region = std::make_shared<const CutRegionData>(*file.cut_region);
  }
  model.source_vertex_ids.assign(file.source_vertex_ids.begin(), file.source_vertex_ids.end());

  const auto vertex_count = static_cast<std::size_t>(file.vertices_m.rows());
  model.compliance_index_of_vertex.assign(vertex_count,
                                          static_cast<std::int32_t>(VertexRole::kInterior));
  for (int fixed : file.fixed_vertices)
    model.compliance_index_of_vertex[static_cast<std::size_t>(fixed)] =
        static_cast<std::int32_t>(VertexRole::kFixed);

  // Compliance vertices first, in compliance order, then every other vertex
  // the surface triangles use (the fixed ones: read_compliance_file checked
  // that the compliance set is the surface minus the fixed vertices).
  std::vector<std::int32_t> drawn_index(vertex_count, -1);
  auto draw = [&](int vertex) {
    drawn_index[static_cast<std::size_t>(vertex)] =
        static_cast<std::int32_t>(model.surface.vertex_ids.size());
    model.surface.vertex_ids.push_back(static_cast<std::uint32_t>(vertex));
    for (int axis = 0; axis < 3; ++axis)
      model.surface.rest_positions_m.push_back(file.vertices_m(vertex, axis));
  };
  for (Eigen::Index i = 0; i < file.compliance_vertices.size(); ++i) {
    const int vertex = file.compliance_vertices(i);
    model.compliance_index_of_vertex[static_cast<std::size_t>(vertex)] =
        static_cast<std::int32_t>(i);
    draw(vertex);
  }
  model.surface.compliance_vertex_count = static_cast<int>(file.compliance_vertices.size());
  model.surface.triangles.reserve(static_cast<std::size_t>(file.surface_triangles.size()));
  for (Eigen::Index t = 0; t < file.surface_triangles.rows(); ++t) {
    for (int corner = 0; corner < 3; ++corner) {
      const int vertex = file.surface_triangles(t, corner);
      if (drawn_index[static_cast<std::size_t>(vertex)] < 0) {
        if (model.compliance_index_of_vertex[static_cast<std::size_t>(vertex)] !=
            static_cast<std::int32_t>(VertexRole::kFixed))
          throw InputError(
              path.string() + ": surface vertex " + std::to_string(vertex) +
              " is neither fixed nor in /compliance/vertex_ids (the compliance set must be "
              "the surface minus the fixed vertices)");
        draw(vertex);
      }
      model.surface.triangles.push_back(
          static_cast<std::uint32_t>(drawn_index[static_cast<std::size_t>(vertex)]));
    }
  }
  return model;
}

}  // namespace palpate
