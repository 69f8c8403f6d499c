#pragma once
// Private to palpate_runtime: the extendable datasets of a session file
// (session_recorder.cpp, docs/session-recording.md): a column of n × width
// values, chunked, whose rows are staged in memory and appended in one
// write.

#include <fmt/format.h>
#include <hdf5.h>

#include <cstdint>
#include <vector>

#include "palpate/file/detail/hdf5_support.hpp"

namespace palpate::detail {

// The HDF5 types (memory, file: little-endian) of the C++ types recorded.
template <typename T>
struct H5Type;
template <>
struct H5Type<double> {
  static hid_t mem() { return H5T_NATIVE_DOUBLE; }
  static hid_t file() { return H5T_IEEE_F64LE; }
};
template <>
struct H5Type<std::uint64_t> {
  static hid_t mem() { return H5T_NATIVE_UINT64; }
  static hid_t file() { return H5T_STD_U64LE; }
};
template <>
struct H5Type<std::int64_t> {
  static hid_t mem() { return H5T_NATIVE_INT64; }
  static hid_t file() { return H5T_STD_I64LE; }
};
template <>
struct H5Type<std::uint32_t> {
  static hid_t mem() { return H5T_NATIVE_UINT32; }
  static hid_t file() { return H5T_STD_U32LE; }
};
template <>
struct H5Type<std::int32_t> {
  static hid_t mem() { return H5T_NATIVE_INT32; }
  static hid_t file() { return H5T_STD_I32LE; }
};
template <>
struct H5Type<std::int8_t> {
  static hid_t mem() { return H5T_NATIVE_INT8; }
  static hid_t file() { return H5T_STD_I8LE; }
};
template <>
struct H5Type<std::uint8_t> {
  static hid_t mem() { return H5T_NATIVE_UINT8; }
  static hid_t file() { return H5T_STD_U8LE; }
};

// An extendable, chunked dataset of n × width values of T (1-D when width
// is 1), with the rows staged since its last write() held in memory.
template <typename T>
class Column {
 public:
  Column(hid_t parent, const char* name, hsize_t width, hsize_t chunk_rows,
         const char* units = nullptr)
      : width_(width), set_(create(parent, name, width, chunk_rows)), name_(name) {
    if (units) hdf5::write_string_attribute(set_, "units", units);
  }

  void stage(T value) { staged_.push_back(value); }
  void stage(const T* row) { staged_.insert(staged_.end(), row, row + width_); }

  // Appends the staged rows to the dataset.
  void write() {
    const hsize_t rows = staged_.size() / width_;
    if (rows == 0) return;
    const hsize_t dims[2] = {rows_ + rows, width_};
    hdf5::check(H5Dset_extent(set_, dims), fmt::format("extend dataset {}", name_));
    hdf5::Handle file_space(H5Dget_space(set_), H5Sclose, "get a dataspace");
    const hsize_t start[2] = {rows_, 0}, count[2] = {rows, width_};
    hdf5::check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr),
                fmt::format("select rows of {}", name_));
    hdf5::Handle mem_space(H5Screate_simple(rank(width_), count, nullptr), H5Sclose,
                           "create a dataspace");
    hdf5::check(
        H5Dwrite(set_, H5Type<T>::mem(), mem_space, file_space, H5P_DEFAULT, staged_.data()),
        fmt::format("write dataset {}", name_));
    rows_ += rows;
    staged_.clear();
  }

  hid_t id() const { return set_; }

 private:
  static int rank(hsize_t width) { return width == 1 ? 1 : 2; }

  static hdf5::Handle create(hid_t parent, const char* name, hsize_t width, hsize_t chunk_rows) {
    const hsize_t dims[2] = {0, width}, max_dims[2] = {H5S_UNLIMITED, width};
    const hsize_t chunk[2] = {chunk_rows, width};
    hdf5::Handle space(H5Screate_simple(rank(width), dims, max_dims), H5Sclose,
                       "create a dataspace");
    hdf5::Handle properties(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, "create dataset properties");
    hdf5::check(H5Pset_chunk(properties, rank(width), chunk),
                fmt::format("chunk dataset {}", name));
    return hdf5::Handle(
        H5Dcreate2(parent, name, H5Type<T>::file(), space, H5P_DEFAULT, properties, H5P_DEFAULT),
        H5Dclose, fmt::format("create dataset {}", name));
  }

  hsize_t width_;
  hdf5::Handle set_;
  const char* name_;
  hsize_t rows_ = 0;
  std::vector<T> staged_;
};

}  // namespace palpate::detail
