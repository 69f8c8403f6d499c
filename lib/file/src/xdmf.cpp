#include "palpate/file/xdmf.hpp"

#include <fmt/format.h>

#include <fstream>

#include "palpate/core/error.hpp"
#include "palpate/file/atomic_file.hpp"

namespace palpate {

namespace {

// Text content and attribute values of XML.
std::string xml_escaped(const std::string& s) {
  std::string out;
  for (const char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// Length of the well-formed UTF-8 sequence that starts s[i] and is a
// character XML 1.0 allows (no C0 controls but tab, LF, CR); 0 if none.
size_t xml_char_length(const std::string& s, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  if (c < 0x80) return c >= 0x20 || c == '\t' || c == '\n' || c == '\r' ? 1 : 0;
  const size_t n = c >= 0xF0 && c <= 0xF4 ? 4 : c >= 0xE0 ? 3 : c >= 0xC2 && c <= 0xDF ? 2 : 0;
  if (n == 0 || (n == 3 && c > 0xEF) || i + n > s.size()) return 0;
  for (size_t k = 1; k < n; ++k)
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
  // Overlong forms, UTF-16 surrogates and code points past U+10FFFF.
  if ((c == 0xE0 && byte(i + 1) < 0xA0) || (c == 0xED && byte(i + 1) >= 0xA0) ||
      (c == 0xF0 && byte(i + 1) < 0x90) || (c == 0xF4 && byte(i + 1) >= 0x90))
    return 0;
  return n;
}

bool is_xml_text(const std::string& s) {
  for (size_t i = 0; i < s.size();) {
    const size_t n = xml_char_length(s, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

// Free text for an XML comment: what XML cannot hold becomes '?', and "--"
// (forbidden inside a comment) becomes "- -".
std::string comment_safe(const std::string& text) {
  std::string s;
  for (size_t i = 0; i < text.size();) {
    const size_t n = xml_char_length(text, i);
    s += n ? text.substr(i, n) : "?";
    i += n ? n : 1;
  }
  for (size_t at = s.find("--"); at != std::string::npos; at = s.find("--", at))
    s.replace(at, 2, "- -");
  return s;
}

// One <DataItem> that reads dataset @p dataset of the compliance file.
// @p type and @p precision are XDMF 3's names for the dataset's type
// (XdmfArrayType: "Float" 8 = float64, "Int" 4 = int32, "Char" 1 = int8; Xdmf3
// has no "Int" 1 and would read it as int32).
std::string data_item(const std::string& h5, const char* dataset, const std::string& dims,
                      const char* type, int precision) {
  return fmt::format(
      "        <DataItem DataType=\"{}\" Precision=\"{}\" Dimensions=\"{}\" "
      "Format=\"HDF\">{}:{}</DataItem>\n",
      type, precision, dims, h5, dataset);
}

// One scalar <Attribute> of @p count values (one per vertex or per cell, as
// @p center says), read from @p dataset.
std::string attribute(const std::string& h5, const char* name, const char* center,
                      const char* dataset, Eigen::Index count, const char* type, int precision) {
  return fmt::format("      <Attribute Name=\"{}\" AttributeType=\"Scalar\" Center=\"{}\">\n", name,
                     center) +
         data_item(h5, dataset, std::to_string(count), type, precision) + "      </Attribute>\n";
}

// The one Uniform grid of a sidecar: @p count cells of @p nodes vertices
// each (dataset @p cells), on all V vertices, with the node arrays both
// sidecars carry and then @p cell_attributes. meshio.read accepts exactly
// this: one <Domain> with one grid of Topology, Geometry and Attribute
// elements (meshio/xdmf/main.py), no collection. And a grid has one
// Topology (Xdmf3 keeps the last of several): hence a file per grid.
std::string one_grid_document(const std::string& comment, const char* grid, const std::string& h5,
                              const char* topology, const char* cells, Eigen::Index count,
                              int nodes, Eigen::Index V, const std::string& cell_attributes) {
  std::string s;
  s += "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n";
  s += "<!-- " + comment_safe(comment) + " -->\n";
  s += "<Xdmf Version=\"3.0\">\n";
  s += "  <Domain>\n";
  s += fmt::format("    <Grid Name=\"{}\" GridType=\"Uniform\">\n", grid);
  s += fmt::format(
      "      <Topology TopologyType=\"{}\" NumberOfElements=\"{}\" NodesPerElement=\"{}\">\n",
      topology, count, nodes);
  s += data_item(h5, cells, fmt::format("{} {}", count, nodes), "Int", 4);
  s += "      </Topology>\n";
  s += "      <Geometry GeometryType=\"XYZ\">\n";
  s += data_item(h5, "/mesh/vertices", fmt::format("{} 3", V), "Float", 8);
  s += "      </Geometry>\n";
  s += cell_attributes;
  s += attribute(h5, "softness_m_per_n", "Node", "/visualization/softness", V, "Float", 8);
  s += attribute(h5, "fixed", "Node", "/visualization/fixed", V, "Char", 1);
  s += attribute(h5, "source_vertex_id", "Node", "/mesh/source_vertex_ids", V, "Int", 4);
  s += "    </Grid>\n";
  s += "  </Domain>\n";
  s += "</Xdmf>\n";
  return s;
}

// The first lines of both sidecars' comment.
std::string comment_header(const ComplianceModel& model, const std::string& h5_file_name) {
  return fmt::format(
      "XDMF sidecar of the palpate compliance file {} (format {}.{}), written by {}.\n"
      "     Open it in ParaView with the Xdmf3 reader, or with meshio.read. Layout and\n"
      "     array meanings: docs/compliance-file.md, \"The XDMF sidecar\".\n",
      h5_file_name, kComplianceFormatMajor, kComplianceFormatMinor, model.producer);
}

// Writes @p text at @p path atomically (AtomicOutput).
void write_atomically(const std::filesystem::path& path, const std::string& text) {
  AtomicOutput out(path);
  {
    std::ofstream file(out.temp_path(), std::ios::binary | std::ios::trunc);
    file << text;
    file.close();
    if (!file)
      throw SystemError(
          fmt::format("cannot write the XDMF sidecar '{}'", out.temp_path().string()));
  }
  out.commit();
}

}  // namespace

std::filesystem::path xdmf_sidecar_path(const std::filesystem::path& compliance_file) {
  return std::filesystem::path(compliance_file).replace_extension(".xdmf");
}

std::filesystem::path xdmf_surface_sidecar_path(const std::filesystem::path& compliance_file) {
  return std::filesystem::path(compliance_file).replace_extension(".surface.xdmf");
}

void check_xdmf_sidecar_name(const std::filesystem::path& compliance_file) {
  const std::string name = compliance_file.filename().string();
  if (!is_xml_text(name))
    throw InputError(fmt::format(
        "output file name '{}' is not valid UTF-8 or holds a control character, which an XDMF "
        "(XML) file cannot refer to: rename the output, or use --no-xdmf (no ParaView sidecar)",
        name));
  if (name.find(':') != std::string::npos)
    throw InputError(fmt::format(
        "output file name '{}' contains ':', which XDMF uses to separate the file from the "
        "dataset: rename the output, or use --no-xdmf (no ParaView sidecar)",
        name));
  if (xdmf_sidecar_path(compliance_file) == compliance_file)
    throw InputError(fmt::format(
        "output path '{}' ends in .xdmf, the name of its own XDMF sidecar: name the compliance "
        "file .h5, or use --no-xdmf (no ParaView sidecar)",
        compliance_file.string()));
}

std::string xdmf_document(const ComplianceModel& model, const std::string& h5_file_name) {
  const std::string h5 = xml_escaped(h5_file_name);
  const Eigen::Index T = model.tetrahedra.rows();
  std::string materials;
  for (size_t i = 0; i < model.materials.size(); ++i)
    materials += fmt::format("{}{} = {}", i ? ", " : "", i, model.materials[i].name);
  const std::string comment =
      comment_header(model, h5_file_name) +
      fmt::format(
          "     Grid \"volume\": the tetrahedra, with the cell array \"material\" ({}),\n"
          "     and the node arrays softness_m_per_n (m/N), fixed and source_vertex_id.\n"
          "     The boundary triangles, with the same node arrays: {}.",
          materials, xdmf_surface_sidecar_path(h5_file_name).string());
  return one_grid_document(
      comment, "volume", h5, "Tetrahedron", "/mesh/tetrahedra", T, 4, model.vertices_m.rows(),
      attribute(h5, "material", "Cell", "/mesh/tetrahedron_material", T, "Int", 4));
}

std::string xdmf_surface_document(const ComplianceModel& model, const std::string& h5_file_name) {
  const std::string comment =
      comment_header(model, h5_file_name) +
      fmt::format(
          "     Grid \"surface\": the boundary triangles (outward), on all the vertices\n"
          "     (interior ones are in no triangle), with the node arrays softness_m_per_n\n"
          "     (m/N), fixed and source_vertex_id. The tetrahedra: {}.",
          xdmf_sidecar_path(h5_file_name).string());
  return one_grid_document(comment, "surface", xml_escaped(h5_file_name), "Triangle",
                           "/mesh/surface_triangles", model.surface_triangles.rows(), 3,
                           model.vertices_m.rows(), "");
}

void write_xdmf_sidecar(const std::filesystem::path& compliance_file,
                        const ComplianceModel& model) {
  const std::string h5 = compliance_file.filename().string();
  // The one the report names first; each is atomic, the pair is not.
  write_atomically(xdmf_sidecar_path(compliance_file), xdmf_document(model, h5));
  write_atomically(xdmf_surface_sidecar_path(compliance_file), xdmf_surface_document(model, h5));
}

}  // namespace palpate
