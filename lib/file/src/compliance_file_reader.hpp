#pragma once
// Private to palpate_file: one read of a compliance file, or of a shard's
// everything but G (docs/compliance-file.md), from opening it to the last
// check; detail::read_compliance_file (compliance_file_internal.hpp, in
// compliance_file_reader.cpp) reads again when the file changed meanwhile.

#include <hdf5.h>

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "palpate/file/compliance_file.hpp"
#include "palpate/file/detail/dataset_io.hpp"
#include "palpate/file/detail/hdf5_support.hpp"

namespace palpate::detail {

/// Where a read puts G: nowhere, in double, or as stored.
struct GTarget {
  Eigen::MatrixXd* G = nullptr;
  Eigen::MatrixXf* G32 = nullptr;  ///< with G: float32 files go here, G is left empty
};

/// Reads a compliance file once and checks it: the root attributes, then
/// the datasets in file order (the order of the content digest), then the
/// checks between them, then the digests. Each refusal is an InputError
/// naming the file, the attribute or dataset, and what is accepted.
///
/// Ownership: holds the open HDF5 file (closed with the reader) and the
/// model read so far; writes G into the caller's matrices of the GTarget,
/// which must outlive read(). Threads: each reader is used by one thread;
/// readers on several threads are safe, HDF5 (built thread-safe)
/// serializing their calls. Allocates: the model, G, and HDF5's buffers.
class ComplianceFileReader {
 public:
  /// Opens @p path, a file of @p format: kComplianceFormatName, or
  /// kPartialFormatName (everything but G: its rows are checked, not read);
  /// @p format is kept (one of those constants).
  /// @throws InputError if it is missing, unreadable, not HDF5, truncated
  ///         or corrupt.
  ComplianceFileReader(const std::filesystem::path& path, GTarget target, const char* format);
  ComplianceFileReader(const ComplianceFileReader&) = delete;
  ComplianceFileReader& operator=(const ComplianceFileReader&) = delete;

  /// Reads and checks everything (call once).
  /// @throws InputError at the first refusal; SystemError if HDF5 fails.
  ComplianceModel read();

 private:
  void read_root_attributes();
  void read_mesh();
  void read_materials();
  void read_compliance();
  void read_g(hid_t set, const std::vector<hsize_t>& gd, hsize_t n3);
  void read_visualization();
  void read_region();  // /cut_region
  void check_indices();
  void check_digests();

  GTarget target_;
  const char* format_;
  bool partial_;
  hdf5::Handle file_;
  Reader r_;  // r_.sink points into r_ itself: the reader is not copied nor moved
  ComplianceModel m_;
  // content_sha256 as stored (1.2 on), and as computed over what was read;
  // the /cut_region digest computed (1.3), its stored one is m_'s.
  std::string stored_digest_, computed_digest_, computed_region_digest_;
};

}  // namespace palpate::detail
