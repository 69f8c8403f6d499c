#include "palpate/offline/partial_file.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <hdf5.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>

#include "palpate/core/error.hpp"
#include "palpate/file/detail/compliance_file_internal.hpp"
#include "palpate/file/detail/hdf5_support.hpp"

namespace palpate {

namespace {

using hdf5::check;
using hdf5::Handle;

constexpr const char* kG = "/compliance/G";
constexpr const char* kDone = "/checkpoint/block_done";
constexpr const char* kDiagonal = "/checkpoint/diagonal";
constexpr const char* kChecks = "/checkpoint/column_checks";
constexpr hsize_t kChunkRows = 256;

using RowMajorD = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMajorF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A dataset whose storage is allocated now, at fixed addresses, and never
// moves: later writes change raw data only, never HDF5's metadata, so a
// run killed mid-write leaves a file HDF5 still opens.
Handle fixed_dataset(hid_t file, const char* path, hid_t type, std::vector<hsize_t> dims,
                     std::vector<hsize_t> chunk = {}) {
  Handle space(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), H5Sclose,
               "create a dataspace");
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, "create a property list");
  if (!chunk.empty())
    check(H5Pset_chunk(dcpl, static_cast<int>(chunk.size()), chunk.data()), "chunk");
  check(H5Pset_alloc_time(dcpl, H5D_ALLOC_TIME_EARLY), "allocate early");
  check(H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER), "no fill");
  check(H5Pset_obj_track_times(dcpl, false), "no times");
  return Handle(H5Dcreate2(file, path, type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT), H5Dclose,
                fmt::format("create dataset {}", path));
}

// Writes @p data (row-major, memory type @p mem_type) into rows [row, row + rows) of a 2-D set.
void write_rows(hid_t set, hid_t mem_type, hsize_t row, hsize_t rows, hsize_t cols, hsize_t col,
                const void* data, const char* what) {
  Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
  hsize_t start[2] = {row, col}, count[2] = {rows, cols};
  check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr), what);
  Handle mem_space(H5Screate_simple(2, count, nullptr), H5Sclose, "create a dataspace");
  check(H5Dwrite(set, mem_type, mem_space, file_space, H5P_DEFAULT, data),
        fmt::format("write {}", what));
}

std::string read_string_attribute(hid_t object, const char* name) {
  if (H5Aexists(object, name) <= 0) return {};
  Handle attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose, fmt::format("open attribute {}", name));
  Handle type = hdf5::string_type();
  char* data = nullptr;
  if (H5Aread(attr, type, &data) < 0) return {};
  std::string s = data ? data : "";
  Handle space(H5Aget_space(attr), H5Sclose, "get a dataspace");
  H5Dvlen_reclaim(type, space, H5P_DEFAULT, &data);
  return s;
}

bool read_int64_attribute(hid_t object, const char* name, std::int64_t* value) {
  if (H5Aexists(object, name) <= 0) return false;
  Handle attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose, fmt::format("open attribute {}", name));
  Handle space(H5Aget_space(attr), H5Sclose, "get a dataspace");
  if (H5Sget_simple_extent_npoints(space) != 1) return false;
  return H5Aread(attr, H5T_NATIVE_INT64, value) >= 0;
}

void set_string_attribute(hid_t object, const char* name, const std::string& value) {
  if (H5Aexists(object, name) > 0)
    check(H5Adelete(object, name), fmt::format("replace attribute {}", name));
  hdf5::write_string_attribute(object, name, value);
}

// True if another process holds the file open for writing (HDF5 locks the
// files it writes with flock).
bool locked_by_another_process(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool busy = ::flock(fd, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  ::close(fd);
  return busy;
}

}  // namespace

std::string ShardIdentity::describe() const {
  return fmt::format("columns {}:{} of {}, blocks of {}, {}, input {}", columns_begin, columns_end,
                     columns_total, block_columns,
                     precision == Precision::kFloat32 ? "float32" : "float64",
                     input_hash.substr(0, 19) + "…");
}

std::filesystem::path checkpoint_path(const std::filesystem::path& output) {
  const auto dir = output.has_parent_path() ? output.parent_path() : std::filesystem::path(".");
  return dir / fmt::format(".{}.checkpoint", output.filename().string());
}

struct PartialFile::Impl {
  std::filesystem::path path;
  std::optional<Handle> file;
  ShardIdentity id;
  std::string blas;
  std::vector<int> check_columns;
  std::vector<std::int8_t> done;
  int fd = -1;  // HDF5's own descriptor, for fsync

  hid_t h() const { return *file; }
  int width() const { return id.columns_end - id.columns_begin; }

  void sync() {
    check(H5Fflush(h(), H5F_SCOPE_LOCAL), fmt::format("flush {}", path.string()));
    if (fd >= 0 && ::fsync(fd) != 0)
      throw SystemError(fmt::format("cannot sync {}: {}", path.string(), std::strerror(errno)));
  }

  void open_fd() {
    void* handle = nullptr;
    if (H5Fget_vfd_handle(h(), H5P_DEFAULT, &handle) >= 0 && handle)
      fd = *static_cast<int*>(handle);
  }

  // Reads the identity and checkpoint of an open file; @returns the reason it is unusable, or "".
  std::string load() {
    if (read_string_attribute(h(), "format") != kPartialFormatName) return "not a shard file";
    std::int64_t b = 0, e = 0, t = 0, k = 0;
    if (!read_int64_attribute(h(), "columns_begin", &b) ||
        !read_int64_attribute(h(), "columns_end", &e) ||
        !read_int64_attribute(h(), "columns_total", &t) ||
        !read_int64_attribute(h(), "block_columns", &k))
      return "its column range attributes are missing";
    if (!(k > 0 && b >= 0 && b < e && e <= t && b % k == 0 && (e % k == 0 || e == t) &&
          t <= std::numeric_limits<int>::max()))
      return fmt::format("its column range {}:{} of {} (blocks of {}) is not valid", b, e, t, k);
    id.columns_begin = static_cast<int>(b);
    id.columns_end = static_cast<int>(e);
    id.columns_total = static_cast<int>(t);
    id.block_columns = static_cast<int>(k);
    id.input_hash = read_string_attribute(h(), "input_hash");
    blas = read_string_attribute(h(), "blas");
    if (H5Lexists(h(), "/compliance", H5P_DEFAULT) <= 0 || H5Lexists(h(), kG, H5P_DEFAULT) <= 0 ||
        H5Lexists(h(), "/checkpoint", H5P_DEFAULT) <= 0 ||
        H5Lexists(h(), kDone, H5P_DEFAULT) <= 0 || H5Lexists(h(), kDiagonal, H5P_DEFAULT) <= 0 ||
        H5Lexists(h(), kChecks, H5P_DEFAULT) <= 0)
      return "a dataset is missing";
    {
      Handle set(H5Dopen2(h(), kG, H5P_DEFAULT), H5Dclose, "open /compliance/G");
      Handle type(H5Dget_type(set), H5Tclose, "get the type of G");
      id.precision = H5Tget_size(type) == 4 ? Precision::kFloat32 : Precision::kFloat64;
      Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
      hsize_t dims[2] = {0, 0};
      if (H5Sget_simple_extent_ndims(space) != 2) return "its G is not a matrix";
      H5Sget_simple_extent_dims(space, dims, nullptr);
      if (dims[0] != static_cast<hsize_t>(t) || dims[1] != static_cast<hsize_t>(e - b))
        return fmt::format("its G is {} × {}, expected {} × {}", dims[0], dims[1], t, e - b);
    }
    done.assign(static_cast<size_t>(id.blocks()), 0);
    {
      Handle set(H5Dopen2(h(), kDone, H5P_DEFAULT), H5Dclose, "open the checkpoint");
      Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
      if (H5Sget_simple_extent_npoints(space) != static_cast<hssize_t>(done.size()))
        return "its checkpoint does not have one flag per block";
      if (H5Dread(set, H5T_NATIVE_INT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, done.data()) < 0)
        return "its checkpoint cannot be read";
    }
    {
      Handle set(H5Dopen2(h(), kChecks, H5P_DEFAULT), H5Dclose, "open the checks");
      Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
      hsize_t dims[2] = {0, 0};
      if (H5Sget_simple_extent_ndims(space) != 2) return "its checks are not a table";
      H5Sget_simple_extent_dims(space, dims, nullptr);
      std::vector<double> rows(dims[0] * 3);
      if (dims[1] != 3 || (!rows.empty() && H5Dread(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL,
                                                    H5P_DEFAULT, rows.data()) < 0))
        return "its checks cannot be read";
      check_columns.clear();
      for (hsize_t i = 0; i < dims[0]; ++i) check_columns.push_back(static_cast<int>(rows[3 * i]));
    }
    return {};
  }

  std::vector<double> check_rows() const {
    std::vector<double> rows(3 * check_columns.size());
    if (rows.empty()) return rows;
    Handle set(H5Dopen2(h(), kChecks, H5P_DEFAULT), H5Dclose, "open the checks");
    check(H5Dread(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows.data()),
          "read the checks");
    return rows;
  }
};

PartialFile::PartialFile(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PartialFile::~PartialFile() = default;

std::unique_ptr<PartialFile> PartialFile::create(const std::filesystem::path& path,
                                                 const ComplianceModel& model,
                                                 const ShardIdentity& id,
                                                 const std::vector<int>& check_columns,
                                                 const std::string& blas) {
  PALPATE_DEMAND(id.block_columns > 0 && id.columns_begin % id.block_columns == 0 &&
                 id.columns_begin < id.columns_end && id.columns_end <= id.columns_total);
  PALPATE_DEMAND(id.columns_total == 3 * model.compliance_vertices.size());
  PALPATE_DEMAND(id.input_hash == model.input_hash);
  hdf5::silence_hdf5();
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->id = id;
  impl->blas = blas;
  impl->check_columns = check_columns;
  impl->file.emplace(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose,
                     fmt::format("create {}", path.string()));
  const hid_t f = impl->h();
  detail::write_root_attributes(f, model, kPartialFormatName);
  hdf5::write_int64_attribute(f, "columns_begin", id.columns_begin);
  hdf5::write_int64_attribute(f, "columns_end", id.columns_end);
  hdf5::write_int64_attribute(f, "columns_total", id.columns_total);
  hdf5::write_int64_attribute(f, "block_columns", id.block_columns);
  hdf5::write_string_attribute(f, "blas", blas);
  Sha256 unused;
  detail::write_model_datasets(f, model, unused);

  const auto m = static_cast<hsize_t>(id.columns_total);
  const auto w = static_cast<hsize_t>(impl->width());
  const bool single = id.precision == Precision::kFloat32;
  // Chunks one block wide, aligned to the blocks: each block fills its chunks
  // whole, once.
  fixed_dataset(f, kG, single ? H5T_IEEE_F32LE : H5T_IEEE_F64LE, {m, w},
                {std::min(kChunkRows, m), std::min(static_cast<hsize_t>(id.block_columns), w)});
  hdf5::group(f, "checkpoint");
  {
    Handle set = fixed_dataset(f, kDone, H5T_STD_I8LE, {static_cast<hsize_t>(id.blocks())});
    const std::vector<std::int8_t> none(static_cast<size_t>(id.blocks()), 0);
    check(H5Dwrite(set, H5T_NATIVE_INT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, none.data()),
          "write the checkpoint");
    hdf5::write_string_attribute(
        set, "meaning", "1: block b (columns [(first_block + b)·block_columns, …)) is complete");
  }
  fixed_dataset(f, kDiagonal, H5T_IEEE_F64LE, {w, 3});
  {
    Handle set = fixed_dataset(f, kChecks, H5T_IEEE_F64LE, {check_columns.size(), 3});
    std::vector<double> rows;
    for (const int c : check_columns) rows.insert(rows.end(), {double(c), NAN, NAN});
    if (!rows.empty())
      check(H5Dwrite(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows.data()),
            "write the checks");
  }
  impl->done.assign(static_cast<size_t>(id.blocks()), 0);
  impl->open_fd();
  impl->sync();
  return std::unique_ptr<PartialFile>(new PartialFile(std::move(impl)));
}

std::unique_ptr<PartialFile> PartialFile::open_to_resume(const std::filesystem::path& path,
                                                         const ShardIdentity& id,
                                                         std::string* why) {
  hdf5::silence_hdf5();
  if (locked_by_another_process(path))
    throw InputError(fmt::format(
        "{}: another palpate-precompute is computing this output now (the file is locked); wait "
        "for it, or stop it",
        path.string()));
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  if (f < 0) {
    *why = "HDF5 cannot open it";
    return nullptr;
  }
  impl->file.emplace(f, H5Fclose, "open");
  try {
    if (std::string reason = impl->load(); !reason.empty()) {
      *why = reason;
      return nullptr;
    }
  } catch (const SystemError& e) {
    *why = e.what();
    return nullptr;
  }
  if (!(impl->id == id)) {
    *why = fmt::format("it holds {}; this run computes {}", impl->id.describe(), id.describe());
    return nullptr;
  }
  if (H5Aexists(f, "complete") > 0) {
    *why = "it is marked complete";  // a complete shard is renamed: this one was left mid-rename
    return nullptr;
  }
  impl->open_fd();
  return std::unique_ptr<PartialFile>(new PartialFile(std::move(impl)));
}

std::unique_ptr<PartialFile> PartialFile::open_complete(const std::filesystem::path& path) {
  hdf5::silence_hdf5();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec))
    throw InputError(fmt::format("{}: no such file", path.string()));
  if (H5Fis_hdf5(path.c_str()) <= 0)
    throw InputError(
        fmt::format("{}: not an HDF5 file; expected a shard written by "
                    "palpate-precompute --shard or --columns",
                    path.string()));
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) throw InputError(fmt::format("{}: HDF5 cannot open it (corrupt?)", path.string()));
  impl->file.emplace(f, H5Fclose, "open");
  const std::string format = read_string_attribute(f, "format");
  if (format == kComplianceFormatName)
    throw InputError(
        fmt::format("{}: a complete compliance file, not a shard: merge takes the "
                    "shards written by palpate-precompute --shard or --columns",
                    path.string()));
  if (std::string reason = impl->load(); !reason.empty())
    throw InputError(fmt::format("{}: not a usable shard: {}", path.string(), reason));
  const long done = std::count(impl->done.begin(), impl->done.end(), 1);
  if (done < static_cast<long>(impl->done.size()) || H5Aexists(f, "complete") <= 0)
    throw InputError(fmt::format(
        "{}: incomplete shard ({} of {} blocks of {}): run its shard again to finish it "
        "(it resumes from its checkpoint)",
        path.string(), done, impl->done.size(), impl->id.describe()));
  return std::unique_ptr<PartialFile>(new PartialFile(std::move(impl)));
}

const std::filesystem::path& PartialFile::path() const { return impl_->path; }
const ShardIdentity& PartialFile::identity() const { return impl_->id; }
const std::string& PartialFile::blas() const { return impl_->blas; }
const std::vector<int>& PartialFile::check_columns() const { return impl_->check_columns; }

std::vector<int> PartialFile::pending_blocks() const {
  std::vector<int> pending;
  for (size_t i = 0; i < impl_->done.size(); ++i)
    if (impl_->done[i] != 1) pending.push_back(impl_->id.first_block() + static_cast<int>(i));
  return pending;
}

void PartialFile::write_block(const SolvedBlock& block) {
  Impl& p = *impl_;
  const auto m = static_cast<hsize_t>(p.id.columns_total);
  const int local = block.index - p.id.first_block();
  PALPATE_DEMAND(local >= 0 && local < p.id.blocks());
  PALPATE_DEMAND(block.first == block.index * p.id.block_columns &&
                 block.columns.rows() == p.id.columns_total);
  const auto w = static_cast<hsize_t>(block.columns.cols());
  const auto col = static_cast<hsize_t>(block.first - p.id.columns_begin);
  {
    Handle set(H5Dopen2(p.h(), kG, H5P_DEFAULT), H5Dclose, "open /compliance/G");
    const RowMajorD rows = block.columns;
    if (p.id.precision == Precision::kFloat32) {
      const RowMajorF rows32 = rows.cast<float>();
      write_rows(set, H5T_NATIVE_FLOAT, 0, m, w, col, rows32.data(), "columns of /compliance/G");
    } else {
      write_rows(set, H5T_NATIVE_DOUBLE, 0, m, w, col, rows.data(), "columns of /compliance/G");
    }
  }
  {
    // Column c's entries in its vertex's diagonal block, G(3k..3k+2, c), in
    // float64: the merge's softness and definiteness check need no G in double.
    RowMajorD diagonal(static_cast<Eigen::Index>(w), 3);
    for (Eigen::Index i = 0; i < diagonal.rows(); ++i) {
      const Eigen::Index k = (block.first + i) / 3;
      diagonal.row(i) = block.columns.col(i).segment<3>(3 * k).transpose();
    }
    Handle set(H5Dopen2(p.h(), kDiagonal, H5P_DEFAULT), H5Dclose, "open the diagonal");
    write_rows(set, H5T_NATIVE_DOUBLE, col, w, 3, 0, diagonal.data(), "the diagonal entries");
  }
  if (!block.checks.empty()) {
    Handle set(H5Dopen2(p.h(), kChecks, H5P_DEFAULT), H5Dclose, "open the checks");
    for (const auto& c : block.checks) {
      const auto at = std::find(p.check_columns.begin(), p.check_columns.end(), c.column);
      if (at == p.check_columns.end()) continue;
      const double row[3] = {double(c.column), c.residual, c.mismatch};
      write_rows(set, H5T_NATIVE_DOUBLE, static_cast<hsize_t>(at - p.check_columns.begin()), 1, 3,
                 0, row, "a column check");
    }
  }
  // The columns on disk first, then the flag: a crash in between leaves the
  // block pending, never flagged with missing columns.
  p.sync();
  {
    Handle set(H5Dopen2(p.h(), kDone, H5P_DEFAULT), H5Dclose, "open the checkpoint");
    Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
    hsize_t start[1] = {static_cast<hsize_t>(local)}, count[1] = {1};
    check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr),
          "select a flag");
    Handle mem_space(H5Screate_simple(1, count, nullptr), H5Sclose, "create a dataspace");
    const std::int8_t one = 1;
    check(H5Dwrite(set, H5T_NATIVE_INT8, mem_space, file_space, H5P_DEFAULT, &one), "flag a block");
  }
  check(H5Fflush(p.h(), H5F_SCOPE_LOCAL), fmt::format("flush {}", p.path.string()));
  p.done[static_cast<size_t>(local)] = 1;
}

void PartialFile::finish(const std::string& report_json) {
  Impl& p = *impl_;
  PALPATE_DEMAND(pending_blocks().empty());
  set_string_attribute(p.h(), "report_json", report_json);
  hdf5::write_int_attribute(p.h(), "complete", 1);
  p.sync();
}

void PartialFile::close() {
  if (impl_->file && !impl_->file->reset())
    throw SystemError(fmt::format("HDF5: cannot close {}", impl_->path.string()));
  impl_->file.reset();
  impl_->fd = -1;
}

ComplianceModel PartialFile::model() const {
  return detail::read_compliance_file(impl_->path, nullptr, nullptr, kPartialFormatName);
}

std::string PartialFile::report_json() const {
  return read_string_attribute(impl_->h(), "report_json");
}

void PartialFile::read_rows(long first, long count, double* band) const {
  const Impl& p = *impl_;
  Handle set(H5Dopen2(p.h(), kG, H5P_DEFAULT), H5Dclose, "open /compliance/G");
  Handle file_space(H5Dget_space(set), H5Sclose, "get a dataspace");
  hsize_t start[2] = {static_cast<hsize_t>(first), 0},
          count2[2] = {static_cast<hsize_t>(count), static_cast<hsize_t>(p.width())};
  check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count2, nullptr),
        "select rows");
  // Straight into the band's columns [begin, end), converted to double by HDF5.
  hsize_t band_dims[2] = {static_cast<hsize_t>(count), static_cast<hsize_t>(p.id.columns_total)};
  Handle mem_space(H5Screate_simple(2, band_dims, nullptr), H5Sclose, "create a dataspace");
  hsize_t at[2] = {0, static_cast<hsize_t>(p.id.columns_begin)};
  check(H5Sselect_hyperslab(mem_space, H5S_SELECT_SET, at, nullptr, count2, nullptr),
        "select columns");
  if (H5Dread(set, H5T_NATIVE_DOUBLE, mem_space, file_space, H5P_DEFAULT, band) < 0)
    throw InputError(fmt::format("{}: /compliance/G: cannot be read (corrupt?)", p.path.string()));
}

Eigen::MatrixX3d PartialFile::diagonal_entries() const {
  RowMajorD rows(impl_->width(), 3);
  Handle set(H5Dopen2(impl_->h(), kDiagonal, H5P_DEFAULT), H5Dclose, "open the diagonal");
  if (H5Dread(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows.data()) < 0)
    throw InputError(
        fmt::format("{}: {}: cannot be read (corrupt?)", impl_->path.string(), kDiagonal));
  return rows;
}

std::vector<ColumnCheck> PartialFile::checks() const {
  const std::vector<double> rows = impl_->check_rows();
  std::vector<ColumnCheck> checks;
  for (size_t i = 0; i + 2 < rows.size(); i += 3)
    checks.push_back({static_cast<int>(rows[i]), rows[i + 1], rows[i + 2]});
  return checks;
}

}  // namespace palpate
