#pragma once
/// @file
/// A precompute job: everything that determines a compliance file, from a
/// TOML job file and/or the command line (docs/configuration.md, "Job
/// files"), and what `palpate-precompute merge` is told.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/attachment.hpp"
#include "palpate/offline/cut_region.hpp"

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

/// Density of soft tissue, kg/m³: liver, muscle and kidney are about 1,040
/// to 1,070 (ICRU Report 46's reference tissues); the default of the cut
/// region's lumped masses.
inline constexpr double kSoftTissueDensityKgM3 = 1060;
/// Default γ of the cut region's mass-proportional damping (force −γ m v),
/// 1/s: a velocity decays in 1/γ = 50 ms, about the time a hand takes to
/// feel a tissue settle, so the region neither rings after a cut nor feels
/// sluggish; γ Δt = 0.02 at a 1 kHz step, far from limiting an explicit
/// step's stability. A starting point for the run-time model to tune.
inline constexpr double kDefaultRegionDampingPerS = 20;

/// The cuttable region of the hybrid model (the job's [cut_region] table,
/// docs/configuration.md): where it is, and what its run-time tensor-mass
/// model needs beyond the elastic material.
struct CutRegionJob {
  RegionSpec spec;  ///< metres (the job file gives millimetres)
  double density_kg_m3 = kSoftTissueDensityKgM3;
  double damping_per_s = kDefaultRegionDampingPerS;
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
  double tolerance = 1e-8;        ///< `both`: largest accepted relative difference
  double memory_limit_bytes = 0;  ///< 0: the machine's available memory
  std::filesystem::path output;
  /// Also write the XDMF sidecar next to the output (xdmf.hpp), for ParaView.
  bool write_xdmf = true;
  /// Keep an output that already holds this problem (the same input hash,
  /// the same precision, its content digest intact) instead of computing it
  /// again (command line only: --reuse).
  bool reuse = false;
  /// Only some columns, into a shard file (command line only: not in the TOML).
  ColumnShard shard;
  /// A cuttable region: G is then the compliance of the rest of the organ
  /// on its boundary, and the file holds the region (docs/precompute.md, "A
  /// cuttable region").
  std::optional<CutRegionJob> cut_region;
};

/// Reads a TOML job file (docs/configuration.md). Relative paths are taken
/// from the job file's directory.
/// @throws InputError naming the file, the key and what is accepted.
PrecomputeJob read_job_file(const std::filesystem::path& file);

/// The job as TOML, with absolute paths: what was run, enough to run it again.
std::string to_toml(const PrecomputeJob& job);

/// What `merge` is told.
struct MergeJob {
  std::vector<std::filesystem::path> shards;
  std::filesystem::path output;
  bool write_xdmf = true;
  double memory_limit_bytes = 0;  ///< 0: the machine's available memory
};

/// Checks what a job needs before any work: mesh, output, material and
/// attachment given, the output directory exists, block size, tolerance,
/// memory limit and unit accepted, a cut region only with an in-memory
/// method (condensation or both) and no shard.
/// @throws InputError saying what is missing or wrong and how to give it.
void validate_job(const PrecomputeJob& job);

}  // namespace palpate
