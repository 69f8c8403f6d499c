#include "palpate/file/compliance_file.hpp"

#include <fmt/format.h>
#include <hdf5.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <optional>
#include <thread>

#include "palpate/core/error.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/detail/compliance_file_internal.hpp"
#include "palpate/file/detail/dataset_io.hpp"
#include "palpate/file/detail/hdf5_support.hpp"
#include "palpate/file/hash.hpp"

namespace palpate {

namespace {

/// Asks the kernel for transparent huge pages (2 MiB) under G before it is
/// first written: the run time reads G in 3 × 3 blocks scattered over
/// hundreds of MB, and with 4 KiB pages nearly every block is a TLB miss
/// (BENCHMARKS.md, "Contact with the surface"). Only the whole 2 MiB pages
/// inside the buffer; a kernel that declines changes nothing.
void advise_huge_pages(void* data, std::size_t bytes) {
  constexpr std::uintptr_t kHuge = std::uintptr_t{2} << 20;
  const auto begin = (reinterpret_cast<std::uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}

}  // namespace

using detail::hash_header;
using detail::Reader;
using detail::write_matrix;
using detail::write_strings;
using detail::write_vector;
using hdf5::check;
using hdf5::Handle;
using hdf5::silence_hdf5;
using hdf5::string_type;
using hdf5::write_int_attribute;
using hdf5::write_string_attribute;

namespace {

/// What identifies a file's content on disk without reading it: a change of
/// any of these during a read means the file was written or replaced meanwhile.
struct FileIdentity {
  dev_t device = 0;
  ino_t inode = 0;
  off_t size = 0;
  std::int64_t modified_ns = 0, changed_ns = 0;
  bool operator==(const FileIdentity&) const = default;
};

std::optional<FileIdentity> identify(const std::filesystem::path& path) {
  struct stat s {};
  if (::stat(path.c_str(), &s) != 0) return std::nullopt;
  return FileIdentity{s.st_dev, s.st_ino, s.st_size,
                      s.st_mtim.tv_sec * 1'000'000'000LL + s.st_mtim.tv_nsec,
                      s.st_ctim.tv_sec * 1'000'000'000LL + s.st_ctim.tv_nsec};
}

/// HDF5's innermost error message (after a failed call), e.g. its "truncated file: eof = …".
std::string hdf5_error_message() {
  std::string message;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned, const H5E_error2_t* e, void* out) -> herr_t {
        auto& m = *static_cast<std::string*>(out);
        if (m.empty() && e->desc != nullptr) m = e->desc;
        return 0;
      },
      &message);
  return message;
}

}  // namespace

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

namespace {

// Where read_once puts G: nowhere, in double, or as stored.
struct GTarget {
  Eigen::MatrixXd* G = nullptr;
  Eigen::MatrixXf* G32 = nullptr;  // with G: float32 files go here, G is left empty
};

ComplianceModel read_once(const std::filesystem::path& path, GTarget target,
                          const char* format = kComplianceFormatName) {
  Eigen::MatrixXd* G = target.G;
  const bool partial = std::strcmp(format, kPartialFormatName) == 0;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec))
    throw InputError(fmt::format("{}: no such file", path.string()));
  if (std::FILE* f = std::fopen(path.c_str(), "rb"))
    std::fclose(f);
  else
    throw InputError(fmt::format("{}: cannot be read: {}", path.string(), std::strerror(errno)));
  if (H5Fis_hdf5(path.c_str()) <= 0)
    throw InputError(
        fmt::format("{}: not an HDF5 file (truncated or of another kind); expected a "
                    "palpate compliance file written by palpate-precompute",
                    path.string()));
  const hid_t id = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (id < 0) {
    // HDF5 says "truncated file: eof = <size>, sblock->base_addr = 0, stored_eof = <expected>".
    const std::string why = hdf5_error_message();
    unsigned long long size = 0, base = 0, expected = 0;
    if (std::sscanf(why.c_str(),
                    "truncated file: eof = %llu, sblock->base_addr = %llu, stored_eof = %llu",
                    &size, &base, &expected) == 3)
      throw InputError(fmt::format(
          "{}: truncated: {} bytes of the {} it was written with (an interrupted copy or a full "
          "disk?); copy it again or regenerate it with palpate-precompute",
          path.string(), size, expected));
    throw InputError(fmt::format("{}: HDF5 cannot open it (corrupt?){}", path.string(),
                                 why.empty() ? "" : ": " + why));
  }
  Handle file(id, H5Fclose, "open");
  Reader r{path.string(), file, {}};

  if (const std::string found = r.string_attribute("format"); found != format) {
    if (found == kPartialFormatName)
      r.fail("attribute format",
             fmt::format("is '{}': a shard holding some columns of G, not a compliance file; "
                         "assemble the shards with palpate-precompute merge (docs/precompute.md, "
                         "\"Batch precomputation\")",
                         found));
    r.fail("attribute format", fmt::format("is '{}', expected '{}'", found, format));
  }
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
  // Since 1.2; verified once everything else is read and checked.
  const std::string stored_digest = m.format_version_minor >= 2 && !partial
                                        ? r.string_attribute("content_sha256")
                                        : std::string();
  r.hashing = !stored_digest.empty() && G != nullptr;
  m.content_sha256 = stored_digest;

  // The datasets in file order: the order of the content digest.
  m.vertices_m = r.matrix<double, 3>("/mesh/vertices", H5T_NATIVE_DOUBLE);
  m.tetrahedra = r.matrix<int, 4>("/mesh/tetrahedra", H5T_NATIVE_INT);
  m.tet_material = r.ints("/mesh/tetrahedron_material");
  m.surface_triangles = r.matrix<int, 3>("/mesh/surface_triangles", H5T_NATIVE_INT);
  m.fixed_vertices = r.ints("/mesh/fixed_vertex_ids");
  m.source_vertex_ids = r.ints("/mesh/source_vertex_ids");
  const auto name_dims = r.dims("/material/name", 1);
  std::vector<std::string> names(static_cast<size_t>(name_dims[0]));
  if (!names.empty()) {
    Handle type = string_type();
    std::vector<char*> raw(names.size(), nullptr);
    r.read("/material/name", type, raw.data());
    for (size_t i = 0; i < raw.size(); ++i) names[i] = raw[i] ? raw[i] : "";
    Handle set(H5Dopen2(file, "/material/name", H5P_DEFAULT), H5Dclose, "open /material/name");
    Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
    H5Dvlen_reclaim(type, space, H5P_DEFAULT, raw.data());
  }
  r.hash_dataset("/material/name", name_dims);
  for (const auto& name : names) r.hash(name.c_str(), name.size() + 1);
  const Eigen::VectorXd E = r.vector<double>("/material/young_modulus_pa", H5T_NATIVE_DOUBLE);
  const Eigen::VectorXd nu = r.vector<double>("/material/poisson_ratio", H5T_NATIVE_DOUBLE);
  if (nu.size() != E.size())
    r.fail("/material", "young_modulus_pa and poisson_ratio differ in length");
  if (names.size() != static_cast<size_t>(E.size()))
    r.fail("/material/name", "does not have one name per material");
  for (Eigen::Index i = 0; i < E.size(); ++i)
    m.materials.push_back({names[static_cast<size_t>(i)], E[i], nu[i]});
  m.compliance_vertices = r.ints("/compliance/vertex_ids");

  const auto gd = r.dims("/compliance/G", 2);
  const auto n3 = static_cast<hsize_t>(3 * m.compliance_vertices.size());
  if (partial) {
    // A shard's G is 3n × (its columns); partial_file.cpp checks it.
    if (gd[0] != n3)
      r.fail("/compliance/G",
             fmt::format("has {} rows, expected {} (3 × /compliance/vertex_ids)", gd[0], n3));
  } else if (gd[0] != n3 || gd[1] != n3)
    r.fail("/compliance/G", fmt::format("is {} × {}, expected {} × {} (3 × /compliance/vertex_ids)",
                                        gd[0], gd[1], n3, n3));
  {
    Handle set(H5Dopen2(file, "/compliance/G", H5P_DEFAULT), H5Dclose, "open /compliance/G");
    Handle type(H5Dget_type(set), H5Tclose, "get the type of G");
    m.precision = H5Tget_size(type) == 4 ? Precision::kFloat32 : Precision::kFloat64;
    if (G && !partial) {
      // In row blocks, as stored (float32 or float64), into the digest; then
      // into G's column-major memory (row i of the file is row i of G).
      const bool single = m.precision == Precision::kFloat32;
      // float32 kept as stored when asked (half the memory), else in double.
      const bool keep32 = single && target.G32 != nullptr;
      if (keep32) {
        G->resize(0, 0);
        target.G32->resize(static_cast<Eigen::Index>(n3), static_cast<Eigen::Index>(n3));
        advise_huge_pages(target.G32->data(), sizeof(float) * target.G32->size());
      } else {
        if (target.G32) target.G32->resize(0, 0);
        G->resize(static_cast<Eigen::Index>(n3), static_cast<Eigen::Index>(n3));
        advise_huge_pages(G->data(), sizeof(double) * G->size());
      }
      r.hash_dataset("/compliance/G", gd);
      const hsize_t block = 256;
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows;
      Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows32;
      for (hsize_t r0 = 0; r0 < n3; r0 += block) {
        const hsize_t h = std::min(block, n3 - r0);
        hsize_t start[2] = {r0, 0}, count[2] = {h, n3};
        Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
        check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr),
              "select rows of G");
        Handle mem_space(H5Screate_simple(2, count, nullptr), H5Sclose, "create a dataspace");
        const auto rows_in_block = static_cast<Eigen::Index>(h),
                   columns = static_cast<Eigen::Index>(n3);
        herr_t status = 0;
        if (single) {
          rows32.resize(rows_in_block, columns);
          status =
              H5Dread(set, H5T_NATIVE_FLOAT, mem_space, file_space, H5P_DEFAULT, rows32.data());
          r.hash(rows32.data(), sizeof(float) * static_cast<std::size_t>(rows32.size()));
          if (keep32) {
            if (status < 0) r.fail("/compliance/G", "cannot be read (corrupt or of a wrong type)");
            if (!rows32.allFinite()) r.fail("/compliance/G", "holds a non-finite value");
            target.G32->middleRows(static_cast<Eigen::Index>(r0), rows_in_block) = rows32;
            continue;
          }
          rows = rows32.cast<double>();
        } else {
          rows.resize(rows_in_block, columns);
          status = H5Dread(set, H5T_NATIVE_DOUBLE, mem_space, file_space, H5P_DEFAULT, rows.data());
          r.hash(rows.data(), sizeof(double) * static_cast<std::size_t>(rows.size()));
        }
        if (status < 0) r.fail("/compliance/G", "cannot be read (corrupt or of a wrong type)");
        if (!rows.allFinite()) r.fail("/compliance/G", "holds a non-finite value");
        G->middleRows(static_cast<Eigen::Index>(r0), rows_in_block) = rows;
      }
    }
  }

  // Since 1.1; absent from 1.0 files, which read all the same.
  const Eigen::Index nv = m.vertices_m.rows();
  if (H5Lexists(file, "/visualization", H5P_DEFAULT) > 0 &&
      H5Lexists(file, "/visualization/softness", H5P_DEFAULT) > 0) {
    const auto d = r.dims("/visualization/softness", 1);
    if (d[0] != static_cast<hsize_t>(nv))
      r.fail("/visualization/softness",
             fmt::format("has {} entries, expected one per vertex ({})", d[0], nv));
    m.softness_m_per_n = r.vector<double>("/visualization/softness", H5T_NATIVE_DOUBLE);
    if (!m.softness_m_per_n.allFinite())
      r.fail("/visualization/softness", "holds a non-finite value");
  }
  if (!stored_digest.empty() && G != nullptr &&
      H5Lexists(file, "/visualization", H5P_DEFAULT) > 0 &&
      H5Lexists(file, "/visualization/fixed", H5P_DEFAULT) > 0)
    r.vector<std::int8_t>("/visualization/fixed", H5T_NATIVE_INT8);
  // Every dataset content_sha256 covers is read: its digest ends here.
  const std::string computed_digest = r.hashing ? r.digest.hex_digest() : std::string();

  // Since 1.3, after /visualization, into its own digest; a 1.2 reader
  // skips the group, and older files have none.
  std::string computed_region_digest;
  if (!partial && H5Lexists(file, "/cut_region", H5P_DEFAULT) > 0) {
    m.cut_region_sha256 = r.string_attribute("cut_region_sha256", false);
    Sha256 region_digest;
    r.sink = &region_digest;
    r.hashing = G != nullptr;
    m.cut_region = detail::read_cut_region(r);
    r.sink = &r.digest;
    r.hashing = false;
    if (G != nullptr) {
      if (m.cut_region_sha256.empty())
        r.fail("attribute cut_region_sha256",
               "missing; a compliance file with /cut_region has it (docs/compliance-file.md)");
      computed_region_digest = region_digest.hex_digest();
    }
  }

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
  in_range(m.tet_material, "/mesh/tetrahedron_material",
           static_cast<Eigen::Index>(m.materials.size()));
  if (m.source_vertex_ids.size() != nv)
    r.fail("/mesh/source_vertex_ids", "does not have one entry per vertex");
  for (Eigen::Index i = 1; i < m.compliance_vertices.size(); ++i)
    if (m.compliance_vertices[i] <= m.compliance_vertices[i - 1])
      r.fail("/compliance/vertex_ids",
             fmt::format("entry {} is not above entry {}: ids must be distinct and increasing", i,
                         i - 1));
  if (m.tet_material.size() != m.tetrahedra.rows())
    r.fail("/mesh/tetrahedron_material", "does not have one entry per tetrahedron");
  if (m.cut_region)
    check_cut_region(*m.cut_region, m.compliance_vertices.size(),
                     static_cast<Eigen::Index>(m.materials.size()), r.file);

  // Last: every check above gives its own message; what passes them all and
  // still differs from what was written is a corrupt file, or one read while
  // it was being overwritten in place.
  if (!stored_digest.empty() && G != nullptr) {
    const std::string& computed = computed_digest;
    if (computed != stored_digest)
      r.fail("attribute content_sha256",
             fmt::format("the datasets do not match the digest they were written with ({} read, "
                         "{} stored): the file is corrupt (damaged on disk or in a copy, or "
                         "modified since); copy it again or regenerate it with palpate-precompute",
                         computed.substr(0, 19), stored_digest.substr(0, 19)));
  }
  if (!computed_region_digest.empty() && computed_region_digest != m.cut_region_sha256)
    r.fail("attribute cut_region_sha256",
           fmt::format("the /cut_region datasets do not match the digest they were written with "
                       "({} read, {} stored): the file is corrupt (damaged on disk or in a copy, "
                       "or modified since); copy it again or regenerate it with palpate-precompute",
                       computed_region_digest.substr(0, 19), m.cut_region_sha256.substr(0, 19)));
  return m;
}

}  // namespace

ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G) {
  return detail::read_compliance_file(path, G, nullptr, kComplianceFormatName);
}

ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G,
                                     Eigen::MatrixXf* G32) {
  PALPATE_DEMAND(G != nullptr && G32 != nullptr);
  return detail::read_compliance_file(path, G, G32, kComplianceFormatName);
}

ComplianceModel detail::read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G,
                                             Eigen::MatrixXf* G32, const char* format) {
  silence_hdf5();
  // A file replaced (renamed over) or written while it is read would give a
  // model made of two files: read again, until one read sees the same file
  // from start to end (docs/faults.md, "Replacing a model").
  constexpr int kAttempts = 5;
  constexpr auto kPause = std::chrono::milliseconds(200);
  for (int attempt = 1;; ++attempt) {
    const auto before = identify(path);
    try {
      ComplianceModel m = read_once(path, GTarget{G, G32}, format);
      if (identify(path) == before) return m;
    } catch (const InputError&) {
      if (identify(path) == before) throw;
    } catch (const SystemError&) {
      if (identify(path) == before) throw;
    }
    if (attempt == kAttempts)
      throw InputError(fmt::format(
          "{}: changed while being read, {} times in a row: something is writing it; replace a "
          "compliance file by renaming a complete one over it (palpate-precompute does), not by "
          "writing into it",
          path.string(), kAttempts));
    std::this_thread::sleep_for(kPause);
  }
}

}  // namespace palpate
