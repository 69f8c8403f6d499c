#pragma once
/// @file
/// A precompute job run end to end, from its description (precompute_job.hpp)
/// to a verified compliance file and its report (precompute_report.hpp);
/// and shards merged into one file.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "palpate/offline/compliance.hpp"
#include "palpate/offline/precompute_job.hpp"
#include "palpate/offline/precompute_report.hpp"

namespace palpate {

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
PrecomputeReport run_precompute(const PrecomputeJob& job, const PrecomputeHooks& hooks);

/// The shard file of columns [begin, end) for @p output: "<stem>.part-<begin>-<end><ext>"
/// beside it ("liver.part-0-1024.h5" for "liver.h5").
std::filesystem::path shard_output_path(const std::filesystem::path& output, int begin, int end);

/// Assembles complete shards of one problem into the compliance file
/// @p job.output, identical (G, every dataset, content_sha256) to a single
/// run: checks that they come from the same inputs (input hash, size,
/// precision, block size) and tile [0, m) exactly, then the diagonal blocks
/// (definiteness, softness), then writes the file atomically in row bands
/// within the memory limit, and its sidecar. Returns the report.
/// @throws InputError naming the shards at fault (different inputs,
///   overlapping or missing columns, incomplete), NumericalError,
///   ResourceError, SystemError.
PrecomputeReport merge_shards(const MergeJob& job, const PrecomputeHooks& hooks);

}  // namespace palpate
