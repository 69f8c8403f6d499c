#include "palpate/file/compliance_file.hpp"

#include <fmt/format.h>
#include <hdf5.h>

#include <cstdint>

#include "palpate/core/error.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/detail/compliance_file_internal.hpp"
#include "palpate/file/detail/dataset_io.hpp"
#include "palpate/file/detail/hdf5_support.hpp"
#include "palpate/file/hash.hpp"

namespace palpate {

using detail::hash_header;
using detail::write_matrix;
using detail::write_strings;
using detail::write_vector;
using hdf5::check;
using hdf5::Handle;
using hdf5::silence_hdf5;
using hdf5::write_int_attribute;
using hdf5::write_string_attribute;

namespace detail {

void write_root_attributes(hid_t file, const ComplianceModel& model, const char* format) {
  write_string_attribute(file, "format", format);
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
}

void write_model_datasets(hid_t file, const ComplianceModel& model, Sha256& digest) {
  hdf5::group(file, "mesh");
  write_matrix(file, "/mesh/vertices", model.vertices_m, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE, digest);
  write_matrix(file, "/mesh/tetrahedra", model.tetrahedra, H5T_NATIVE_INT, H5T_STD_I32LE, digest);
  write_vector(file, "/mesh/tetrahedron_material", model.tet_material, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
  write_matrix(file, "/mesh/surface_triangles", model.surface_triangles, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
  write_vector(file, "/mesh/fixed_vertex_ids", model.fixed_vertices, H5T_NATIVE_INT, H5T_STD_I32LE,
               digest);
  write_vector(file, "/mesh/source_vertex_ids", model.source_vertex_ids, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);

  hdf5::group(file, "material");
  std::vector<std::string> names;
  Eigen::VectorXd E(static_cast<Eigen::Index>(model.materials.size())), nu(E.size());
  for (size_t i = 0; i < model.materials.size(); ++i) {
    names.push_back(model.materials[i].name);
    E[static_cast<Eigen::Index>(i)] = model.materials[i].young_modulus_pa;
    nu[static_cast<Eigen::Index>(i)] = model.materials[i].poisson_ratio;
  }
  write_strings(file, "/material/name", names, digest);
  write_vector(file, "/material/young_modulus_pa", E, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE, digest);
  write_vector(file, "/material/poisson_ratio", nu, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE, digest);

  hdf5::group(file, "compliance");
  write_vector(file, "/compliance/vertex_ids", model.compliance_vertices, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
}

}  // namespace detail

void write_compliance_file(const std::filesystem::path& path, const ComplianceModel& model,
                           CRef<Eigen::MatrixXd> G,
                           const std::function<void(long done, long total)>& progress) {
  const Eigen::Index n = model.compliance_vertices.size();
  PALPATE_DEMAND(G.rows() == 3 * n && G.cols() == 3 * n);
  // Column j of Eigen's storage is row j of the file: copy row bands, so the
  // transpose is exact for any G, symmetric or not.
  write_compliance_file(
      path, model,
      [&](long first, long count, double* rows) {
        Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
            rows, count, G.cols()) = G.middleRows(first, count);
      },
      256, progress);
}

void write_compliance_file(const std::filesystem::path& path, const ComplianceModel& model,
                           const GRowSource& G_rows, long band_rows,
                           const std::function<void(long done, long total)>& progress) {
  const auto n3 = static_cast<hsize_t>(3 * model.compliance_vertices.size());
  PALPATE_DEMAND(model.softness_m_per_n.size() == model.vertices_m.rows() && band_rows > 0);
  silence_hdf5();
  AtomicOutput out(path);
  {
    Handle file(H5Fcreate(out.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT),
                H5Fclose, fmt::format("create {}", out.temp_path().string()));
    detail::write_root_attributes(file, model, kComplianceFormatName);

    // Every dataset goes into the digest, in this order (the reader's too).
    Sha256 digest;
    detail::write_model_datasets(file, model, digest);
    hsize_t dims[2] = {n3, n3};
    Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose, "create a dataspace");
    const bool single = model.precision == Precision::kFloat32;
    Handle set(H5Dcreate2(file, "/compliance/G", single ? H5T_IEEE_F32LE : H5T_IEEE_F64LE, space,
                          H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
               H5Dclose, "create dataset /compliance/G");
    hash_header(digest, "/compliance/G", {dims[0], dims[1]});
    // In row bands, as the file stores them. float32 is rounded here (round
    // to nearest, as HDF5 would), so that the digest covers the bytes stored.
    const auto block = static_cast<hsize_t>(band_rows);
    std::vector<double> rows;
    std::vector<float> rows32;
    for (hsize_t r0 = 0; r0 < dims[0]; r0 += block) {
      const hsize_t h = std::min(block, dims[0] - r0);
      const std::size_t values = static_cast<std::size_t>(h * dims[1]);
      rows.resize(values);
      G_rows(static_cast<long>(r0), static_cast<long>(h), rows.data());
      hsize_t start[2] = {r0, 0}, count[2] = {h, dims[1]};
      Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
      check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr),
            "select rows of G");
      Handle mem_space(H5Screate_simple(2, count, nullptr), H5Sclose, "create a dataspace");
      if (single) {
        rows32.assign(rows.begin(), rows.end());
        check(H5Dwrite(set, H5T_NATIVE_FLOAT, mem_space, file_space, H5P_DEFAULT, rows32.data()),
              "write /compliance/G");
        digest.update(rows32.data(), sizeof(float) * values);
      } else {
        check(H5Dwrite(set, H5T_NATIVE_DOUBLE, mem_space, file_space, H5P_DEFAULT, rows.data()),
              "write /compliance/G");
        digest.update(rows.data(), sizeof(double) * values);
      }
      if (progress) progress(static_cast<long>(r0 + h), static_cast<long>(dims[0]));
    }
    write_string_attribute(set, "units", "m/N");

    // 1.1: per-vertex arrays for viewers (the XDMF sidecar, xdmf.hpp).
    hdf5::group(file, "visualization");
    write_vector(file, "/visualization/softness", model.softness_m_per_n, H5T_NATIVE_DOUBLE,
                 H5T_IEEE_F64LE, digest);
    {
      Handle softness(H5Dopen2(file, "/visualization/softness", H5P_DEFAULT), H5Dclose,
                      "open /visualization/softness");
      write_string_attribute(softness, "units", "m/N");
    }
    Eigen::Matrix<std::int8_t, Eigen::Dynamic, 1> fixed =
        Eigen::Matrix<std::int8_t, Eigen::Dynamic, 1>::Zero(model.vertices_m.rows());
    for (const int v : model.fixed_vertices) fixed[v] = 1;
    write_vector(file, "/visualization/fixed", fixed, H5T_NATIVE_INT8, H5T_STD_I8LE, digest);
    // 1.3: only when there is a region, so that a file without one has the
    // datasets it had before; with a digest of its own, so that content_sha256
    // stays the digest of the datasets a 1.2 reader knows and verifies.
    if (model.cut_region) {
      Sha256 region_digest;
      detail::write_cut_region(file, *model.cut_region, region_digest);
      write_string_attribute(file, "cut_region_sha256", region_digest.hex_digest());
    }
    // 1.2: written last, over everything above but /cut_region.
    write_string_attribute(file, "content_sha256", digest.hex_digest());
    check(H5Fflush(file, H5F_SCOPE_GLOBAL), "flush the file");
  }
  out.commit();
}

}  // namespace palpate
