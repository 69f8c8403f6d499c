#include "palpate/core/version.hpp"
#include "palpate/offline/precompute.hpp"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <fmt/format.h>
#include <malloc.h>
#include <map>
#include <set>
#include <charconv>
#include <sstream>
#include <toml++/toml.h>

#include "palpate/file/atomic_file.hpp"
#include "palpate/core/error.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/file/hash.hpp"
#include "palpate/offline/partial_file.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/file/xdmf.hpp"
#include "palpate/core/detail/toml_reader.hpp"


namespace palpate {

using nlohmann::json;

namespace {
constexpr int kMaxBlockColumns = 100000;
}  // namespace

Method parse_method(const std::string& name) {
  if (name == "solves") return Method::kSolves;
  if (name == "condensation") return Method::kCondensation;
  if (name == "both") return Method::kBoth;
  throw InputError(fmt::format("method '{}' is not accepted: use solves, condensation or both", name));
}

std::string to_string(Method method) {
  switch (method) {
    case Method::kSolves: return "solves";
    case Method::kCondensation: return "condensation";
    case Method::kBoth: return "both";
  }
  return "?";
}

Precision parse_precision(const std::string& name) {
  if (name == "float64") return Precision::kFloat64;
  if (name == "float32") return Precision::kFloat32;
  throw InputError(fmt::format("precision '{}' is not accepted: use float64 or float32", name));
}

std::string to_string(Precision precision) {
  return precision == Precision::kFloat32 ? "float32" : "float64";
}

void parse_shard(const std::string& text, ColumnShard* shard) {
  auto number = [&](std::string_view digits, int* out) {
    const auto [rest, status] = std::from_chars(digits.data(), digits.data() + digits.size(), *out);
    return status == std::errc() && rest == digits.data() + digits.size() && !digits.empty();
  };
  const auto slash = text.find('/'), colon = text.find(':');
  const std::string_view t(text);
  if (slash != std::string::npos && colon == std::string::npos) {
    ColumnShard s;
    if (number(t.substr(0, slash), &s.index) && number(t.substr(slash + 1), &s.count) &&
        s.count > 0 && s.index >= 0 && s.index < s.count) {
      *shard = s;
      return;
    }
    throw InputError(fmt::format("shard '{}' is not accepted: use INDEX/COUNT with 0 ≤ INDEX < "
                                 "COUNT, e.g. 0/4 … 3/4",
                                 text));
  }
  if (colon != std::string::npos && slash == std::string::npos) {
    ColumnShard s;
    if (number(t.substr(0, colon), &s.begin) && number(t.substr(colon + 1), &s.end) &&
        s.begin >= 0 && s.begin < s.end) {
      *shard = s;
      return;
    }
  }
  throw InputError(fmt::format("columns '{}' are not accepted: use BEGIN:END with 0 ≤ BEGIN < END "
                               "(columns of G, END excluded), or a shard INDEX/COUNT",
                               text));
}

std::filesystem::path shard_output_path(const std::filesystem::path& output, int begin, int end) {
  auto name = fmt::format("{}.part-{}-{}{}", output.stem().string(), begin, end,
                          output.extension().string());
  return output.has_parent_path() ? output.parent_path() / name : std::filesystem::path(name);
}

// ---- job file ----------------------------------------------------------------

using detail::relative_to;

PrecomputeJob read_job_file(const std::filesystem::path& file) {
  const toml::table root = detail::parse_toml_file(file);
  const detail::TomlReader r(file.string());
  const auto base = std::filesystem::absolute(file).parent_path();
  PrecomputeJob job;
  r.only_keys(root, "", {"mesh", "material", "attachment", "compute", "output"});

  double unit = 1.0;
  if (const auto* mesh = root.get("mesh")) {
    const auto& t = r.table(*mesh, "mesh");
    r.only_keys(t, "mesh", {"file", "unit", "fill_size"});
    if (const auto* n = t.get("file")) job.mesh_file = relative_to(base, r.string(*n, "mesh.file"));
    if (const auto* n = t.get("unit")) {
      job.mesh_unit = r.string(*n, "mesh.unit");
      try {
        unit = parse_length_unit(job.mesh_unit).to_metres;
      } catch (const InputError& e) {
        r.fail(n, "mesh.unit", e.what());
      }
    }
    if (const auto* n = t.get("fill_size")) job.fill_size = r.number(*n, "mesh.fill_size");
  }
  if (const auto* material = root.get("material")) {
    const auto& t = r.table(*material, "material");
    r.only_keys(t, "material", {"young_modulus_pa", "poisson_ratio", "group"});
    if (const auto* n = t.get("young_modulus_pa")) job.young_modulus_pa = r.number(*n, "material.young_modulus_pa");
    if (const auto* n = t.get("poisson_ratio")) job.poisson_ratio = r.number(*n, "material.poisson_ratio");
    if (const auto* groups = t.get("group"))
      r.each_table(*groups, "material.group", [&](const toml::table& g) {
        r.only_keys(g, "material.group", {"name", "young_modulus_pa", "poisson_ratio"});
        GroupMaterial gm;
        const auto* name = g.get("name");
        const auto* E = g.get("young_modulus_pa");
        const auto* nu = g.get("poisson_ratio");
        if (!name || !E || !nu)
          r.fail(&g, "material.group", "needs name, young_modulus_pa and poisson_ratio");
        gm.group = r.string(*name, "material.group.name");
        gm.young_modulus_pa = r.number(*E, "material.group.young_modulus_pa");
        gm.poisson_ratio = r.number(*nu, "material.group.poisson_ratio");
        job.group_materials.push_back(gm);
      });
  }
  if (const auto* attachment = root.get("attachment")) {
    const auto& t = r.table(*attachment, "attachment");
    r.only_keys(t, "attachment", {"groups", "ids_file", "boxes", "spheres", "half_spaces"});
    auto& a = job.attachment;
    if (const auto* n = t.get("groups")) {
      const auto* arr = n->as_array();
      if (!arr) r.fail(n, "attachment.groups", "expected an array of group names");
      for (const auto& g : *arr) a.groups.push_back(r.string(g, "attachment.groups"));
    }
    if (const auto* n = t.get("ids_file")) a.ids_file = relative_to(base, r.string(*n, "attachment.ids_file"));
    if (const auto* n = t.get("boxes"))
      r.each_table(*n, "attachment.boxes", [&](const toml::table& b) {
        r.only_keys(b, "attachment.boxes", {"min", "max"});
        if (!b.get("min") || !b.get("max")) r.fail(&b, "attachment.boxes", "needs min and max");
        a.boxes.push_back({unit * r.vec3(*b.get("min"), "attachment.boxes.min"),
                           unit * r.vec3(*b.get("max"), "attachment.boxes.max")});
      });
    if (const auto* n = t.get("spheres"))
      r.each_table(*n, "attachment.spheres", [&](const toml::table& s) {
        r.only_keys(s, "attachment.spheres", {"center", "radius"});
        if (!s.get("center") || !s.get("radius")) r.fail(&s, "attachment.spheres", "needs center and radius");
        a.spheres.push_back({unit * r.vec3(*s.get("center"), "attachment.spheres.center"),
                             unit * r.number(*s.get("radius"), "attachment.spheres.radius")});
      });
    if (const auto* n = t.get("half_spaces"))
      r.each_table(*n, "attachment.half_spaces", [&](const toml::table& h) {
        r.only_keys(h, "attachment.half_spaces", {"point", "normal"});
        if (!h.get("point") || !h.get("normal")) r.fail(&h, "attachment.half_spaces", "needs point and normal");
        a.half_spaces.push_back({unit * r.vec3(*h.get("point"), "attachment.half_spaces.point"),
                                 r.vec3(*h.get("normal"), "attachment.half_spaces.normal")});
      });
  }
  if (const auto* compute = root.get("compute")) {
    const auto& t = r.table(*compute, "compute");
    r.only_keys(t, "compute", {"method", "precision", "block_columns", "tolerance", "memory_limit_gb"});
    if (const auto* n = t.get("method")) {
      try {
        job.method = parse_method(r.string(*n, "compute.method"));
      } catch (const InputError& e) {
        r.fail(n, "compute.method", e.what());
      }
    }
    if (const auto* n = t.get("precision")) {
      try {
        job.precision = parse_precision(r.string(*n, "compute.precision"));
      } catch (const InputError& e) {
        r.fail(n, "compute.precision", e.what());
      }
    }
    if (const auto* n = t.get("block_columns")) {
      const auto v = n->value<int64_t>();
      if (!v || *v < 1 || *v > kMaxBlockColumns)
        r.fail(n, "compute.block_columns", fmt::format("expected an integer from 1 to {}", kMaxBlockColumns));
      job.block_columns = static_cast<int>(*v);
    }
    if (const auto* n = t.get("tolerance")) job.tolerance = r.number(*n, "compute.tolerance");
    if (const auto* n = t.get("memory_limit_gb")) job.memory_limit_bytes = 1e9 * r.number(*n, "compute.memory_limit_gb");
  }
  if (const auto* output = root.get("output")) {
    const auto& t = r.table(*output, "output");
    r.only_keys(t, "output", {"file", "xdmf"});
    if (const auto* n = t.get("file")) job.output = relative_to(base, r.string(*n, "output.file"));
    if (const auto* n = t.get("xdmf")) job.write_xdmf = r.boolean(*n, "output.xdmf");
  }
  return job;
}

std::string to_toml(const PrecomputeJob& job) {
  const double unit = parse_length_unit(job.mesh_unit).to_metres;
  auto vec = [&](const Eigen::Vector3d& v, double scale) {
    return toml::array{v.x() / scale, v.y() / scale, v.z() / scale};
  };
  auto absolute = [](const std::filesystem::path& p) {
    return p.empty() ? std::string() : std::filesystem::absolute(p).string();
  };
  // An empty path is left out: `file = ""` would read back as the job's directory.
  toml::table mesh{{"unit", job.mesh_unit}};
  if (!job.mesh_file.empty()) mesh.insert("file", absolute(job.mesh_file));
  if (job.fill_size > 0) mesh.insert("fill_size", job.fill_size);
  toml::array groups;
  for (const auto& g : job.group_materials)
    groups.push_back(toml::table{{"name", g.group},
                                 {"young_modulus_pa", g.young_modulus_pa},
                                 {"poisson_ratio", g.poisson_ratio}});
  toml::table material;
  if (job.young_modulus_pa) material.insert("young_modulus_pa", *job.young_modulus_pa);
  if (job.poisson_ratio) material.insert("poisson_ratio", *job.poisson_ratio);
  if (!groups.empty()) material.insert("group", groups);
  toml::table attachment;
  const auto& a = job.attachment;
  if (!a.groups.empty()) {
    toml::array g;
    for (const auto& name : a.groups) g.push_back(name);
    attachment.insert("groups", g);
  }
  if (!a.ids_file.empty()) attachment.insert("ids_file", absolute(a.ids_file));
  toml::array boxes, spheres, half_spaces;
  for (const auto& b : a.boxes) boxes.push_back(toml::table{{"min", vec(b.min, unit)}, {"max", vec(b.max, unit)}});
  for (const auto& s : a.spheres) spheres.push_back(toml::table{{"center", vec(s.center, unit)}, {"radius", s.radius / unit}});
  for (const auto& h : a.half_spaces) half_spaces.push_back(toml::table{{"point", vec(h.point, unit)}, {"normal", vec(h.normal, 1.0)}});
  if (!boxes.empty()) attachment.insert("boxes", boxes);
  if (!spheres.empty()) attachment.insert("spheres", spheres);
  if (!half_spaces.empty()) attachment.insert("half_spaces", half_spaces);
  toml::table compute{{"method", to_string(job.method)},
                      {"precision", to_string(job.precision)},
                      {"block_columns", job.block_columns},
                      {"tolerance", job.tolerance}};
  if (job.memory_limit_bytes > 0) compute.insert("memory_limit_gb", job.memory_limit_bytes / 1e9);
  toml::table output{{"xdmf", job.write_xdmf}};
  if (!job.output.empty()) output.insert("file", absolute(job.output));
  toml::table root{{"mesh", mesh}, {"material", material}, {"attachment", attachment},
                   {"compute", compute}, {"output", output}};
  std::ostringstream out;
  out << "# palpate-precompute job (written by " << "palpate-precompute " PALPATE_VERSION << ")\n"
      << root << "\n";
  return out.str();
}

// ---- the pipeline --------------------------------------------------------------

namespace {

void validate_job(const PrecomputeJob& job) {
  if (job.mesh_file.empty()) throw InputError("no mesh given: use --mesh FILE or [mesh] file in the job file");
  if (job.output.empty()) throw InputError("no output file given: use -o FILE.h5 or [output] file in the job file");
  if (!job.young_modulus_pa)
    throw InputError("no Young's modulus given: use --young-modulus PA or [material] young_modulus_pa");
  if (!job.poisson_ratio)
    throw InputError("no Poisson ratio given: use --poisson-ratio NU or [material] poisson_ratio");
  require_output_directory(job.output);
  if (job.write_xdmf) check_xdmf_sidecar_name(job.output);
  if (job.attachment.empty())
    throw InputError("no attachment given: the organ must be held somewhere; use --fix-ids, "
                     "--fix-group, --fix-box, --fix-sphere, --fix-half-space or [attachment]");
  if (job.block_columns < 1 || job.block_columns > kMaxBlockColumns)
    throw InputError(fmt::format("block columns {} is not accepted: use 1 to {}", job.block_columns, kMaxBlockColumns));
  if (!(job.tolerance > 0)) throw InputError(fmt::format("tolerance {} is not accepted: use a number > 0", job.tolerance));
  if (!(job.memory_limit_bytes >= 0)) throw InputError("memory limit must be ≥ 0 (0: available memory)");
  parse_length_unit(job.mesh_unit);
}

// Times a phase and measures its peak resident memory.
class Phases {
 public:
  explicit Phases(json* out) : out_(out) {}
  void begin(const std::string& name) {
    name_ = name;
    // glibc keeps freed heap pages (Gmsh's model, assembly triplets) resident;
    // handing them back makes the process's memory what the phase holds, which
    // is what a batch scheduler's memory limit counts.
    malloc_trim(0);
    reset_peak_rss();
    start_rss_ = current_rss_bytes();
    t0_ = std::chrono::steady_clock::now();
  }
  json& end() {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    out_->push_back({{"name", name_}, {"seconds", s}, {"start_rss_bytes", start_rss_}, {"peak_rss_bytes", peak_rss_bytes()}});
    peak_ = std::max(peak_, peak_rss_bytes());
    return out_->back();
  }
  double peak() const { return peak_; }

 private:
  json* out_;
  std::string name_;
  double start_rss_ = 0;
  std::chrono::steady_clock::time_point t0_;
  double peak_ = 0;
};

json factor_json(const ComplianceStats& s) {
  const auto& f = s.factor;
  return {{"ordering", f.ordering},
          {"nnz_L", f.nnz_L},
          {"supernodes", f.supernodes},
          {"bytes", f.bytes},
          {"analyze_seconds", f.analyze_seconds},
          {"factor_seconds", f.factor_seconds},
          {"factor_gflops", f.flops / 1e9},
          {"factor_gflop_per_s", f.factor_seconds > 0 ? f.flops / f.factor_seconds / 1e9 : 0.0},
          {"dense_seconds", s.dense_seconds},
          {"dense_gflops", s.dense_flops / 1e9},
          {"dense_gflop_per_s", s.dense_seconds > 0 ? s.dense_flops / s.dense_seconds / 1e9 : 0.0},
          {"max_residual", s.max_residual},
          {"max_column_mismatch", s.max_column_mismatch},
          {"checked_columns", s.checked_columns}};
}

std::string input_hash(const TetMesh& mesh, const std::vector<MaterialRecord>& materials,
                       const Eigen::VectorXi& tet_material, const std::vector<int>& fixed) {
  Sha256 h;
  // The version in which this definition of the hash was fixed, not the
  // file's: minor versions add datasets but hash the same problem the same
  // way, so a 1.1 file and a 1.0 file of one problem share their hash.
  h.update(fmt::format("{} {}.0\n", kComplianceFormatName, kComplianceFormatMajor));
  const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> X = mesh.vertices;
  const Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor> T = mesh.tetrahedra;
  h.update(fmt::format("vertices {}\n", X.rows()));
  h.update(X.data(), sizeof(double) * static_cast<size_t>(X.size()));
  h.update(fmt::format("tetrahedra {}\n", T.rows()));
  h.update(T.data(), sizeof(int) * static_cast<size_t>(T.size()));
  h.update(tet_material.data(), sizeof(int) * static_cast<size_t>(tet_material.size()));
  for (const auto& m : materials) h.update(fmt::format("material {:.17g} {:.17g}\n", m.young_modulus_pa, m.poisson_ratio));
  h.update(fmt::format("fixed {}\n", fixed.size()));
  h.update(fixed.data(), sizeof(int) * fixed.size());
  return h.hex_digest();
}

// ---- batch precomputation: the streaming solves, shards, merge -----------------

// Largest relative residual or column mismatch accepted: larger means K is
// singular to working precision (a part held too loosely, a degenerate
// region), and G would be meaningless.
constexpr double kMaxResidual = 1e-6;

void refuse_bad_residual(double residual, double mismatch) {
  if (!(residual <= kMaxResidual) || !(mismatch <= kMaxResidual))
    throw NumericalError(fmt::format(
        "the solution does not satisfy K u = e: residual {:.3g}, column mismatch {:.3g} (accepted: "
        "≤ {:.0e}); K is numerically singular: check that the attachment holds every part of the "
        "organ and that no region is degenerate; no file written",
        residual, mismatch, kMaxResidual));
}

// Rows of G per band when writing the final file from shards, within
// @p budget bytes: a band in double and float, plus the sampled rows.
long band_rows_within(double budget, int m) {
  const double per_row = 12.0 * m;
  return static_cast<long>(std::clamp(std::floor(budget / per_row), 1.0, 256.0));
}

// Prints one line at the first block (the estimate), then at every tenth of
// the columns: done / total, columns per second, time left.
class SolveProgress {
 public:
  SolveProgress(std::function<void(const std::string&)> info, long done, long total, int threads)
      : info_(std::move(info)), resumed_(done), done_(done), total_(total), threads_(threads),
        t0_(std::chrono::steady_clock::now()) {}
  /// The clock starts when the factor is ready: the first block's time (and
  /// so the estimate, and the rate) is then the solves' alone.
  void start() { t0_ = std::chrono::steady_clock::now(); }
  void add(long columns, int block_columns, long pending_blocks) {
    done_ += columns;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    if (!info_) return;
    if (!first_reported_) {
      first_reported_ = true;
      // The threads solve their first blocks side by side.
      const double estimate = s * static_cast<double>(pending_blocks) / threads_;
      info_(fmt::format("first block of {} columns solved in {:.2f} s: about {:.0f} s for the {} "
                        "blocks left ({} thread{})",
                        block_columns, s, estimate, pending_blocks, threads_, threads_ > 1 ? "s" : ""));
    }
    const long tenth = 10 * done_ / std::max(1L, total_);
    if (tenth <= last_tenth_) return;
    last_tenth_ = tenth;
    const double rate = s > 0 ? static_cast<double>(done_ - resumed_) / s : 0;
    info_(fmt::format("solves: {}/{} columns ({:.0f} %), {:.0f} columns/s, about {:.0f} s left",
                      done_, total_, 100.0 * static_cast<double>(done_) / static_cast<double>(total_),
                      rate, rate > 0 ? static_cast<double>(total_ - done_) / rate : 0.0));
  }
  double rate() const {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    return s > 0 ? static_cast<double>(done_ - resumed_) / s : 0;
  }

 private:
  std::function<void(const std::string&)> info_;
  long resumed_, done_, total_;
  int threads_;
  std::chrono::steady_clock::time_point t0_;
  bool first_reported_ = false;
  long last_tenth_ = 0;
};

// The OpenBLAS kernels in a blas_description() ("… core SkylakeX]"): what,
// besides the inputs, decides G's last bits (the thread count does not: the
// solves method runs on single-threaded BLAS).
std::string blas_core(const std::string& description) {
  const auto at = description.rfind("core ");
  return at == std::string::npos ? description : description.substr(at);
}

// Shards sorted by their first column; refused unless they come from one
// problem, with one storage and block size, and cover [0, m) once.
void check_shards_tile(std::vector<std::unique_ptr<PartialFile>>& shards,
                       const std::function<void(const std::string&)>& warn) {
  if (shards.empty()) throw InputError("merge: no shard given");
  std::sort(shards.begin(), shards.end(), [](const auto& a, const auto& b) {
    return a->identity().columns_begin < b->identity().columns_begin;
  });
  const auto& ref = *shards.front();
  const ShardIdentity& r = ref.identity();
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    const auto names = fmt::format("{} and {}", ref.path().string(), s->path().string());
    if (i.input_hash != r.input_hash || i.columns_total != r.columns_total)
      throw InputError(fmt::format(
          "merge: {} come from different inputs (input hash {}… and {}…): merge only the shards "
          "of one job (same mesh, materials and attachment)",
          names, r.input_hash.substr(0, 19), i.input_hash.substr(0, 19)));
    if (i.precision != r.precision)
      throw InputError(fmt::format("merge: {} store G in {} and {}: compute every shard with the "
                                   "same --precision",
                                   names, to_string(r.precision), to_string(i.precision)));
    if (i.block_columns != r.block_columns)
      throw InputError(fmt::format("merge: {} were solved in blocks of {} and {} columns: compute "
                                   "every shard with the same --block-columns (the merged file "
                                   "must equal one run)",
                                   names, r.block_columns, i.block_columns));
    if (blas_core(s->blas()) != blas_core(ref.blas()))
      warn(fmt::format("merge: {} were computed with different BLAS kernels ({} and {}): G agrees "
                       "to round-off but its last bits may differ from a single run's (set "
                       "OPENBLAS_CORETYPE alike on every node)",
                       names, ref.blas(), s->blas()));
  }
  int expected = 0;
  const PartialFile* previous = nullptr;
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    if (i.columns_begin > expected)
      throw InputError(fmt::format(
          "merge: columns {}:{} of {} are in no shard (a gap {}): compute them with --columns "
          "{}:{}, or pass the shard that holds them",
          expected, i.columns_begin, r.columns_total,
          previous ? fmt::format("between {} and {}", previous->path().string(), s->path().string())
                   : fmt::format("before {}", s->path().string()),
          expected, i.columns_begin));
    if (i.columns_begin < expected)
      throw InputError(fmt::format(
          "merge: {} and {} both hold columns {}:{} (overlapping shards, e.g. from two different "
          "splits): pass each column once",
          previous->path().string(), s->path().string(), i.columns_begin,
          std::min(expected, i.columns_end)));
    expected = i.columns_end;
    previous = s.get();
  }
  if (expected < r.columns_total)
    throw InputError(fmt::format(
        "merge: columns {}:{} of {} are in no shard (a gap after {}): compute them with --columns "
        "{}:{}, or pass the shard that holds them",
        expected, r.columns_total, r.columns_total, previous->path().string(), expected,
        r.columns_total));
}

// The compliance file from complete shards that tile G: the diagonal blocks
// (definiteness, softness) from their float64 entries, the checks, then G
// in row bands, and the sidecar. Fills report's checks and output.
void write_from_shards(std::vector<std::unique_ptr<PartialFile>>& shards,
                       const std::filesystem::path& output, bool write_xdmf, double limit,
                       const PrecomputeHooks& hooks, json& report, Phases& phases) {
  auto phase = [&](const std::string& s) { if (hooks.phase) hooks.phase(s); };
  ComplianceModel model = shards.front()->model();
  const int m = shards.front()->identity().columns_total;

  // Diagonal blocks: entries (3k + i, c) for the 3 columns c of vertex k.
  Eigen::MatrixX3d diagonal(m, 3);
  double residual = 0, mismatch = 0;
  std::vector<int> checked;
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    diagonal.middleRows(i.columns_begin, i.columns_end - i.columns_begin) = s->diagonal_entries();
    for (const auto& c : s->checks()) {
      residual = std::max(residual, c.residual);
      mismatch = std::max(mismatch, c.mismatch);
      checked.push_back(c.column);
    }
  }
  const int n = m / 3;
  Eigen::MatrixXd blocks(3, m);  // [G^00 G^11 …], each block's column j = diagonal.row(3k + j)
  for (int c = 0; c < m; ++c) blocks.col(c) = diagonal.row(c).transpose();
  // diagonal_block_*() read blocks G(3k:3k+3, 3k:3k+3): give them a block-diagonal view.
  double lowest = INFINITY;
  int weakest = 0;
  Eigen::VectorXd softness(n);
  for (int k = 0; k < n; ++k) {
    const Eigen::Matrix3d B = blocks.middleCols<3>(3 * k);
    const Eigen::Matrix3d S = 0.5 * (B + B.transpose());
    const Eigen::Vector3d e =
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(S, Eigen::EigenvaluesOnly).eigenvalues();
    softness[k] = e[2];
    if (e[0] < lowest) lowest = e[0], weakest = k;
  }
  model.softness_m_per_n = Eigen::VectorXd::Zero(model.vertices_m.rows());
  for (int k = 0; k < n; ++k) model.softness_m_per_n[model.compliance_vertices[k]] = softness[k];
  const int weakest_vertex = model.source_vertex_ids[model.compliance_vertices[weakest]];
  refuse_bad_residual(residual, mismatch);
  if (!(lowest > 0))
    throw NumericalError(fmt::format("G has a diagonal block that is not positive definite (vertex {}, "
                                     "eigenvalue {:.3g} m/N); no file written",
                                     weakest_vertex, lowest));

  // Symmetry, sampled: for spread columns c, column c against row c, both
  // seen as the row bands go by (G itself is never whole in memory).
  std::vector<int> sampled = sample_columns(m, 32);
  std::vector<Eigen::VectorXd> column(sampled.size(), Eigen::VectorXd(m)), row(sampled.size());
  double largest = 0;
  std::sort(checked.begin(), checked.end());
  json checks = {{"max_residual", residual},
                 {"max_column_mismatch", mismatch},
                 {"min_diagonal_block_eigenvalue_m_per_n", lowest},
                 {"min_diagonal_block_vertex", weakest_vertex},
                 {"checked_columns", checked}};
  report["checks"] = checks;
  report["method"] = "solves";
  model.method = "solves";
  model.created_utc = report["created_utc"];
  model.producer = report["producer"];
  report["output"] = {{"file", output.string()},
                      {"precision", to_string(model.precision)},
                      {"xdmf", write_xdmf ? json(xdmf_sidecar_path(output).string()) : json(nullptr)}};
  // The symmetry error is only known once G is written: the stored report
  // says it was sampled, the returned one has the value.
  report["checks"]["symmetry_error_sampled_columns"] = sampled.size();
  model.report_json = report.dump();

  const double fixed_bytes = 8.0 * m * static_cast<double>(sampled.size()) + 48.0 * m;
  const long band = band_rows_within(limit - fixed_bytes, m);
  report["memory"]["merge_band_rows"] = band;

  phase("write file");
  phases.begin("write file");
  auto progress = hooks.progress ? hooks.progress("write file") : ProgressFn{};
  write_compliance_file(
      output, model,
      [&](long first, long count, double* rows) {
        for (const auto& s : shards) s->read_rows(first, count, rows);
        const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>
            band_rows(rows, count, m);
        if (!band_rows.allFinite())
          throw InputError(fmt::format("rows {}:{} of G in the shards hold a non-finite value "
                                       "(a damaged shard?)",
                                       first, first + count));
        largest = std::max(largest, band_rows.cwiseAbs().maxCoeff());
        for (size_t j = 0; j < sampled.size(); ++j) {
          column[j].segment(first, count) = band_rows.col(sampled[j]);
          if (sampled[j] >= first && sampled[j] < first + count)
            row[j] = band_rows.row(sampled[j] - first).transpose();
        }
      },
      band, progress);
  if (write_xdmf) write_xdmf_sidecar(output, model);
  phases.end();
  double asymmetry = 0;
  for (size_t j = 0; j < sampled.size(); ++j)
    asymmetry = std::max(asymmetry, (column[j] - row[j]).cwiseAbs().maxCoeff());
  report["checks"]["symmetry_error"] = largest > 0 ? asymmetry / largest : asymmetry;
  report["output"]["bytes"] = std::filesystem::file_size(output);
}

}  // namespace

json run_precompute(const PrecomputeJob& job, const PrecomputeHooks& hooks) {
  auto warn = [&](const std::string& s) { if (hooks.warn) hooks.warn(s); };
  auto phase = [&](const std::string& s) { if (hooks.phase) hooks.phase(s); };
  auto progress = [&](const std::string& label) { return hooks.progress ? hooks.progress(label) : ProgressFn{}; };
  auto info = [&](const std::string& s) { if (hooks.info) hooks.info(s); };

  validate_job(job);
  json report;
  report["producer"] = "palpate-precompute " PALPATE_VERSION;
  report["created_utc"] = utc_timestamp();
  report["blas"] = blas_description();
  report["method"] = to_string(job.method);
  report["phases"] = json::array();
  Phases phases(&report["phases"]);

  // Materials first: a bad modulus is reported before any long work.
  std::vector<MaterialRecord> materials{{"organ", *job.young_modulus_pa, *job.poisson_ratio}};
  std::vector<Lame> lame{lame_parameters(*job.young_modulus_pa, *job.poisson_ratio)};
  for (const auto& g : job.group_materials) {
    try {
      lame.push_back(lame_parameters(g.young_modulus_pa, g.poisson_ratio));
    } catch (const InputError& e) {
      throw InputError(fmt::format("material of group '{}': {}", g.group, e.what()));
    }
    materials.push_back({g.group, g.young_modulus_pa, g.poisson_ratio});
  }

  phase("read mesh");
  phases.begin("read mesh");
  MeshReadOptions read_options{parse_length_unit(job.mesh_unit), job.fill_size};
  TetMesh mesh = read_mesh(job.mesh_file, read_options);
  const MeshCheck check = validate_and_compact(mesh);
  if (!check.dropped_vertices.empty()) {
    std::string first;
    for (size_t i = 0; i < std::min<size_t>(5, check.dropped_vertices.size()); ++i)
      first += fmt::format("{}{}", i ? " " : "", check.dropped_vertices[i]);
    warn(fmt::format("{}: {} vertices belong to no tetrahedron and were dropped (first: {})",
                     mesh.source, check.dropped_vertices.size(), first));
  }
  const double diagonal = (check.bbox_max - check.bbox_min).norm();
  if (diagonal > 3.0)
    warn(fmt::format("{}: the organ is {:.3g} m across; if the file is in millimetres, use --mesh-unit mm",
                     mesh.source, diagonal));
  if (diagonal < 0.005)
    warn(fmt::format("{}: the organ is {:.3g} m across; check --mesh-unit", mesh.source, diagonal));
  const Boundary boundary = extract_boundary(mesh);
  phases.end();

  // Per-tetrahedron material: the organ's, or its physical group's.
  Eigen::VectorXi tet_material = Eigen::VectorXi::Zero(mesh.tetrahedra.rows());
  for (size_t g = 0; g < job.group_materials.size(); ++g) {
    const auto& name = job.group_materials[g].group;
    int tag = 0;
    for (const auto& [t, n] : mesh.group_names)
      if (n == name || fmt::format("#{}", t) == name) tag = t;
    if (tag == 0) {
      std::string known;
      for (const auto& [t, n] : mesh.group_names) known += (known.empty() ? "" : ", ") + n;
      throw InputError(fmt::format("{}: material group '{}' is not a physical volume of the mesh "
                                   "(its physical volumes: {})",
                                   mesh.source, name, known.empty() ? "none" : known));
    }
    for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t)
      if (mesh.tet_group[t] == tag) tet_material[t] = static_cast<int>(g + 1);
  }

  const std::vector<int> fixed = select_fixed_vertices(mesh, job.attachment);
  check_attachment_stops_rigid_motion(mesh, fixed);
  const DofMap dofs = make_dof_map(boundary.on_surface, fixed);
  const int m = dofs.surface_dofs();
  const int n = dofs.dofs();
  if (m == 0) throw InputError(fmt::format("{}: every surface vertex is fixed: nothing left to touch", mesh.source));

  const int n_surface = static_cast<int>(std::count(boundary.on_surface.begin(), boundary.on_surface.end(), true));
  report["mesh"] = {{"file", job.mesh_file.string()},
                    {"unit", job.mesh_unit},
                    {"vertices", mesh.vertices.rows()},
                    {"tetrahedra", mesh.tetrahedra.rows()},
                    {"dropped_vertices", check.dropped_vertices.size()},
                    {"surface_triangles", boundary.triangles.rows()},
                    {"surface_vertices", n_surface},
                    {"fixed_vertices", fixed.size()},
                    {"compliance_vertices", dofs.compliance_vertices.size()},
                    {"bbox_min_m", {check.bbox_min.x(), check.bbox_min.y(), check.bbox_min.z()}},
                    {"bbox_max_m", {check.bbox_max.x(), check.bbox_max.y(), check.bbox_max.z()}},
                    {"min_tet_volume_m3", check.min_volume_m3}};
  report["dofs"] = {{"total", n}, {"surface", m}};
  report["materials"] = json::array();
  for (const auto& mat : materials)
    report["materials"].push_back({{"name", mat.name}, {"young_modulus_pa", mat.young_modulus_pa}, {"poisson_ratio", mat.poisson_ratio}});

  // The file's content but G, known before any solve: the streaming
  // method's checkpoint holds it from the start.
  ComplianceModel model;
  model.vertices_m = mesh.vertices;
  model.tetrahedra = mesh.tetrahedra;
  model.tet_material = tet_material;
  model.materials = materials;
  model.surface_triangles = boundary.triangles;
  model.fixed_vertices = Eigen::Map<const Eigen::VectorXi>(fixed.data(), static_cast<Eigen::Index>(fixed.size()));
  model.source_vertex_ids = mesh.source_ids;
  model.compliance_vertices = Eigen::Map<const Eigen::VectorXi>(
      dofs.compliance_vertices.data(), static_cast<Eigen::Index>(dofs.compliance_vertices.size()));
  model.precision = job.precision;
  model.method = to_string(job.method);
  model.producer = report["producer"];
  model.created_utc = report["created_utc"];
  model.input_hash = input_hash(mesh, materials, tet_material, fixed);
  report["input_hash"] = model.input_hash;
  std::string summary;
  for (const auto& mat : materials)
    summary += fmt::format("{}{}: E = {:.6g} Pa, nu = {:.6g}", summary.empty() ? "" : "; ", mat.name,
                           mat.young_modulus_pa, mat.poisson_ratio);
  model.material_summary = summary;
  // The `solves` method streams G through a checkpoint: out of core and
  // resumable. Its columns: all, or the shard's whole blocks. Shards are
  // computed by solves (condensation needs the whole G).
  if (job.shard.any() && job.method == Method::kCondensation)
    throw InputError("--shard and --columns compute columns of G by solves: use --method solves "
                     "(condensation computes the whole G at once)");
  const bool streaming = job.method == Method::kSolves || job.shard.any();
  {
    PrecomputeJob stored = job;
    stored.shard = {};
    if (streaming) stored.method = Method::kSolves;
    model.method = to_string(stored.method);
    report["method"] = model.method;
    model.job_toml = to_toml(stored);
  }
  const int block_columns = job.block_columns;
  int first_column = 0, end_column = m;
  if (job.shard.count > 0) {
    const int blocks = (m + block_columns - 1) / block_columns;
    if (job.shard.count > blocks)
      throw InputError(fmt::format("shard {}/{}: G has {} columns, {} blocks of {}: at most {} "
                                   "shards; use fewer shards or a smaller --block-columns",
                                   job.shard.index, job.shard.count, m, blocks, block_columns, blocks));
    // As even as whole blocks go: shard k gets blocks [k·B/N, (k+1)·B/N).
    first_column = static_cast<int>(static_cast<long>(job.shard.index) * blocks / job.shard.count) * block_columns;
    end_column = std::min(m, static_cast<int>(static_cast<long>(job.shard.index + 1) * blocks / job.shard.count) * block_columns);
  } else if (job.shard.begin >= 0) {
    first_column = job.shard.begin;
    end_column = job.shard.end;
    if (end_column > m || first_column % block_columns != 0 ||
        (end_column % block_columns != 0 && end_column != m))
      throw InputError(fmt::format(
          "columns {}:{}: G has {} columns (0:{}) solved in blocks of {}: a shard starts at a "
          "multiple of {} and ends at one or at {}, so that every column is solved as in a "
          "single run",
          first_column, end_column, m, m, block_columns, block_columns, m));
  }

  // Memory: refuse before the long work, with the numbers.
  const int elt = job.precision == Precision::kFloat32 ? 4 : 8;
  const double g_bytes = 8.0 * m * static_cast<double>(m);
  const double limit = job.memory_limit_bytes > 0 ? job.memory_limit_bytes : available_memory_bytes();
  const std::string limit_name =
      job.memory_limit_bytes > 0 ? "is the memory limit set" : "is available on this machine";
  auto refuse_if_too_big = [&](double need, const std::string& detail) {
    if (need > limit)
      throw ResourceError(fmt::format(
          "the job needs about {} ({}) but {} {}: use a coarser mesh (fewer surface vertices), "
          "or a machine with more memory",
          format_bytes(need), detail, format_bytes(limit), limit_name));
  };
  if (!streaming)
    refuse_if_too_big(g_bytes, fmt::format("G alone is {} × {} doubles; --method solves computes it "
                                           "out of core, within the limit",
                                           m, m));

  phase("assemble K");
  phases.begin("assemble K");
  const SparseMatrixd K = assemble_stiffness(mesh.vertices, mesh.tetrahedra, tet_material, lame, dofs);
  phases.end()["nnz_upper"] = K.nonZeros();

  // Runs a method, turning a failed Cholesky into a message about the mesh.
  auto with_vertex_context = [&](auto method) {
    try {
      method();
    } catch (const NotPositiveDefinite& e) {
      const int v = dofs.vertex_of_dof(e.column());
      throw NumericalError(fmt::format(
          "{}: the stiffness matrix is not positive definite (Cholesky failed at vertex {}, axis {}): "
          "check that the attachment holds every part of the organ and that no element is degenerate",
          mesh.source, mesh.source_ids[v], "xyz"[e.column() % 3]));
    }
  };
  const double k_bytes = 12.0 * static_cast<double>(K.nonZeros());

  if (streaming) {
    const ShardIdentity id{model.input_hash, first_column, end_column, m, block_columns, job.precision};
    const bool sharded = first_column != 0 || end_column != m || job.shard.any();
    const auto target = sharded ? shard_output_path(job.output, first_column, end_column) : job.output;
    const auto checkpoint = checkpoint_path(target);
    const int width = end_column - first_column;

    // G is never in memory. What is: K; the factor, and CHOLMOD's permuted
    // copies of K while it factors (freed, but glibc keeps them in the heap);
    // per solve thread four n × B arrays (unit columns, solution, CHOLMOD's X
    // and Y) and its m × B block on the way to the file; one more block being
    // converted; the checks. Against the solves phase's peak resident memory
    // less its start (docs/precompute.md): 280 MB for 310 estimated on one
    // thread, 374 for 407 on two (110k-tet liver, B = 64); 2.90 GB for 3.06 on
    // two (505k tets). Writing the final file needs a band of rows, which fits
    // any limit these do.
    const int threads = std::min(solve_threads(), id.blocks());
    const int block = std::min(block_columns, m);
    const double factor_bytes = SparseCholesky::estimate_factor_bytes(K);
    const double need = 3 * k_bytes + factor_bytes + threads * (32.0 * n * block + 16.0 * m * block) +
                        16.0 * m * block + 8.0 * m * 40 + 48.0 * m;
    const double file_bytes = static_cast<double>(elt) * m * width;
    report["memory"] = {{"G_bytes", g_bytes},
                        {"estimate_bytes", need},
                        {"limit_bytes", limit},
                        {"streamed", true},
                        {"G_file_bytes", file_bytes}};
    if (need > limit)
      throw ResourceError(fmt::format(
          "even one block of {} columns per thread ({} threads) and the sparse factor ({}) need "
          "about {} but {} {}: use a smaller --block-columns, or a machine with more memory",
          block, threads, format_bytes(factor_bytes), format_bytes(need), format_bytes(limit), limit_name));
    info(fmt::format("{}: columns {}:{} of {} in {} blocks of {}; G {} on disk ({}), at most about "
                     "{} in memory (limit {})",
                     sharded ? "shard" : "solves", first_column, end_column, m, id.blocks(), block_columns,
                     format_bytes(file_bytes), to_string(job.precision), format_bytes(need),
                     format_bytes(limit)));

    // Resume the checkpoint of an earlier run of the same columns, if any.
    std::unique_ptr<PartialFile> partial;
    std::error_code ec;
    if (std::filesystem::exists(checkpoint, ec)) {
      std::string why;
      partial = PartialFile::open_to_resume(checkpoint, id, &why);
      if (partial) {
        info(fmt::format("resuming {}: {} of {} blocks already complete", checkpoint.string(),
                         id.blocks() - static_cast<int>(partial->pending_blocks().size()), id.blocks()));
      } else {
        warn(fmt::format("discarded {}, left by an earlier run: {}; starting from the first block",
                         checkpoint.string(), why));
        std::filesystem::remove(checkpoint, ec);
      }
    }
    const auto checks_wanted = [&] {
      // The checks a single run makes that fall here, plus this range's ends.
      std::set<int> c{first_column, end_column - 1};
      for (const int j : sample_columns(m, ComplianceOptions{}.check_columns))
        if (j >= first_column && j < end_column) c.insert(j);
      return std::vector<int>(c.begin(), c.end());
    }();
    if (!partial) partial = PartialFile::create(checkpoint, model, id, checks_wanted, report["blas"]);
    const std::vector<int> pending = partial->pending_blocks();
    report["columns"] = {{"begin", first_column}, {"end", end_column}, {"total", m},
                         {"block_columns", block_columns}, {"blocks", id.blocks()},
                         {"resumed_blocks", id.blocks() - static_cast<int>(pending.size())}};

    phase("solves");
    phases.begin("solves");
    ComplianceStats stats;
    if (!pending.empty()) {
      long done = 0;
      for (int b = id.first_block(); b < id.first_block() + id.blocks(); ++b)
        if (!std::binary_search(pending.begin(), pending.end(), b))
          done += std::min(block_columns, m - b * block_columns);
      SolveProgress lines(hooks.info, done, width, std::min<int>(threads, static_cast<int>(pending.size())));
      auto bar = progress(fmt::format("{} solves", width));
      long left = static_cast<long>(pending.size());
      with_vertex_context([&] {
        solve_compliance_blocks(
            K, m, block_columns, pending, checks_wanted,
            [&](const SolvedBlock& b) {
              partial->write_block(b);
              done += b.columns.cols();
              lines.add(b.columns.cols(), block_columns, --left);
              if (bar) bar(done, width);
            },
            &stats,
            [&](const FactorInfo& f) {
              lines.start();
              info(fmt::format("factor: {} ordering, nnz(L) = {:.3g}, {:.2f} s; {} columns left to "
                               "solve, {:.3g} GFLOP",
                               f.ordering, f.nnz_L, f.factor_seconds, width - done,
                               4.0 * f.nnz_L * static_cast<double>(width - done) / 1e9));
            });
      });
      report["columns"]["columns_per_second"] = lines.rate();
    }
    auto& p = phases.end();
    p["gflop_per_s"] = stats.dense_seconds > 0 ? stats.dense_flops / stats.dense_seconds / 1e9 : 0.0;
    // The checks of every block, this run's and the resumed ones.
    double residual = 0, mismatch = 0;
    std::vector<int> checked;
    for (const auto& c : partial->checks()) {
      residual = std::max(residual, c.residual);
      mismatch = std::max(mismatch, c.mismatch);
      checked.push_back(c.column);
    }
    stats.max_residual = residual;
    stats.max_column_mismatch = mismatch;
    stats.checked_columns = checked;
    report["methods"] = {{"solves", factor_json(stats)}};
    report["checks"] = {{"max_residual", residual}, {"max_column_mismatch", mismatch}};
    try {
      refuse_bad_residual(residual, mismatch);
    } catch (const NumericalError&) {
      partial.reset();
      std::filesystem::remove(checkpoint, ec);  // the same inputs would give the same
      throw;
    }

    if (sharded) {
      report["output"] = {{"file", target.string()}, {"precision", to_string(job.precision)}, {"xdmf", nullptr}};
      partial->finish(report.dump());
      partial->close();
      durable_rename(checkpoint, target);
      report["output"]["bytes"] = std::filesystem::file_size(target);
      report["peak_rss_bytes"] = phases.peak();
      return report;
    }
    partial->finish(report.dump());
    partial->close();
    partial.reset();
    std::vector<std::unique_ptr<PartialFile>> whole;
    whole.push_back(PartialFile::open_complete(checkpoint));
    write_from_shards(whole, job.output, job.write_xdmf, limit - k_bytes, hooks, report, phases);
    whole.clear();
    std::filesystem::remove(checkpoint, ec);
    if (!job.write_xdmf && std::filesystem::exists(xdmf_sidecar_path(job.output), ec))
      warn(fmt::format("{} is left from an earlier run and may not match the new {}: delete it, "
                       "or run without --no-xdmf to rewrite it",
                       xdmf_sidecar_path(job.output).string(), job.output.string()));
    report["peak_rss_bytes"] = phases.peak();
    return report;
  }

  const bool do_solves = job.method != Method::kCondensation;
  const bool do_condensation = job.method != Method::kSolves;
  {
    // G, plus each method's factor and work arrays (they run one at a time):
    // per solve thread four n × B arrays and its m × B block, as streamed.
    double need = 0;
    if (do_solves)
      need = std::max(need, g_bytes + SparseCholesky::estimate_factor_bytes(K) +
                                (32.0 * n + 8.0 * m) * std::min(job.block_columns, m) * solve_threads());
    if (do_condensation)
      need = std::max(need, g_bytes + SparseCholesky::estimate_factor_bytes(K, condensation_ordering(K, m)));
    need += k_bytes;
    report["memory"] = {{"G_bytes", g_bytes}, {"estimate_bytes", need}, {"limit_bytes", limit}};
    refuse_if_too_big(need, fmt::format("G is {}; the rest is the sparse factor; --method solves "
                                        "computes G out of core, within the limit",
                                        format_bytes(g_bytes)));
  }

  ComplianceOptions options;
  options.block_columns = job.block_columns;
  Eigen::MatrixXd G;
  json methods;
  if (do_condensation) {
    phase("condensation");
    phases.begin("condensation");
    options.progress = progress("condensation");
    ComplianceStats stats;
    with_vertex_context([&] { G = compliance_by_condensation(K, m, options, &stats); });
    auto& p = phases.end();
    p["gflop_per_s"] = stats.dense_seconds > 0 ? stats.dense_flops / stats.dense_seconds / 1e9 : 0.0;
    methods["condensation"] = factor_json(stats);
  }
  double max_difference = -1;
  if (do_solves) {
    phase("solves");
    phases.begin("solves");
    options.progress = progress(fmt::format("{} solves", m));
    ComplianceStats stats;
    if (do_condensation) {
      // Compare block by block with the condensation result, then overwrite it.
      const double scale = G.cwiseAbs().maxCoeff();
      double worst = 0;
      options.on_block = [&](int first, CRef<Eigen::MatrixXd> block) {
        worst = std::max(worst, (block - G.middleCols(first, block.cols())).cwiseAbs().maxCoeff());
      };
      with_vertex_context([&] { compliance_by_solves(K, m, options, G, &stats); });
      max_difference = worst / scale;
    } else {
      with_vertex_context([&] { G = compliance_by_solves(K, m, options, &stats); });
    }
    auto& p = phases.end();
    p["gflop_per_s"] = stats.dense_seconds > 0 ? stats.dense_flops / stats.dense_seconds / 1e9 : 0.0;
    methods["solves"] = factor_json(stats);
  }
  report["methods"] = methods;

  phase("checks");
  phases.begin("checks");
  json checks;
  double residual = 0, mismatch = 0;
  for (const auto& [name, s] : methods.items()) {
    residual = std::max(residual, s["max_residual"].get<double>());
    mismatch = std::max(mismatch, s["max_column_mismatch"].get<double>());
  }
  int weakest = 0;
  const double min_eig = min_diagonal_block_eigenvalue(G, &weakest);
  // The softness map, from the float64 G (before any float32 storage rounding).
  const Eigen::VectorXd block_softness = diagonal_block_largest_eigenvalues(G);
  checks["max_residual"] = residual;
  checks["max_column_mismatch"] = mismatch;
  checks["symmetry_error"] = symmetry_error(G);
  checks["min_diagonal_block_eigenvalue_m_per_n"] = min_eig;
  checks["min_diagonal_block_vertex"] = mesh.source_ids[dofs.compliance_vertices[weakest]];
  if (max_difference >= 0) {
    checks["max_relative_difference"] = max_difference;
    checks["tolerance"] = job.tolerance;
  }
  report["checks"] = checks;
  phases.end();
  if (max_difference > job.tolerance || !(max_difference == max_difference))
    throw NumericalError(fmt::format(
        "the two methods disagree: largest relative difference {:.3g} > tolerance {:.3g}; "
        "no file written (the stiffness may be too ill-conditioned: check ν < 0.5 and the mesh quality)",
        max_difference, job.tolerance));
  refuse_bad_residual(residual, mismatch);
  if (!(min_eig > 0))
    throw NumericalError(fmt::format("G has a diagonal block that is not positive definite (vertex {}, "
                                     "eigenvalue {:.3g} m/N); no file written",
                                     mesh.source_ids[dofs.compliance_vertices[weakest]], min_eig));

  model.softness_m_per_n = Eigen::VectorXd::Zero(mesh.vertices.rows());
  for (Eigen::Index a = 0; a < model.compliance_vertices.size(); ++a)
    model.softness_m_per_n[model.compliance_vertices[a]] = block_softness[a];
  const auto sidecar = xdmf_sidecar_path(job.output);
  report["output"] = {{"file", job.output.string()},
                      {"precision", to_string(job.precision)},
                      {"xdmf", job.write_xdmf ? json(sidecar.string()) : json(nullptr)}};
  model.report_json = report.dump();

  phase("write file");
  phases.begin("write file");
  write_compliance_file(job.output, model, G, progress("write file"));
  // The sidecar refers to the file's datasets: only once the file is in place.
  if (job.write_xdmf) write_xdmf_sidecar(job.output, model);
  phases.end();
  std::error_code ec;
  if (!job.write_xdmf && std::filesystem::exists(sidecar, ec))
    warn(fmt::format("{} is left from an earlier run and may not match the new {}: delete it, "
                     "or run without --no-xdmf to rewrite it",
                     sidecar.string(), job.output.string()));
  report["output"]["bytes"] = std::filesystem::file_size(job.output);
  report["peak_rss_bytes"] = phases.peak();
  return report;
}


json merge_shards(const MergeJob& job, const PrecomputeHooks& hooks) {
  auto warn = [&](const std::string& s) { if (hooks.warn) hooks.warn(s); };
  auto phase = [&](const std::string& s) { if (hooks.phase) hooks.phase(s); };
  if (job.output.empty()) throw InputError("merge: no output file given: use -o FILE.h5");
  if (job.shards.empty())
    throw InputError("merge: no shard given: list the shard files (e.g. liver.part-*.h5)");
  require_output_directory(job.output);
  if (job.write_xdmf) check_xdmf_sidecar_name(job.output);
  if (!(job.memory_limit_bytes >= 0)) throw InputError("memory limit must be ≥ 0 (0: available memory)");

  json phase_list = json::array();
  Phases phases(&phase_list);
  phase("check shards");
  phases.begin("check shards");
  std::vector<std::unique_ptr<PartialFile>> shards;
  for (const auto& path : job.shards) shards.push_back(PartialFile::open_complete(path));
  check_shards_tile(shards, warn);
  phases.end();

  // The first shard's report describes the problem (mesh, materials, factor).
  json report;
  try {
    report = json::parse(shards.front()->report_json());
  } catch (const json::exception&) {
    report = json::object();
  }
  report["producer"] = "palpate-precompute " PALPATE_VERSION;
  report["created_utc"] = utc_timestamp();
  report.erase("columns");
  report.erase("peak_rss_bytes");
  json list = json::array();
  for (const auto& s : shards) {
    const ShardIdentity& i = s->identity();
    json entry = {{"file", s->path().string()}, {"columns", {i.columns_begin, i.columns_end}}, {"blas", s->blas()}};
    try {
      const json r = json::parse(s->report_json());
      if (r.contains("columns") && r["columns"].contains("columns_per_second"))
        entry["columns_per_second"] = r["columns"]["columns_per_second"];
      if (r.contains("peak_rss_bytes")) entry["peak_rss_bytes"] = r["peak_rss_bytes"];
    } catch (const json::exception&) {
    }
    list.push_back(entry);
  }
  report["shards"] = list;
  report["phases"] = phase_list;
  Phases more(&report["phases"]);
  const double limit = job.memory_limit_bytes > 0 ? job.memory_limit_bytes : available_memory_bytes();
  if (!report.contains("memory") || !report["memory"].is_object()) report["memory"] = json::object();
  report["memory"]["limit_bytes"] = limit;
  write_from_shards(shards, job.output, job.write_xdmf, limit, hooks, report, more);
  report["peak_rss_bytes"] = std::max(phases.peak(), more.peak());
  return report;
}

std::string format_report(const json& r) {
  std::string s;
  const auto& mesh = r["mesh"];
  s += fmt::format("palpate-precompute report ({})\n", r["producer"].get<std::string>());
  if (!r.contains("mesh")) return s;
  s += fmt::format("  mesh       {}: {} vertices, {} tetrahedra, {} surface triangles\n",
                   mesh["file"].get<std::string>(), mesh["vertices"].get<long>(),
                   mesh["tetrahedra"].get<long>(), mesh["surface_triangles"].get<long>());
  s += fmt::format("             {} surface vertices, {} fixed, {} in the compliance; {} DOFs\n",
                   mesh["surface_vertices"].get<long>(), mesh["fixed_vertices"].get<long>(),
                   mesh["compliance_vertices"].get<long>(), r["dofs"]["total"].get<long>());
  for (const auto& mat : r["materials"])
    s += fmt::format("  material   {}: E = {:.4g} Pa, nu = {}\n", mat["name"].get<std::string>(),
                     mat["young_modulus_pa"].get<double>(), mat["poisson_ratio"].get<double>());
  s += fmt::format("  BLAS       {}\n", r["blas"].get<std::string>());
  s += "  phases     time        peak RSS    rate\n";
  for (const auto& p : r["phases"]) {
    s += fmt::format("    {:<14} {:>8.3f} s  {:>10}", p["name"].get<std::string>(),
                     p["seconds"].get<double>(), format_bytes(p["peak_rss_bytes"].get<double>()));
    if (p.contains("gflop_per_s")) s += fmt::format("  {:.1f} GFLOP/s (dense part)", p["gflop_per_s"].get<double>());
    s += "\n";
  }
  for (const auto& [name, m] : r["methods"].items())
    s += fmt::format("  {:<12} factor: {} ordering, nnz(L) = {:.3g}, {:.2f} s ({:.1f} GFLOP/s); dense: {:.2f} s ({:.1f} GFLOP/s)\n",
                     name, m["ordering"].get<std::string>(), m["nnz_L"].get<double>(),
                     m["factor_seconds"].get<double>(), m["factor_gflop_per_s"].get<double>(),
                     m["dense_seconds"].get<double>(), m["dense_gflop_per_s"].get<double>());
  const auto& c = r["checks"];
  s += fmt::format("  checks     residual ‖Ku−e‖/‖e‖ ≤ {:.2e} on sampled columns; column mismatch ≤ {:.2e}\n",
                   c["max_residual"].get<double>(), c["max_column_mismatch"].get<double>());
  // A shard has no whole diagonal block, nor G to compare with its transpose.
  if (c.contains("symmetry_error"))
    s += fmt::format("             symmetry error {:.2e}{}; smallest eigenvalue of a diagonal block {:.4g} m/N\n",
                     c["symmetry_error"].get<double>(),
                     c.contains("symmetry_error_sampled_columns")
                         ? fmt::format(" ({} sampled columns)", c["symmetry_error_sampled_columns"].get<int>())
                         : std::string(),
                     c["min_diagonal_block_eigenvalue_m_per_n"].get<double>());
  if (r.contains("columns")) {
    const auto& k = r["columns"];
    s += fmt::format("  columns    {}:{} of {}, {} blocks of {} ({} resumed from the checkpoint){}\n",
                     k["begin"].get<int>(), k["end"].get<int>(), k["total"].get<int>(),
                     k["blocks"].get<int>(), k["block_columns"].get<int>(), k["resumed_blocks"].get<int>(),
                     k.contains("columns_per_second")
                         ? fmt::format(", {:.0f} columns/s", k["columns_per_second"].get<double>())
                         : std::string());
  }
  if (r.contains("shards"))
    for (const auto& sh : r["shards"])
      s += fmt::format("  shard      {}: columns {}:{}\n", sh["file"].get<std::string>(),
                       sh["columns"][0].get<int>(), sh["columns"][1].get<int>());
  if (c.contains("max_relative_difference"))
    s += fmt::format("             solves vs condensation: largest relative difference {:.2e} (tolerance {:.0e})\n",
                     c["max_relative_difference"].get<double>(), c["tolerance"].get<double>());
  if (r.contains("output"))
    s += fmt::format("  output     {} ({}, {}), input hash {}\n", r["output"]["file"].get<std::string>(),
                     r["output"]["precision"].get<std::string>(),
                     format_bytes(r["output"].value("bytes", 0.0)), r["input_hash"].get<std::string>().substr(0, 23));
  if (r.contains("peak_rss_bytes"))
    s += fmt::format("  peak RSS   {} (G is {})\n", format_bytes(r["peak_rss_bytes"].get<double>()),
                     format_bytes(r["memory"]["G_bytes"].get<double>()));
  return s;
}

}  // namespace palpate
