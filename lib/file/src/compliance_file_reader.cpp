// Reading a compliance file (docs/compliance-file.md): one read whole and
// checked (ComplianceFileReader), and the reads again when the file changed
// meanwhile (read_compliance_file). Writing it is compliance_file.cpp.

#include "compliance_file_reader.hpp"

#include <fmt/format.h>
#include <hdf5.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <optional>
#include <thread>
#include <utility>

#include "palpate/core/error.hpp"
#include "palpate/file/cut_region_data.hpp"
#include "palpate/file/detail/compliance_file_internal.hpp"
#include "palpate/file/hash.hpp"

namespace palpate {
namespace detail {

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

/// The file opened read-only, after the checks that name what it is not.
hid_t open_checked(const std::filesystem::path& path) {
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
  return id;
}

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

}  // namespace

ComplianceFileReader::ComplianceFileReader(const std::filesystem::path& path, GTarget target,
                                           const char* format)
    : target_(target),
      format_(format),
      partial_(std::strcmp(format, kPartialFormatName) == 0),
      file_(open_checked(path), H5Fclose, "open"),
      r_{path.string(), file_, {}} {}

ComplianceModel ComplianceFileReader::read() {
  read_root_attributes();
  // The datasets in file order: the order of the content digest.
  read_mesh();
  read_materials();
  read_compliance();
  read_visualization();
  read_region();
  check_indices();
  check_digests();
  return std::move(m_);
}

void ComplianceFileReader::read_root_attributes() {
  if (const std::string found = r_.string_attribute("format"); found != format_) {
    if (found == kPartialFormatName)
      r_.fail("attribute format",
              fmt::format("is '{}': a shard holding some columns of G, not a compliance file; "
                          "assemble the shards with palpate-precompute merge (docs/precompute.md, "
                          "\"Batch precomputation\")",
                          found));
    r_.fail("attribute format", fmt::format("is '{}', expected '{}'", found, format_));
  }
  const int major = r_.int_attribute("format_version_major");
  if (major != kComplianceFormatMajor)
    r_.fail("attribute format_version_major",
            fmt::format("is {}; this palpate reads version {}.x", major, kComplianceFormatMajor));

  // Any minor version reads: minor versions only add (docs/compliance-file.md).
  m_.format_version_minor =
      H5Aexists(file_, "format_version_minor") > 0 ? r_.int_attribute("format_version_minor") : 0;
  m_.producer = r_.string_attribute("producer");
  m_.method = r_.string_attribute("method");
  m_.material_summary = r_.string_attribute("material_summary");
  m_.created_utc = r_.string_attribute("created_utc");
  m_.input_hash = r_.string_attribute("input_hash");
  m_.job_toml = r_.string_attribute("job_toml", false);
  m_.report_json = r_.string_attribute("report_json", false);
  // Since 1.2; verified once everything else is read and checked.
  stored_digest_ = m_.format_version_minor >= 2 && !partial_ ? r_.string_attribute("content_sha256")
                                                             : std::string();
  r_.hashing = !stored_digest_.empty() && target_.G != nullptr;
  m_.content_sha256 = stored_digest_;
}

void ComplianceFileReader::read_mesh() {
  m_.vertices_m = r_.matrix<double, 3>("/mesh/vertices", H5T_NATIVE_DOUBLE);
  m_.tetrahedra = r_.matrix<int, 4>("/mesh/tetrahedra", H5T_NATIVE_INT);
  m_.tet_material = r_.ints("/mesh/tetrahedron_material");
  m_.surface_triangles = r_.matrix<int, 3>("/mesh/surface_triangles", H5T_NATIVE_INT);
  m_.fixed_vertices = r_.ints("/mesh/fixed_vertex_ids");
  m_.source_vertex_ids = r_.ints("/mesh/source_vertex_ids");
}

void ComplianceFileReader::read_materials() {
  const auto name_dims = r_.dims("/material/name", 1);
  std::vector<std::string> names(static_cast<size_t>(name_dims[0]));
  if (!names.empty()) {
    hdf5::Handle type = hdf5::string_type();
    std::vector<char*> raw(names.size(), nullptr);
    r_.read("/material/name", type, raw.data());
    for (size_t i = 0; i < raw.size(); ++i) names[i] = raw[i] ? raw[i] : "";
    hdf5::Handle set(H5Dopen2(file_, "/material/name", H5P_DEFAULT), H5Dclose,
                     "open /material/name");
    hdf5::Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
    H5Dvlen_reclaim(type, space, H5P_DEFAULT, raw.data());
  }
  r_.hash_dataset("/material/name", name_dims);
  for (const auto& name : names) r_.hash(name.c_str(), name.size() + 1);
  const Eigen::VectorXd E = r_.vector<double>("/material/young_modulus_pa", H5T_NATIVE_DOUBLE);
  const Eigen::VectorXd nu = r_.vector<double>("/material/poisson_ratio", H5T_NATIVE_DOUBLE);
  if (nu.size() != E.size())
    r_.fail("/material", "young_modulus_pa and poisson_ratio differ in length");
  if (names.size() != static_cast<size_t>(E.size()))
    r_.fail("/material/name", "does not have one name per material");
  for (Eigen::Index i = 0; i < E.size(); ++i)
    m_.materials.push_back({names[static_cast<size_t>(i)], E[i], nu[i]});
}

void ComplianceFileReader::read_compliance() {
  m_.compliance_vertices = r_.ints("/compliance/vertex_ids");
  const auto gd = r_.dims("/compliance/G", 2);
  const auto n3 = static_cast<hsize_t>(3 * m_.compliance_vertices.size());
  if (partial_) {
    // A shard's G is 3n × (its columns); partial_file.cpp checks it.
    if (gd[0] != n3)
      r_.fail("/compliance/G",
              fmt::format("has {} rows, expected {} (3 × /compliance/vertex_ids)", gd[0], n3));
  } else if (gd[0] != n3 || gd[1] != n3)
    r_.fail("/compliance/G",
            fmt::format("is {} × {}, expected {} × {} (3 × /compliance/vertex_ids)", gd[0], gd[1],
                        n3, n3));
  hdf5::Handle set(H5Dopen2(file_, "/compliance/G", H5P_DEFAULT), H5Dclose, "open /compliance/G");
  hdf5::Handle type(H5Dget_type(set), H5Tclose, "get the type of G");
  m_.precision = H5Tget_size(type) == 4 ? Precision::kFloat32 : Precision::kFloat64;
  if (target_.G && !partial_) read_g(set, gd, n3);
}

// In row blocks, as stored (float32 or float64), into the digest; then into
// G's column-major memory (row i of the file is row i of G).
void ComplianceFileReader::read_g(hid_t set, const std::vector<hsize_t>& gd, hsize_t n3) {
  Eigen::MatrixXd* G = target_.G;
  const bool single = m_.precision == Precision::kFloat32;
  // float32 kept as stored when asked (half the memory), else in double.
  const bool keep32 = single && target_.G32 != nullptr;
  if (keep32) {
    G->resize(0, 0);
    target_.G32->resize(static_cast<Eigen::Index>(n3), static_cast<Eigen::Index>(n3));
    advise_huge_pages(target_.G32->data(), sizeof(float) * target_.G32->size());
  } else {
    if (target_.G32) target_.G32->resize(0, 0);
    G->resize(static_cast<Eigen::Index>(n3), static_cast<Eigen::Index>(n3));
    advise_huge_pages(G->data(), sizeof(double) * G->size());
  }
  r_.hash_dataset("/compliance/G", gd);
  const hsize_t block = 256;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows;
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows32;
  for (hsize_t r0 = 0; r0 < n3; r0 += block) {
    const hsize_t h = std::min(block, n3 - r0);
    hsize_t start[2] = {r0, 0}, count[2] = {h, n3};
    hdf5::Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
    hdf5::check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr),
                "select rows of G");
    hdf5::Handle mem_space(H5Screate_simple(2, count, nullptr), H5Sclose, "create a dataspace");
    const auto rows_in_block = static_cast<Eigen::Index>(h),
               columns = static_cast<Eigen::Index>(n3);
    herr_t status = 0;
    if (single) {
      rows32.resize(rows_in_block, columns);
      status = H5Dread(set, H5T_NATIVE_FLOAT, mem_space, file_space, H5P_DEFAULT, rows32.data());
      r_.hash(rows32.data(), sizeof(float) * static_cast<std::size_t>(rows32.size()));
      if (keep32) {
        if (status < 0) r_.fail("/compliance/G", "cannot be read (corrupt or of a wrong type)");
        if (!rows32.allFinite()) r_.fail("/compliance/G", "holds a non-finite value");
        target_.G32->middleRows(static_cast<Eigen::Index>(r0), rows_in_block) = rows32;
        continue;
      }
      rows = rows32.cast<double>();
    } else {
      rows.resize(rows_in_block, columns);
      status = H5Dread(set, H5T_NATIVE_DOUBLE, mem_space, file_space, H5P_DEFAULT, rows.data());
      r_.hash(rows.data(), sizeof(double) * static_cast<std::size_t>(rows.size()));
    }
    if (status < 0) r_.fail("/compliance/G", "cannot be read (corrupt or of a wrong type)");
    if (!rows.allFinite()) r_.fail("/compliance/G", "holds a non-finite value");
    G->middleRows(static_cast<Eigen::Index>(r0), rows_in_block) = rows;
  }
}

// Since 1.1; absent from 1.0 files, which read all the same.
void ComplianceFileReader::read_visualization() {
  const Eigen::Index nv = m_.vertices_m.rows();
  if (H5Lexists(file_, "/visualization", H5P_DEFAULT) > 0 &&
      H5Lexists(file_, "/visualization/softness", H5P_DEFAULT) > 0) {
    const auto d = r_.dims("/visualization/softness", 1);
    if (d[0] != static_cast<hsize_t>(nv))
      r_.fail("/visualization/softness",
              fmt::format("has {} entries, expected one per vertex ({})", d[0], nv));
    m_.softness_m_per_n = r_.vector<double>("/visualization/softness", H5T_NATIVE_DOUBLE);
    if (!m_.softness_m_per_n.allFinite())
      r_.fail("/visualization/softness", "holds a non-finite value");
  }
  if (!stored_digest_.empty() && target_.G != nullptr &&
      H5Lexists(file_, "/visualization", H5P_DEFAULT) > 0 &&
      H5Lexists(file_, "/visualization/fixed", H5P_DEFAULT) > 0)
    r_.vector<std::int8_t>("/visualization/fixed", H5T_NATIVE_INT8);
  // Every dataset content_sha256 covers is read: its digest ends here.
  computed_digest_ = r_.hashing ? r_.digest.hex_digest() : std::string();
}

// Since 1.3, after /visualization, into its own digest; a 1.2 reader skips
// the group, and older files have none.
void ComplianceFileReader::read_region() {
  if (partial_ || H5Lexists(file_, "/cut_region", H5P_DEFAULT) <= 0) return;
  m_.cut_region_sha256 = r_.string_attribute("cut_region_sha256", false);
  Sha256 region_digest;
  r_.sink = &region_digest;
  r_.hashing = target_.G != nullptr;
  m_.cut_region = read_cut_region(r_);
  r_.sink = &r_.digest;
  r_.hashing = false;
  if (target_.G != nullptr) {
    if (m_.cut_region_sha256.empty())
      r_.fail("attribute cut_region_sha256",
              "missing; a compliance file with /cut_region has it (docs/compliance-file.md)");
    computed_region_digest_ = region_digest.hex_digest();
  }
}

void ComplianceFileReader::check_indices() {
  const Eigen::Index nv = m_.vertices_m.rows();
  if (!m_.vertices_m.allFinite()) r_.fail("/mesh/vertices", "holds a non-finite coordinate");
  auto in_range = [&](const auto& ids, const char* name, Eigen::Index limit) {
    for (Eigen::Index i = 0; i < ids.size(); ++i)
      if (ids.data()[i] < 0 || ids.data()[i] >= limit)
        r_.fail(name, fmt::format("entry {} is {}, outside 0..{}", i, ids.data()[i], limit - 1));
  };
  in_range(m_.tetrahedra, "/mesh/tetrahedra", nv);
  in_range(m_.surface_triangles, "/mesh/surface_triangles", nv);
  in_range(m_.fixed_vertices, "/mesh/fixed_vertex_ids", nv);
  in_range(m_.compliance_vertices, "/compliance/vertex_ids", nv);
  in_range(m_.tet_material, "/mesh/tetrahedron_material",
           static_cast<Eigen::Index>(m_.materials.size()));
  if (m_.source_vertex_ids.size() != nv)
    r_.fail("/mesh/source_vertex_ids", "does not have one entry per vertex");
  for (Eigen::Index i = 1; i < m_.compliance_vertices.size(); ++i)
    if (m_.compliance_vertices[i] <= m_.compliance_vertices[i - 1])
      r_.fail("/compliance/vertex_ids",
              fmt::format("entry {} is not above entry {}: ids must be distinct and increasing", i,
                          i - 1));
  if (m_.tet_material.size() != m_.tetrahedra.rows())
    r_.fail("/mesh/tetrahedron_material", "does not have one entry per tetrahedron");
  if (m_.cut_region)
    check_cut_region(*m_.cut_region, m_.compliance_vertices.size(),
                     static_cast<Eigen::Index>(m_.materials.size()), r_.file);
}

// Last: every check above gives its own message; what passes them all and
// still differs from what was written is a corrupt file, or one read while
// it was being overwritten in place.
void ComplianceFileReader::check_digests() {
  if (!stored_digest_.empty() && target_.G != nullptr) {
    const std::string& computed = computed_digest_;
    if (computed != stored_digest_)
      r_.fail("attribute content_sha256",
              fmt::format("the datasets do not match the digest they were written with ({} read, "
                          "{} stored): the file is corrupt (damaged on disk or in a copy, or "
                          "modified since); copy it again or regenerate it with palpate-precompute",
                          computed.substr(0, 19), stored_digest_.substr(0, 19)));
  }
  if (!computed_region_digest_.empty() && computed_region_digest_ != m_.cut_region_sha256)
    r_.fail(
        "attribute cut_region_sha256",
        fmt::format("the /cut_region datasets do not match the digest they were written with "
                    "({} read, {} stored): the file is corrupt (damaged on disk or in a copy, "
                    "or modified since); copy it again or regenerate it with palpate-precompute",
                    computed_region_digest_.substr(0, 19), m_.cut_region_sha256.substr(0, 19)));
}

ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G,
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
      ComplianceModel m = ComplianceFileReader(path, GTarget{G, G32}, format).read();
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

}  // namespace detail

ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G) {
  return detail::read_compliance_file(path, G, nullptr, kComplianceFormatName);
}

ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G,
                                     Eigen::MatrixXf* G32) {
  PALPATE_DEMAND(G != nullptr && G32 != nullptr);
  return detail::read_compliance_file(path, G, G32, kComplianceFormatName);
}

}  // namespace palpate
