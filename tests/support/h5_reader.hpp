#pragma once
// A session (or any HDF5) file read back with the HDF5 C API, sharing no
// code with palpate's writers: datasets and attributes by name. Problems are
// test failures; the readers then return empty values.

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace palpate::testing {

template <typename T>
hid_t native();
template <>
inline hid_t native<double>() {
  return H5T_NATIVE_DOUBLE;
}
template <>
inline hid_t native<std::uint64_t>() {
  return H5T_NATIVE_UINT64;
}
template <>
inline hid_t native<std::int64_t>() {
  return H5T_NATIVE_INT64;
}
template <>
inline hid_t native<std::uint32_t>() {
  return H5T_NATIVE_UINT32;
}
template <>
inline hid_t native<std::int32_t>() {
  return H5T_NATIVE_INT32;
}
template <>
inline hid_t native<std::int8_t>() {
  return H5T_NATIVE_INT8;
}
template <>
inline hid_t native<std::uint8_t>() {
  return H5T_NATIVE_UINT8;
}

// A file opened read-only.
class H5Reader {
 public:
  explicit H5Reader(const std::filesystem::path& file)
      : id_(H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT)) {
    if (id_ < 0) ADD_FAILURE() << "HDF5 cannot open " << file;
  }
  ~H5Reader() {
    if (id_ >= 0) H5Fclose(id_);
  }
  H5Reader(const H5Reader&) = delete;
  H5Reader& operator=(const H5Reader&) = delete;

  // Dataset @p name as rows × cols values (cols = 1 for a 1-D dataset).
  template <typename T>
  std::vector<T> read(const std::string& name, hsize_t cols = 1) const {
    std::vector<T> out;
    const hid_t set = H5Dopen2(id_, name.c_str(), H5P_DEFAULT);
    if (set < 0) {
      ADD_FAILURE() << "no dataset " << name;
      return out;
    }
    const hid_t space = H5Dget_space(set);
    hsize_t dims[2] = {0, 1};
    const int rank = H5Sget_simple_extent_ndims(space);
    H5Sget_simple_extent_dims(space, dims, nullptr);
    EXPECT_EQ(rank, cols == 1 ? 1 : 2) << name;
    EXPECT_EQ(dims[1], rank == 2 ? cols : 1) << name;
    out.resize(dims[0] * cols);
    if (!out.empty()) {
      EXPECT_GE(H5Dread(set, native<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()), 0) << name;
    }
    H5Sclose(space);
    H5Dclose(set);
    return out;
  }

  bool has_attribute(const std::string& object, const std::string& name) const {
    return H5Aexists_by_name(id_, object.c_str(), name.c_str(), H5P_DEFAULT) > 0;
  }

  template <typename T>
  T attribute(const std::string& object, const std::string& name) const {
    T value{};
    const hid_t a = open_attribute(object, name);
    if (a < 0) return value;
    EXPECT_GE(H5Aread(a, native<T>(), &value), 0) << object << " " << name;
    H5Aclose(a);
    return value;
  }

  std::string string_attribute(const std::string& object, const std::string& name) const {
    const auto v = strings_attribute(object, name);
    return v.size() == 1 ? v[0] : std::string();
  }

  // A scalar or 1-D attribute of variable-length strings.
  std::vector<std::string> strings_attribute(const std::string& object,
                                             const std::string& name) const {
    std::vector<std::string> out;
    const hid_t a = open_attribute(object, name);
    if (a < 0) return out;
    const hid_t space = H5Aget_space(a);
    const hssize_t n = H5Sget_simple_extent_npoints(space);
    const hid_t type = H5Tcopy(H5T_C_S1);
    H5Tset_size(type, H5T_VARIABLE);
    H5Tset_cset(type, H5T_CSET_UTF8);
    std::vector<char*> raw(static_cast<std::size_t>(n), nullptr);
    if (H5Aread(a, type, raw.data()) >= 0) {
      for (char* s : raw) out.emplace_back(s ? s : "");
      H5Dvlen_reclaim(type, space, H5P_DEFAULT, raw.data());
    } else {
      ADD_FAILURE() << object << " " << name << " is not a string attribute";
    }
    H5Tclose(type);
    H5Sclose(space);
    H5Aclose(a);
    return out;
  }

 private:
  hid_t open_attribute(const std::string& object, const std::string& name) const {
    const hid_t a = H5Aopen_by_name(id_, object.c_str(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0) ADD_FAILURE() << "no attribute " << name << " on " << object;
    return a;
  }

  hid_t id_;
};

}  // namespace palpate::testing
