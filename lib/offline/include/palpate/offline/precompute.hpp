#pragma once
/// @file
/// A precompute job, from its description (TOML job file and/or command-line
/// values) to a verified compliance file and its report.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "palpate/offline/attachment.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/mesh_io.hpp"

namespace palpate {

enum class Method { kSolves, kCondensation, kBoth };
/// "solves", "condensation", "both". @throws InputError otherwise.
Method parse_method(const std::string& name);
std::string to_string(Method method);
/// "float64", "float32". @throws InputError otherwise.
Precision parse_precision(const std::string& name);
std::string to_string(Precision precision);

/// Material of a Gmsh physical volume that differs from the organ's.
struct GroupMaterial {
  std::string group;  ///< physical name, or "#tag"
  double young_modulus_pa = 0;
  double poisson_ratio = 0;
};

/// Which columns of G a run computes (docs/precompute.md, "Batch
/// precomputation"): all of them (the default), shard `index` of `count`
/// (0-based; whole blocks of columns, as even as they go), or the explicit
/// columns [begin, end), begin a multiple of the block size and end one too
/// or the last column. A run of some columns writes a shard file,
/// shard_output_path(), for `palpate-precompute merge`.
struct ColumnShard {
  int index = 0, count = 0;  ///< --shard INDEX/COUNT, when count > 0
  int begin = -1, end = -1;  ///< --columns BEGIN:END, when begin ≥ 0
  bool any() const { return count > 0 || begin >= 0; }
};

/// "K/N" or "BEGIN:END" into @p shard. @throws InputError naming the text.
void parse_shard(const std::string& text, ColumnShard* shard);

/// Everything that determines a compliance file. Lengths of attachment
/// regions are stored in metres; the job file gives them in the mesh's unit.
struct PrecomputeJob {
  std::filesystem::path mesh_file;
  std::string mesh_unit = "m";
  double fill_size = 0;  ///< STL input: target tetrahedron size, mesh unit (0: automatic)
  std::optional<double> young_modulus_pa;  ///< Pa; required
  std::optional<double> poisson_ratio;     ///< required
  std::vector<GroupMaterial> group_materials;
  AttachmentSpec attachment;
  Method method = Method::kBoth;
  Precision precision = Precision::kFloat64;
  int block_columns = 64;
  double tolerance = 1e-8;         ///< `both`: largest accepted relative difference
  double memory_limit_bytes = 0;   ///< 0: the machine's available memory
  std::filesystem::path output;
  /// Also write the XDMF sidecar next to the output (xdmf.hpp), for ParaView.
  bool write_xdmf = true;
  /// Only some columns, into a shard file (command line only: not in the TOML).
  ColumnShard shard;
};

/// Reads a TOML job file (docs/configuration.md). Relative paths are taken
/// from the job file's directory.
/// @throws InputError naming the file, the key and what is accepted.
PrecomputeJob read_job_file(const std::filesystem::path& file);

/// The job as TOML, with absolute paths: what was run, enough to run it again.
std::string to_toml(const PrecomputeJob& job);

/// What the pipeline tells its caller while it runs.
struct PrecomputeHooks {
  std::function<void(const std::string&)> warn;   ///< a warning, one line
  std::function<void(const std::string&)> phase;  ///< a phase starts
  /// A progress function for a long phase, or an empty one.
  std::function<ProgressFn(const std::string& label)> progress;
  /// An informative line for logs: estimates, progress of a batch run.
  std::function<void(const std::string&)> info;
};

/// Runs the job end to end: read and check the mesh, select the attachment,
/// assemble K, compute G_SS by the chosen method(s), check, write the file
/// atomically, then its XDMF sidecar (unless !job.write_xdmf). Returns the
/// report (docs/compliance-file.md, "report").
///
/// The `solves` method streams: G is written block by block into a
/// checkpoint beside the output (checkpoint_path(), partial_file.hpp), never
/// held in memory, and a killed run resumes from its last complete block.
/// With job.shard, only those columns, into shard_output_path().
/// @throws InputError, NumericalError (including methods that disagree beyond
///   the tolerance: then no file is written), ResourceError, SystemError.
nlohmann::json run_precompute(const PrecomputeJob& job, const PrecomputeHooks& hooks);

/// The shard file of columns [begin, end) for @p output: "<stem>.part-<begin>-<end><ext>"
/// beside it ("liver.part-0-1024.h5" for "liver.h5").
std::filesystem::path shard_output_path(const std::filesystem::path& output, int begin, int end);

/// What `merge` is told.
struct MergeJob {
  std::vector<std::filesystem::path> shards;
  std::filesystem::path output;
  bool write_xdmf = true;
  double memory_limit_bytes = 0;  ///< 0: the machine's available memory
};

/// Assembles complete shards of one problem into the compliance file
/// @p job.output, identical (G, every dataset, content_sha256) to a single
/// run: checks that they come from the same inputs (input hash, size,
/// precision, block size) and tile [0, m) exactly, then the diagonal blocks
/// (definiteness, softness), then writes the file atomically in row bands
/// within the memory limit, and its sidecar. Returns the report.
/// @throws InputError naming the shards at fault (different inputs,
///   overlapping or missing columns, incomplete), NumericalError,
///   ResourceError, SystemError.
nlohmann::json merge_shards(const MergeJob& job, const PrecomputeHooks& hooks);

/// The report as text for a terminal.
std::string format_report(const nlohmann::json& report);

}  // namespace palpate
