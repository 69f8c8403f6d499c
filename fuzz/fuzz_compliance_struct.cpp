// The compliance-file loader, structure-aware: every input is a well-formed
// HDF5 file (written here with the HDF5 C API), made from a real compliance
// file (the box model's, as palpate-precompute wrote it) with some of its
// objects changed: datasets and attributes missing, of another type, rank or
// shape, declared huge without data, replaced by a group or a dangling link;
// values replaced (NaN, out of range, repeated); extra objects. The template
// is read back from the file at start-up, so the layout follows the writer.
// load_surface_model must refuse with an InputError or give a model the
// daemon can serve (palpate::fuzz::serve).

#include <fuzzer/FuzzedDataProvider.h>
#include <hdf5.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "fuzz_support.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace {

// An attribute or a dataset of the template: its file type, shape and values.
struct Array {
  std::string name;  // attribute name, or dataset path from the root
  hid_t type = -1;   // a copy, kept for the process's life
  bool is_string = false;
  std::vector<hsize_t> dims;  // empty: scalar
  std::vector<double> numbers;
  std::vector<std::string> strings;
  std::vector<Array> attributes;  // of a dataset
};

struct Template {
  std::vector<Array> root_attributes;
  std::vector<std::string> groups;
  std::vector<Array> datasets;
};

hid_t vlen_string_type() {
  const hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, H5T_VARIABLE);
  H5Tset_cset(t, H5T_CSET_UTF8);
  return t;
}

std::size_t count(const std::vector<hsize_t>& dims) {
  std::size_t n = 1;
  for (const hsize_t d : dims) n *= static_cast<std::size_t>(d);
  return n;
}

// Reads the values of an attribute (is_attribute) or dataset into @p a.
void read_values(hid_t id, bool is_attribute, Array& a) {
  const hid_t space = is_attribute ? H5Aget_space(id) : H5Dget_space(id);
  const int rank = H5Sget_simple_extent_ndims(space);
  a.dims.resize(static_cast<std::size_t>(rank));
  if (rank > 0) H5Sget_simple_extent_dims(space, a.dims.data(), nullptr);
  H5Sclose(space);
  a.type = is_attribute ? H5Aget_type(id) : H5Dget_type(id);
  a.is_string = H5Tget_class(a.type) == H5T_STRING;
  const std::size_t n = count(a.dims);
  herr_t status = 0;
  if (a.is_string) {
    const hid_t mem = vlen_string_type();
    std::vector<char*> raw(n, nullptr);
    status = is_attribute ? H5Aread(id, mem, raw.data())
                          : H5Dread(id, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, raw.data());
    for (char* s : raw) {
      a.strings.emplace_back(s ? s : "");
      H5free_memory(s);
    }
    H5Tclose(mem);
  } else {
    a.numbers.resize(n);
    status = is_attribute
                 ? H5Aread(id, H5T_NATIVE_DOUBLE, a.numbers.data())
                 : H5Dread(id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, a.numbers.data());
  }
  if (status < 0) palpate::fuzz::fail("cannot read the template " + a.name);
}

herr_t read_attribute(hid_t object, const char* name, const H5A_info_t*, void* out) {
  Array a;
  a.name = name;
  const hid_t attr = H5Aopen(object, name, H5P_DEFAULT);
  read_values(attr, true, a);
  H5Aclose(attr);
  static_cast<std::vector<Array>*>(out)->push_back(std::move(a));
  return 0;
}

herr_t read_link(hid_t root, const char* name, const H5L_info_t*, void* out) {
  auto& t = *static_cast<Template*>(out);
  const hid_t object = H5Oopen(root, name, H5P_DEFAULT);
  if (H5Iget_type(object) == H5I_GROUP) {
    t.groups.push_back(std::string("/") + name);
  } else {
    Array a;
    a.name = std::string("/") + name;
    read_values(object, false, a);
    H5Aiterate2(object, H5_INDEX_NAME, H5_ITER_INC, nullptr, read_attribute, &a.attributes);
    t.datasets.push_back(std::move(a));
  }
  H5Oclose(object);
  return 0;
}

const Template& the_template() {
  static const Template t = [] {
    Template r;
    const hid_t file =
        H5Fopen(palpate::fuzz::box_compliance_file().c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (file < 0) palpate::fuzz::fail("cannot open the template compliance file");
    H5Aiterate2(file, H5_INDEX_NAME, H5_ITER_INC, nullptr, read_attribute, &r.root_attributes);
    H5Lvisit(file, H5_INDEX_NAME, H5_ITER_INC, read_link, &r);
    H5Fclose(file);
    if (r.datasets.empty()) palpate::fuzz::fail("the template compliance file has no dataset");
    return r;
  }();
  return t;
}

// ---- writing one input ---------------------------------------------------------

double odd_number(FuzzedDataProvider& in, const Array& a) {
  switch (in.ConsumeIntegralInRange(0, 9)) {
    case 0:
      return std::numeric_limits<double>::quiet_NaN();
    case 1:
      return std::numeric_limits<double>::infinity();
    case 2:
      return -1;
    case 3:
      return static_cast<double>(a.numbers.size());  // one past the end of something
    case 4:
      return 2147483647.0;
    case 5:
      return -2147483648.0;
    case 6:
      return a.numbers.empty()
                 ? 0
                 : a.numbers[in.ConsumeIntegralInRange<std::size_t>(0, a.numbers.size() - 1)];
    case 7:
      return in.ConsumeFloatingPoint<double>();
    default:
      return in.ConsumeIntegralInRange(-3, 60);
  }
}

hid_t pick_type(FuzzedDataProvider& in) {
  switch (in.ConsumeIntegralInRange(0, 7)) {
    case 0:
      return H5Tcopy(H5T_IEEE_F64LE);
    case 1:
      return H5Tcopy(H5T_IEEE_F32LE);
    case 2:
      return H5Tcopy(H5T_STD_I32LE);
    case 3:
      return H5Tcopy(H5T_STD_I64BE);
    case 4:
      return H5Tcopy(H5T_STD_U8LE);
    case 5: {
      const hid_t t = H5Tcopy(H5T_C_S1);  // fixed-length string
      H5Tset_size(t, 8);
      return t;
    }
    case 6:
      return vlen_string_type();
    default: {
      const hid_t t = H5Tcreate(H5T_COMPOUND, 16);
      H5Tinsert(t, "a", 0, H5T_NATIVE_DOUBLE);
      H5Tinsert(t, "b", 8, H5T_NATIVE_INT64);
      return t;
    }
  }
}

struct Owned {
  hid_t id;
  herr_t (*close)(hid_t);
  ~Owned() {
    if (id >= 0) close(id);
  }
};

// Writes @p values (numbers or strings, as the type asks) if their count fits
// the shape; leaves the data unwritten (fill values) otherwise.
void write_data(hid_t id, bool is_attribute, hid_t type, const std::vector<hsize_t>& dims,
                const Array& a, const std::vector<double>& numbers) {
  const std::size_t n = count(dims);
  const bool string_type = H5Tget_class(type) == H5T_STRING;
  if (string_type && H5Tis_variable_str(type) > 0 && a.is_string && a.strings.size() == n) {
    std::vector<const char*> p;
    for (const auto& s : a.strings) p.push_back(s.c_str());
    if (is_attribute)
      H5Awrite(id, type, p.data());
    else
      H5Dwrite(id, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, p.data());
  } else if (!string_type && H5Tget_class(type) != H5T_COMPOUND && numbers.size() == n && n > 0) {
    if (is_attribute)
      H5Awrite(id, H5T_NATIVE_DOUBLE, numbers.data());
    else
      H5Dwrite(id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, numbers.data());
  }
}

enum class Change { kNone, kOmit, kValues, kType, kShape, kRank, kHuge, kNotADataset };

Change pick_change(FuzzedDataProvider& in) {
  // Mostly unchanged, so that inputs get past the first checks.
  const int c = in.ConsumeIntegralInRange(0, 15);
  return c < 8 ? Change::kNone : static_cast<Change>(c - 7);
}

std::vector<hsize_t> changed_dims(FuzzedDataProvider& in, const std::vector<hsize_t>& dims,
                                  Change change) {
  std::vector<hsize_t> d = dims;
  if (change == Change::kShape && !d.empty()) {
    for (hsize_t& x : d) x = in.ConsumeIntegralInRange<hsize_t>(0, 2 * x + 3);
  } else if (change == Change::kRank || change == Change::kShape) {
    // Another rank (a scalar becomes an array and back); the same number of
    // values, or a few.
    std::size_t rank = in.ConsumeIntegralInRange<std::size_t>(0, 3);
    if (rank == dims.size()) rank = (rank + 1) % 4;
    d.assign(rank, 1);
    if (!d.empty())
      d[0] = in.ConsumeBool() ? count(dims) : in.ConsumeIntegralInRange<hsize_t>(0, 4);
  } else if (change == Change::kHuge) {
    for (hsize_t& x : d) x = in.ConsumeIntegralInRange<hsize_t>(1, hsize_t{1} << 40);
  }
  return d;
}

std::vector<double> changed_values(FuzzedDataProvider& in, const Array& a) {
  std::vector<double> v = a.numbers;
  if (v.empty()) return v;
  for (int k = in.ConsumeIntegralInRange(1, 4); k > 0; --k)
    v[in.ConsumeIntegralInRange<std::size_t>(0, v.size() - 1)] = odd_number(in, a);
  return v;
}

void write_attribute(FuzzedDataProvider& in, hid_t object, const Array& a) {
  const Change change = pick_change(in);
  if (change == Change::kOmit) return;
  Array value = a;
  if (change == Change::kValues) {
    if (a.is_string)
      for (auto& s : value.strings) s = in.ConsumeRandomLengthString(64);
    else
      value.numbers = changed_values(in, a);
  }
  const auto dims = changed_dims(in, a.dims, change == Change::kHuge ? Change::kShape : change);
  const Owned type{change == Change::kType ? pick_type(in) : H5Tcopy(a.type), H5Tclose};
  const Owned space{dims.empty()
                        ? H5Screate(H5S_SCALAR)
                        : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr),
                    H5Sclose};
  const Owned attr{H5Acreate2(object, a.name.c_str(), type.id, space.id, H5P_DEFAULT, H5P_DEFAULT),
                   H5Aclose};
  if (attr.id >= 0) write_data(attr.id, true, type.id, dims, value, value.numbers);
}

void write_dataset(FuzzedDataProvider& in, hid_t file, hid_t link_plist, const Array& a,
                   const Template& t) {
  const Change change = pick_change(in);
  if (change == Change::kOmit) return;
  if (change == Change::kNotADataset) {
    if (in.ConsumeBool()) {
      Owned g{H5Gcreate2(file, a.name.c_str(), link_plist, H5P_DEFAULT, H5P_DEFAULT), H5Gclose};
    } else {
      // Dangling, or pointing at another dataset (written later or not).
      const auto& other =
          t.datasets[in.ConsumeIntegralInRange<std::size_t>(0, t.datasets.size() - 1)];
      H5Lcreate_soft(in.ConsumeBool() ? "/nowhere" : other.name.c_str(), file, a.name.c_str(),
                     link_plist, H5P_DEFAULT);
    }
    return;
  }
  const auto dims = changed_dims(in, a.dims, change);
  const Owned type{change == Change::kType ? pick_type(in) : H5Tcopy(a.type), H5Tclose};
  const Owned space{dims.empty()
                        ? H5Screate(H5S_SCALAR)
                        : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr),
                    H5Sclose};
  const Owned create{H5Pcreate(H5P_DATASET_CREATE), H5Pclose};
  if (change == Change::kHuge && !dims.empty()) {
    // Declared huge, stored as nothing: chunks are only written with data.
    std::vector<hsize_t> chunk(dims.size());
    for (std::size_t i = 0; i < dims.size(); ++i) chunk[i] = std::min<hsize_t>(dims[i], 64);
    H5Pset_chunk(create.id, static_cast<int>(chunk.size()), chunk.data());
  }
  const Owned set{
      H5Dcreate2(file, a.name.c_str(), type.id, space.id, link_plist, create.id, H5P_DEFAULT),
      H5Dclose};
  if (set.id < 0) return;
  if (change != Change::kHuge)
    write_data(set.id, false, type.id, dims, a,
               change == Change::kValues ? changed_values(in, a) : a.numbers);
  for (const auto& attribute : a.attributes) write_attribute(in, set.id, attribute);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  the_template();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const Template& t = the_template();
  FuzzedDataProvider in(data, size);
  const auto path = palpate::fuzz::scratch_dir() / "model.h5";
  {
    const Owned file{H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose};
    if (file.id < 0) palpate::fuzz::fail("cannot create " + path.string());
    const Owned links{H5Pcreate(H5P_LINK_CREATE), H5Pclose};
    H5Pset_create_intermediate_group(links.id, 1);
    for (const auto& a : t.root_attributes) write_attribute(in, file.id, a);
    for (const auto& g : t.groups)
      if (H5Lexists(file.id, g.c_str(), H5P_DEFAULT) <= 0)
        const Owned group{H5Gcreate2(file.id, g.c_str(), links.id, H5P_DEFAULT, H5P_DEFAULT),
                          H5Gclose};
    for (const auto& a : t.datasets) write_dataset(in, file.id, links.id, a, t);
    // Objects a later version might add: an extra attribute and dataset.
    if (in.ConsumeBool()) {
      Array extra = t.datasets[in.ConsumeIntegralInRange<std::size_t>(0, t.datasets.size() - 1)];
      extra.name = "/" + in.ConsumeRandomLengthString(16);
      write_dataset(in, file.id, links.id, extra, t);
      extra.name = in.ConsumeRandomLengthString(16);
      if (!extra.name.empty()) write_attribute(in, file.id, extra);
    }
  }
  // To look at an input's file (h5dump, h5py) or keep it as a raw seed for
  // fuzz_compliance_file: PALPATE_FUZZ_SAVE_H5=<path> fuzz_compliance_struct <input>.
  if (const char* save = std::getenv("PALPATE_FUZZ_SAVE_H5"))
    std::filesystem::copy_file(path, save, std::filesystem::copy_options::overwrite_existing);
  palpate::SurfaceModel model;
  if (!palpate::fuzz::accepted([&] { model = palpate::load_surface_model("fuzz", path); }))
    return 0;
  palpate::fuzz::serve(model);
  return 0;
}
