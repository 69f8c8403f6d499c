#include "palpate/compliance_file.hpp"

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include <hdf5.h>

#include <fmt/format.h>

#include "hdf5_support.hpp"
#include "palpate/atomic_file.hpp"
#include "palpate/error.hpp"

namespace palpate {

namespace {

using hdf5::check;
using hdf5::Handle;
using hdf5::silence_hdf5;
using hdf5::string_type;
using hdf5::write_int_attribute;
using hdf5::write_string_attribute;

// Row-major [rows, cols] dataset from a column-major Eigen matrix: the file
// holds the transpose of Eigen's memory layout, so write Mᵀ's storage.
template <typename Matrix>
void write_matrix(hid_t parent, const char* name, const Matrix& M, hid_t mem_type, hid_t file_type) {
  using Scalar = typename Matrix::Scalar;
  const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = M;
  hsize_t dims[2] = {static_cast<hsize_t>(M.rows()), static_cast<hsize_t>(M.cols())};
  Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose, "create a dataspace");
  Handle set(H5Dcreate2(parent, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
             H5Dclose, fmt::format("create dataset {}", name));
  if (rows.size() > 0)
    check(H5Dwrite(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows.data()),
          fmt::format("write dataset {}", name));
}

template <typename Vector>
void write_vector(hid_t parent, const char* name, const Vector& v, hid_t mem_type, hid_t file_type) {
  hsize_t dims[1] = {static_cast<hsize_t>(v.size())};
  Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose, "create a dataspace");
  Handle set(H5Dcreate2(parent, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
             H5Dclose, fmt::format("create dataset {}", name));
  if (v.size() > 0)
    check(H5Dwrite(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()),
          fmt::format("write dataset {}", name));
}

void write_strings(hid_t parent, const char* name, const std::vector<std::string>& values) {
  Handle type = string_type();
  hsize_t dims[1] = {values.size()};
  Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose, "create a dataspace");
  Handle set(H5Dcreate2(parent, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Dclose,
             fmt::format("create dataset {}", name));
  std::vector<const char*> data;
  for (const auto& s : values) data.push_back(s.c_str());
  if (!data.empty()) check(H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), name);
}

// ---- reading ---------------------------------------------------------------

struct Reader {
  std::string file;
  hid_t root;

  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw InputError(fmt::format("{}: {}: {}", file, where, what));
  }

  std::vector<hsize_t> dims(const char* name, int rank) const {
    if (H5Lexists(root, name, H5P_DEFAULT) <= 0)
      fail(name, "missing; a palpate compliance file has it (docs/compliance-file.md)");
    Handle set(H5Dopen2(root, name, H5P_DEFAULT), H5Dclose, fmt::format("open {}", name));
    Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
    const int r = H5Sget_simple_extent_ndims(space);
    if (r != rank) fail(name, fmt::format("has rank {}, expected {}", r, rank));
    std::vector<hsize_t> d(static_cast<size_t>(rank));
    H5Sget_simple_extent_dims(space, d.data(), nullptr);
    return d;
  }

  void read(const char* name, hid_t mem_type, void* out) const {
    Handle set(H5Dopen2(root, name, H5P_DEFAULT), H5Dclose, fmt::format("open {}", name));
    if (H5Dread(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out) < 0)
      fail(name, "cannot be read (corrupt or of a wrong type)");
  }

  template <typename Scalar, int Cols>
  Eigen::Matrix<Scalar, Eigen::Dynamic, Cols> matrix(const char* name, hid_t mem_type) const {
    const auto d = dims(name, 2);
    if (Cols != Eigen::Dynamic && d[1] != static_cast<hsize_t>(Cols))
      fail(name, fmt::format("has {} columns, expected {}", d[1], Cols));
    Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows(d[0], d[1]);
    if (rows.size() > 0) read(name, mem_type, rows.data());
    return rows;
  }

  Eigen::VectorXi ints(const char* name) const {
    const auto d = dims(name, 1);
    Eigen::VectorXi v(static_cast<Eigen::Index>(d[0]));
    if (v.size() > 0) read(name, H5T_NATIVE_INT, v.data());
    return v;
  }

  std::string string_attribute(const char* name, bool required = true) const {
    if (H5Aexists(root, name) <= 0) {
      if (required) fail(fmt::format("attribute {}", name), "missing");
      return {};
    }
    Handle attr(H5Aopen(root, name, H5P_DEFAULT), H5Aclose, fmt::format("open attribute {}", name));
    Handle type = string_type();
    char* data = nullptr;
    if (H5Aread(attr, type, &data) < 0) fail(fmt::format("attribute {}", name), "not a string");
    std::string s = data ? data : "";
    Handle space(H5Aget_space(attr), H5Sclose, "get a dataspace");
    H5Dvlen_reclaim(type, space, H5P_DEFAULT, &data);
    return s;
  }

  int int_attribute(const char* name) const {
    if (H5Aexists(root, name) <= 0) fail(fmt::format("attribute {}", name), "missing");
    Handle attr(H5Aopen(root, name, H5P_DEFAULT), H5Aclose, fmt::format("open attribute {}", name));
    int value = 0;
    if (H5Aread(attr, H5T_NATIVE_INT, &value) < 0) fail(fmt::format("attribute {}", name), "not an integer");
    return value;
  }
};

}  // namespace

void write_compliance_file(const std::filesystem::path& path, const ComplianceModel& model,
                           CRef<Eigen::MatrixXd> G) {
  const Eigen::Index n = model.compliance_vertices.size();
  PALPATE_DEMAND(G.rows() == 3 * n && G.cols() == 3 * n);
  PALPATE_DEMAND(model.softness_m_per_n.size() == model.vertices_m.rows());
  silence_hdf5();
  AtomicOutput out(path);
  {
    Handle file(H5Fcreate(out.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT),
                H5Fclose, fmt::format("create {}", out.temp_path().string()));
    write_string_attribute(file, "format", kComplianceFormatName);
    write_int_attribute(file, "format_version_major", kComplianceFormatMajor);
    write_int_attribute(file, "format_version_minor", kComplianceFormatMinor);
    write_string_attribute(file, "producer", model.producer);
    write_string_attribute(file, "method", model.method);
    write_string_attribute(file, "units", "SI: lengths in m, forces in N, moduli in Pa; G in m/N");
    write_string_attribute(file, "material_summary", model.material_summary);
    write_string_attribute(file, "created_utc", model.created_utc);
    write_string_attribute(file, "input_hash", model.input_hash);
    write_string_attribute(file, "job_toml", model.job_toml);
    write_string_attribute(file, "report_json", model.report_json);

    Handle mesh(H5Gcreate2(file, "mesh", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                "create group /mesh");
    write_matrix(mesh, "vertices", model.vertices_m, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE);
    write_matrix(mesh, "tetrahedra", model.tetrahedra, H5T_NATIVE_INT, H5T_STD_I32LE);
    write_vector(mesh, "tetrahedron_material", model.tet_material, H5T_NATIVE_INT, H5T_STD_I32LE);
    write_matrix(mesh, "surface_triangles", model.surface_triangles, H5T_NATIVE_INT, H5T_STD_I32LE);
    write_vector(mesh, "fixed_vertex_ids", model.fixed_vertices, H5T_NATIVE_INT, H5T_STD_I32LE);
    write_vector(mesh, "source_vertex_ids", model.source_vertex_ids, H5T_NATIVE_INT, H5T_STD_I32LE);

    Handle material(H5Gcreate2(file, "material", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                    "create group /material");
    std::vector<std::string> names;
    Eigen::VectorXd E(static_cast<Eigen::Index>(model.materials.size())), nu(E.size());
    for (size_t i = 0; i < model.materials.size(); ++i) {
      names.push_back(model.materials[i].name);
      E[static_cast<Eigen::Index>(i)] = model.materials[i].young_modulus_pa;
      nu[static_cast<Eigen::Index>(i)] = model.materials[i].poisson_ratio;
    }
    write_strings(material, "name", names);
    write_vector(material, "young_modulus_pa", E, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE);
    write_vector(material, "poisson_ratio", nu, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE);

    Handle compliance(H5Gcreate2(file, "compliance", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                      H5Gclose, "create group /compliance");
    write_vector(compliance, "vertex_ids", model.compliance_vertices, H5T_NATIVE_INT, H5T_STD_I32LE);
    hsize_t dims[2] = {static_cast<hsize_t>(G.rows()), static_cast<hsize_t>(G.cols())};
    Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose, "create a dataspace");
    const hid_t file_type =
        model.precision == Precision::kFloat32 ? H5T_IEEE_F32LE : H5T_IEEE_F64LE;
    Handle set(H5Dcreate2(compliance, "G", file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
               H5Dclose, "create dataset /compliance/G");
    // Column j of Eigen's storage is row j of the file: write in row blocks
    // so the transpose is exact for any G, symmetric or not.
    const hsize_t block = 256;
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows;
    for (hsize_t r0 = 0; r0 < dims[0]; r0 += block) {
      const hsize_t h = std::min(block, dims[0] - r0);
      rows = G.middleRows(static_cast<Eigen::Index>(r0), static_cast<Eigen::Index>(h));
      hsize_t start[2] = {r0, 0}, count[2] = {h, dims[1]};
      Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
      check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr),
            "select rows of G");
      Handle mem_space(H5Screate_simple(2, count, nullptr), H5Sclose, "create a dataspace");
      check(H5Dwrite(set, H5T_NATIVE_DOUBLE, mem_space, file_space, H5P_DEFAULT, rows.data()),
            "write /compliance/G");
    }
    write_string_attribute(set, "units", "m/N");

    // 1.1: per-vertex arrays for viewers (the XDMF sidecar, xdmf.hpp).
    Handle visualization(H5Gcreate2(file, "visualization", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                         H5Gclose, "create group /visualization");
    write_vector(visualization, "softness", model.softness_m_per_n, H5T_NATIVE_DOUBLE,
                 H5T_IEEE_F64LE);
    {
      Handle softness(H5Dopen2(visualization, "softness", H5P_DEFAULT), H5Dclose,
                      "open /visualization/softness");
      write_string_attribute(softness, "units", "m/N");
    }
    Eigen::Matrix<std::int8_t, Eigen::Dynamic, 1> fixed =
        Eigen::Matrix<std::int8_t, Eigen::Dynamic, 1>::Zero(model.vertices_m.rows());
    for (const int v : model.fixed_vertices) fixed[v] = 1;
    write_vector(visualization, "fixed", fixed, H5T_NATIVE_INT8, H5T_STD_I8LE);
    check(H5Fflush(file, H5F_SCOPE_GLOBAL), "flush the file");
  }
  out.commit();
}

ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G) {
  silence_hdf5();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(fmt::format("{}: no such file", path.string()));
  if (std::FILE* f = std::fopen(path.c_str(), "rb"))
    std::fclose(f);
  else
    throw InputError(fmt::format("{}: cannot be read: {}", path.string(), std::strerror(errno)));
  if (H5Fis_hdf5(path.c_str()) <= 0)
    throw InputError(fmt::format("{}: not an HDF5 file (truncated or of another kind); expected a "
                                 "palpate compliance file written by palpate-precompute",
                                 path.string()));
  const hid_t id = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (id < 0) throw InputError(fmt::format("{}: HDF5 cannot open it (corrupt?)", path.string()));
  Handle file(id, H5Fclose, "open");
  Reader r{path.string(), file};

  if (r.string_attribute("format") != kComplianceFormatName)
    r.fail("attribute format", fmt::format("is '{}', expected '{}'", r.string_attribute("format"),
                                           kComplianceFormatName));
  const int major = r.int_attribute("format_version_major");
  if (major != kComplianceFormatMajor)
    r.fail("attribute format_version_major",
           fmt::format("is {}; this palpate reads version {}.x", major, kComplianceFormatMajor));

  ComplianceModel m;
  // Any minor version reads: minor versions only add (docs/compliance-file.md).
  m.format_version_minor =
      H5Aexists(file, "format_version_minor") > 0 ? r.int_attribute("format_version_minor") : 0;
  m.producer = r.string_attribute("producer");
  m.method = r.string_attribute("method");
  m.material_summary = r.string_attribute("material_summary");
  m.created_utc = r.string_attribute("created_utc");
  m.input_hash = r.string_attribute("input_hash");
  m.job_toml = r.string_attribute("job_toml", false);
  m.report_json = r.string_attribute("report_json", false);

  m.vertices_m = r.matrix<double, 3>("/mesh/vertices", H5T_NATIVE_DOUBLE);
  m.tetrahedra = r.matrix<int, 4>("/mesh/tetrahedra", H5T_NATIVE_INT);
  m.surface_triangles = r.matrix<int, 3>("/mesh/surface_triangles", H5T_NATIVE_INT);
  m.tet_material = r.ints("/mesh/tetrahedron_material");
  m.fixed_vertices = r.ints("/mesh/fixed_vertex_ids");
  m.source_vertex_ids = r.ints("/mesh/source_vertex_ids");
  m.compliance_vertices = r.ints("/compliance/vertex_ids");
  const Eigen::VectorXd E = [&] {
    const auto d = r.dims("/material/young_modulus_pa", 1);
    Eigen::VectorXd v(static_cast<Eigen::Index>(d[0]));
    if (v.size()) r.read("/material/young_modulus_pa", H5T_NATIVE_DOUBLE, v.data());
    return v;
  }();
  const auto nu_dims = r.dims("/material/poisson_ratio", 1);
  Eigen::VectorXd nu(static_cast<Eigen::Index>(nu_dims[0]));
  if (nu.size()) r.read("/material/poisson_ratio", H5T_NATIVE_DOUBLE, nu.data());
  if (nu.size() != E.size()) r.fail("/material", "young_modulus_pa and poisson_ratio differ in length");
  std::vector<std::string> names(static_cast<size_t>(E.size()));
  if (r.dims("/material/name", 1)[0] != static_cast<hsize_t>(E.size()))
    r.fail("/material/name", "does not have one name per material");
  if (E.size() > 0) {
    Handle type = string_type();
    std::vector<char*> raw(static_cast<size_t>(E.size()), nullptr);
    r.read("/material/name", type, raw.data());
    for (size_t i = 0; i < raw.size(); ++i) names[i] = raw[i] ? raw[i] : "";
    Handle set(H5Dopen2(file, "/material/name", H5P_DEFAULT), H5Dclose, "open /material/name");
    Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
    H5Dvlen_reclaim(type, space, H5P_DEFAULT, raw.data());
  }
  for (Eigen::Index i = 0; i < E.size(); ++i)
    m.materials.push_back({names[static_cast<size_t>(i)], E[i], nu[i]});

  const Eigen::Index nv = m.vertices_m.rows();
  if (!m.vertices_m.allFinite()) r.fail("/mesh/vertices", "holds a non-finite coordinate");
  auto in_range = [&](const auto& ids, const char* name, Eigen::Index limit) {
    for (Eigen::Index i = 0; i < ids.size(); ++i)
      if (ids.data()[i] < 0 || ids.data()[i] >= limit)
        r.fail(name, fmt::format("entry {} is {}, outside 0..{}", i, ids.data()[i], limit - 1));
  };
  in_range(m.tetrahedra, "/mesh/tetrahedra", nv);
  in_range(m.surface_triangles, "/mesh/surface_triangles", nv);
  in_range(m.fixed_vertices, "/mesh/fixed_vertex_ids", nv);
  in_range(m.compliance_vertices, "/compliance/vertex_ids", nv);
  in_range(m.tet_material, "/mesh/tetrahedron_material", static_cast<Eigen::Index>(m.materials.size()));
  if (m.source_vertex_ids.size() != nv)
    r.fail("/mesh/source_vertex_ids", "does not have one entry per vertex");
  for (Eigen::Index i = 1; i < m.compliance_vertices.size(); ++i)
    if (m.compliance_vertices[i] <= m.compliance_vertices[i - 1])
      r.fail("/compliance/vertex_ids", fmt::format("entry {} is not above entry {}: ids must be distinct and increasing", i, i - 1));
  if (m.tet_material.size() != m.tetrahedra.rows())
    r.fail("/mesh/tetrahedron_material", "does not have one entry per tetrahedron");

  // Since 1.1; absent from 1.0 files, which read all the same.
  if (H5Lexists(file, "/visualization", H5P_DEFAULT) > 0 &&
      H5Lexists(file, "/visualization/softness", H5P_DEFAULT) > 0) {
    const auto d = r.dims("/visualization/softness", 1);
    if (d[0] != static_cast<hsize_t>(nv))
      r.fail("/visualization/softness",
             fmt::format("has {} entries, expected one per vertex ({})", d[0], nv));
    m.softness_m_per_n.resize(nv);
    if (nv > 0) r.read("/visualization/softness", H5T_NATIVE_DOUBLE, m.softness_m_per_n.data());
    if (!m.softness_m_per_n.allFinite())
      r.fail("/visualization/softness", "holds a non-finite value");
  }

  const auto gd = r.dims("/compliance/G", 2);
  const auto n3 = static_cast<hsize_t>(3 * m.compliance_vertices.size());
  if (gd[0] != n3 || gd[1] != n3)
    r.fail("/compliance/G", fmt::format("is {} × {}, expected {} × {} (3 × /compliance/vertex_ids)",
                                        gd[0], gd[1], n3, n3));
  {
    Handle set(H5Dopen2(file, "/compliance/G", H5P_DEFAULT), H5Dclose, "open /compliance/G");
    Handle type(H5Dget_type(set), H5Tclose, "get the type of G");
    m.precision = H5Tget_size(type) == 4 ? Precision::kFloat32 : Precision::kFloat64;
  }
  if (G) {
    // Row-major G read into column-major memory is Gᵀ; transpose back.
    Eigen::MatrixXd transposed(static_cast<Eigen::Index>(n3), static_cast<Eigen::Index>(n3));
    if (n3 > 0) r.read("/compliance/G", H5T_NATIVE_DOUBLE, transposed.data());
    if (!transposed.allFinite()) r.fail("/compliance/G", "holds a non-finite value");
    *G = transposed.transpose();
  }
  return m;
}

}  // namespace palpate
