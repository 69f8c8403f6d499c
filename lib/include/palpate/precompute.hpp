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

#include "palpate/attachment.hpp"
#include "palpate/compliance.hpp"
#include "palpate/compliance_file.hpp"
#include "palpate/mesh_io.hpp"

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
};

/// Runs the job end to end: read and check the mesh, select the attachment,
/// assemble K, compute G_SS by the chosen method(s), check, write the file
/// atomically, then its XDMF sidecar (unless !job.write_xdmf). Returns the
/// report (docs/compliance-file.md, "report").
/// @throws InputError, NumericalError (including methods that disagree beyond
///   the tolerance: then no file is written), ResourceError, SystemError.
nlohmann::json run_precompute(const PrecomputeJob& job, const PrecomputeHooks& hooks);

/// The report as text for a terminal.
std::string format_report(const nlohmann::json& report);

}  // namespace palpate
