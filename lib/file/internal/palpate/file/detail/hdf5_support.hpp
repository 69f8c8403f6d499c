#pragma once
// Private to the library: RAII handles and small writers over the HDF5 C API,
// shared by the compliance file and the session recorder.

#include <fmt/format.h>
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"

namespace palpate::hdf5 {

// An HDF5 identifier closed by its own function on scope exit.
class Handle {
 public:
  Handle(hid_t id, herr_t (*close)(hid_t), const std::string& what) : id_(id), close_(close) {
    if (id_ < 0) throw SystemError(fmt::format("HDF5: cannot {}", what));
  }
  ~Handle() { reset(); }
  Handle(Handle&& other) noexcept : id_(other.id_), close_(other.close_) { other.id_ = -1; }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  Handle& operator=(Handle&&) = delete;
  operator hid_t() const { return id_; }
  // Closes now; @returns false if HDF5 reported an error (a write it had deferred failed).
  bool reset() {
    const hid_t id = id_;
    id_ = -1;
    return id < 0 || close_(id) >= 0;
  }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

inline void check(herr_t status, const std::string& what) {
  if (status < 0) throw SystemError(fmt::format("HDF5: cannot {}", what));
}

// HDF5's automatic error printing is per thread (the library is built
// thread-safe): call this on every thread that makes HDF5 calls.
inline void silence_hdf5() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

inline Handle group(hid_t parent, const std::string& name) {
  return Handle(H5Gcreate2(parent, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose,
                fmt::format("create group {}", name));
}

inline Handle string_type() {
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose, "copy the string type");
  check(H5Tset_size(type, H5T_VARIABLE), "make a variable-length string type");
  check(H5Tset_cset(type, H5T_CSET_UTF8), "set UTF-8");
  return type;
}

inline void write_string_attribute(hid_t object, const char* name, const std::string& value) {
  Handle type = string_type();
  Handle space(H5Screate(H5S_SCALAR), H5Sclose, "create a scalar dataspace");
  Handle attr(H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
              fmt::format("create attribute {}", name));
  const char* data = value.c_str();
  check(H5Awrite(attr, type, &data), fmt::format("write attribute {}", name));
}

// A 1-D attribute of variable-length UTF-8 strings.
inline void write_strings_attribute(hid_t object, const char* name,
                                    const std::vector<std::string>& values) {
  Handle type = string_type();
  hsize_t dims[1] = {values.size()};
  Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose, "create a dataspace");
  Handle attr(H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
              fmt::format("create attribute {}", name));
  std::vector<const char*> data;
  for (const auto& s : values) data.push_back(s.c_str());
  if (!data.empty())
    check(H5Awrite(attr, type, data.data()), fmt::format("write attribute {}", name));
}

// A scalar attribute stored as @p file_type from memory of @p mem_type.
inline void write_scalar_attribute(hid_t object, const char* name, hid_t file_type, hid_t mem_type,
                                   const void* value) {
  Handle space(H5Screate(H5S_SCALAR), H5Sclose, "create a scalar dataspace");
  Handle attr(H5Acreate2(object, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
              fmt::format("create attribute {}", name));
  check(H5Awrite(attr, mem_type, value), fmt::format("write attribute {}", name));
}

inline void write_int_attribute(hid_t object, const char* name, int value) {
  write_scalar_attribute(object, name, H5T_STD_I32LE, H5T_NATIVE_INT, &value);
}
inline void write_int64_attribute(hid_t object, const char* name, std::int64_t value) {
  write_scalar_attribute(object, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value);
}
inline void write_uint64_attribute(hid_t object, const char* name, std::uint64_t value) {
  write_scalar_attribute(object, name, H5T_STD_U64LE, H5T_NATIVE_UINT64, &value);
}
inline void write_double_attribute(hid_t object, const char* name, double value) {
  write_scalar_attribute(object, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value);
}

}  // namespace palpate::hdf5
