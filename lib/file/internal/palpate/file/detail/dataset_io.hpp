#pragma once
// Private to the library: the compliance file's dataset writers and reader,
// each of which feeds the content digest (docs/compliance-file.md,
// "content_sha256"), shared by the file's parts (compliance_file.cpp,
// cut_region_data.cpp).

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/core/error.hpp"
#include "palpate/file/detail/hdf5_support.hpp"
#include "palpate/file/hash.hpp"

namespace palpate::detail {

using hdf5::check;
using hdf5::Handle;
using hdf5::silence_hdf5;
using hdf5::string_type;
using hdf5::write_int_attribute;
using hdf5::write_string_attribute;

// The content digest (docs/compliance-file.md, "content_sha256"): for each
// dataset in file order, a line "<path> <d0>x<d1>...\n", then the bytes it
// stores (little-endian, row-major; a string and its NUL).
inline void hash_header(Sha256& digest, const char* path, const std::vector<hsize_t>& dims) {
  std::string line = path;
  char separator = ' ';
  for (const hsize_t d : dims) {
    line += fmt::format("{}{}", separator, d);
    separator = 'x';
  }
  digest.update(line + "\n");
}

// Row-major [rows, cols] dataset @p path from a column-major Eigen matrix:
// the file holds the transpose of Eigen's memory layout, so write Mᵀ's storage.
template <typename Matrix>
void write_matrix(hid_t file, const char* path, const Matrix& M, hid_t mem_type, hid_t file_type,
                  Sha256& digest) {
  using Scalar = typename Matrix::Scalar;
  const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = M;
  hsize_t dims[2] = {static_cast<hsize_t>(M.rows()), static_cast<hsize_t>(M.cols())};
  Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose, "create a dataspace");
  Handle set(H5Dcreate2(file, path, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
             H5Dclose, fmt::format("create dataset {}", path));
  if (rows.size() > 0)
    check(H5Dwrite(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows.data()),
          fmt::format("write dataset {}", path));
  hash_header(digest, path, {dims[0], dims[1]});
  digest.update(rows.data(), sizeof(Scalar) * static_cast<std::size_t>(rows.size()));
}

template <typename Vector>
void write_vector(hid_t file, const char* path, const Vector& v, hid_t mem_type, hid_t file_type,
                  Sha256& digest) {
  hsize_t dims[1] = {static_cast<hsize_t>(v.size())};
  Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose, "create a dataspace");
  Handle set(H5Dcreate2(file, path, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
             H5Dclose, fmt::format("create dataset {}", path));
  if (v.size() > 0)
    check(H5Dwrite(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()),
          fmt::format("write dataset {}", path));
  hash_header(digest, path, {dims[0]});
  digest.update(v.data(), sizeof(*v.data()) * static_cast<std::size_t>(v.size()));
}

inline void write_strings(hid_t file, const char* path, const std::vector<std::string>& values,
                          Sha256& digest) {
  Handle type = string_type();
  hsize_t dims[1] = {values.size()};
  Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose, "create a dataspace");
  Handle set(H5Dcreate2(file, path, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Dclose,
             fmt::format("create dataset {}", path));
  std::vector<const char*> data;
  for (const auto& s : values) data.push_back(s.c_str());
  if (!data.empty()) check(H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), path);
  hash_header(digest, path, {dims[0]});
  for (const auto& s : values) digest.update(s.c_str(), s.size() + 1);
}

// ---- reading ---------------------------------------------------------------

struct Reader {
  std::string file;
  hid_t root;
  Sha256 digest;         // of the datasets read, in file order (hash_header)
  bool hashing = false;  // only for files that carry a digest (1.2 on)
  // Where the datasets read go: `digest`, or another digest of a part of the
  // file that has its own (the 1.3 /cut_region, cut_region_sha256).
  Sha256* sink = &digest;

  void hash(const void* data, std::size_t bytes) {
    if (hashing) sink->update(data, bytes);
  }
  void hash_dataset(const char* path, const std::vector<hsize_t>& dims) {
    if (hashing) hash_header(*sink, path, dims);
  }

  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw InputError(fmt::format("{}: {}: {}", file, where, what));
  }

  // A group or a dangling link where a dataset belongs is a malformed file
  // (an InputError), not a failure of HDF5.
  Handle open(const char* name) const {
    const hid_t id = H5Dopen2(root, name, H5P_DEFAULT);
    if (id < 0) fail(name, "is not a dataset (a group, or a link to nothing)");
    return Handle(id, H5Dclose, fmt::format("open {}", name));
  }

  std::vector<hsize_t> dims(const char* name, int rank) const {
    if (H5Lexists(root, name, H5P_DEFAULT) <= 0)
      fail(name, "missing; a palpate compliance file has it (docs/compliance-file.md)");
    Handle set = open(name);
    Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
    const int r = H5Sget_simple_extent_ndims(space);
    if (r != rank) fail(name, fmt::format("has rank {}, expected {}", r, rank));
    std::vector<hsize_t> d(static_cast<size_t>(rank));
    H5Sget_simple_extent_dims(space, d.data(), nullptr);
    // palpate stores every value (contiguous, at least a byte each): a
    // dataset declaring more values than it stores bytes is damaged or forged,
    // and reading it would allocate memory for data that is not there.
    hsize_t values = 1;
    for (const hsize_t n : d)
      if (__builtin_mul_overflow(values, n, &values)) values = ~hsize_t{0};
    if (const hsize_t stored = H5Dget_storage_size(set); stored < values)
      fail(name, fmt::format("declares {} values but stores {} bytes: damaged, or not written "
                             "by palpate-precompute",
                             fmt::join(d, " × "), stored));
    return d;
  }

  void read(const char* name, hid_t mem_type, void* out) const {
    Handle set = open(name);
    if (H5Dread(set, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out) < 0)
      fail(name, "cannot be read (corrupt or of a wrong type)");
  }

  /// Reads @p name into @p out (native memory, the bytes palpate stores) and hashes it.
  void read_hashed(const char* name, const std::vector<hsize_t>& d, hid_t mem_type, void* out,
                   std::size_t bytes) {
    if (bytes > 0) read(name, mem_type, out);
    hash_dataset(name, d);
    hash(out, bytes);
  }

  template <typename Scalar, int Cols>
  Eigen::Matrix<Scalar, Eigen::Dynamic, Cols> matrix(const char* name, hid_t mem_type) {
    const auto d = dims(name, 2);
    if (Cols != Eigen::Dynamic && d[1] != static_cast<hsize_t>(Cols))
      fail(name, fmt::format("has {} columns, expected {}", d[1], Cols));
    Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows(d[0], d[1]);
    read_hashed(name, d, mem_type, rows.data(),
                sizeof(Scalar) * static_cast<std::size_t>(rows.size()));
    return rows;
  }

  template <typename Scalar>
  Eigen::Matrix<Scalar, Eigen::Dynamic, 1> vector(const char* name, hid_t mem_type) {
    const auto d = dims(name, 1);
    Eigen::Matrix<Scalar, Eigen::Dynamic, 1> v(static_cast<Eigen::Index>(d[0]));
    read_hashed(name, d, mem_type, v.data(), sizeof(Scalar) * static_cast<std::size_t>(v.size()));
    return v;
  }

  Eigen::VectorXi ints(const char* name) { return vector<int>(name, H5T_NATIVE_INT); }

  // Root attribute @p name, refused unless it holds one value: H5Aread
  // writes as many values as it holds.
  Handle single_value_attribute(const char* name) const {
    Handle attr(H5Aopen(root, name, H5P_DEFAULT), H5Aclose, fmt::format("open attribute {}", name));
    Handle space(H5Aget_space(attr), H5Sclose, "get a dataspace");
    if (const hssize_t n = H5Sget_simple_extent_npoints(space); n != 1)
      fail(fmt::format("attribute {}", name), fmt::format("holds {} values, expected one", n));
    return attr;
  }

  std::string string_attribute(const char* name, bool required = true) const {
    if (H5Aexists(root, name) <= 0) {
      if (required) fail(fmt::format("attribute {}", name), "missing");
      return {};
    }
    Handle attr = single_value_attribute(name);
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
    Handle attr = single_value_attribute(name);
    int value = 0;
    if (H5Aread(attr, H5T_NATIVE_INT, &value) < 0)
      fail(fmt::format("attribute {}", name), "not an integer");
    return value;
  }
};

}  // namespace palpate::detail
