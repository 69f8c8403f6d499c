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
std::string data_item(const std::string& h5, const char* dataset, const std::string& dims,
                      const char* type, int precision, const char* indent) {
  return fmt::format(
      "{}<DataItem DataType=\"{}\" Precision=\"{}\" Dimensions=\"{}\" "
      "Format=\"HDF\">{}:{}</DataItem>\n",
      indent, type, precision, dims, h5, dataset);
}

// The node attributes both grids carry (all #V long, from the compliance file).
std::string vertex_attributes(const std::string& h5, Eigen::Index V) {
  const std::string v = std::to_string(V);
  const char* in = "          ";
  std::string s;
  s += "        <Attribute Name=\"softness_m_per_n\" AttributeType=\"Scalar\" Center=\"Node\">\n";
  s += data_item(h5, "/visualization/softness", v, "Float", 8, in);
  s += "        </Attribute>\n";
  s += "        <Attribute Name=\"fixed\" AttributeType=\"Scalar\" Center=\"Node\">\n";
  s += data_item(h5, "/visualization/fixed", v, "Int", 1, in);
  s += "        </Attribute>\n";
  s += "        <Attribute Name=\"source_vertex_id\" AttributeType=\"Scalar\" Center=\"Node\">\n";
  s += data_item(h5, "/mesh/source_vertex_ids", v, "Int", 4, in);
  s += "        </Attribute>\n";
  return s;
}

}  // namespace

std::filesystem::path xdmf_sidecar_path(const std::filesystem::path& compliance_file) {
  return std::filesystem::path(compliance_file).replace_extension(".xdmf");
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
  const Eigen::Index V = model.vertices_m.rows();
  const Eigen::Index T = model.tetrahedra.rows();
  const Eigen::Index F = model.surface_triangles.rows();
  std::string materials;
  for (size_t i = 0; i < model.materials.size(); ++i)
    materials += fmt::format("{}{} = {}", i ? ", " : "", i, model.materials[i].name);

  std::string s;
  s += "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n";
  s += "<!-- ";
  s += comment_safe(fmt::format(
      "XDMF sidecar of the palpate compliance file {} (format {}.{}), written by {}.\n"
      "     Open this file in ParaView with the Xdmf3 reader. Layout and array meanings:\n"
      "     docs/compliance-file.md, \"The XDMF sidecar\". Grid \"volume\": tetrahedra with\n"
      "     the cell array \"material\" ({}). Grid \"surface\": the boundary\n"
      "     triangles. Both carry the node arrays softness_m_per_n (m/N), fixed\n"
      "     and source_vertex_id.",
      h5_file_name, kComplianceFormatMajor, kComplianceFormatMinor, model.producer, materials));
  s += " -->\n";
  s += "<Xdmf Version=\"3.0\">\n";
  s += "  <Domain>\n";
  s += "    <Grid Name=\"organ\" GridType=\"Collection\" CollectionType=\"Spatial\">\n";

  const std::string geometry =
      "        <Geometry GeometryType=\"XYZ\">\n" +
      data_item(h5, "/mesh/vertices", fmt::format("{} 3", V), "Float", 8, "          ") +
      "        </Geometry>\n";

  // One grid's connectivity: @p count elements of @p nodes vertices each.
  auto topology = [&](const char* type, const char* dataset, Eigen::Index count, int nodes) {
    return fmt::format(
               "        <Topology TopologyType=\"{}\" NumberOfElements=\"{}\" "
               "NodesPerElement=\"{}\">\n",
               type, count, nodes) +
           data_item(h5, dataset, fmt::format("{} {}", count, nodes), "Int", 4, "          ") +
           "        </Topology>\n";
  };

  s += "      <Grid Name=\"volume\" GridType=\"Uniform\">\n";
  s += topology("Tetrahedron", "/mesh/tetrahedra", T, 4);
  s += geometry;
  s += "        <Attribute Name=\"material\" AttributeType=\"Scalar\" Center=\"Cell\">\n";
  s += data_item(h5, "/mesh/tetrahedron_material", std::to_string(T), "Int", 4, "          ");
  s += "        </Attribute>\n";
  s += vertex_attributes(h5, V);
  s += "      </Grid>\n";

  s += "      <Grid Name=\"surface\" GridType=\"Uniform\">\n";
  s += topology("Triangle", "/mesh/surface_triangles", F, 3);
  s += geometry;
  s += vertex_attributes(h5, V);
  s += "      </Grid>\n";

  s += "    </Grid>\n";
  s += "  </Domain>\n";
  s += "</Xdmf>\n";
  return s;
}

void write_xdmf_sidecar(const std::filesystem::path& compliance_file,
                        const ComplianceModel& model) {
  const auto path = xdmf_sidecar_path(compliance_file);
  const std::string text = xdmf_document(model, compliance_file.filename().string());
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

}  // namespace palpate
