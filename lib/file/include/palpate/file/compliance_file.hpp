#pragma once
/// @file
/// The compliance file: one self-describing HDF5 file per organ, written by
/// palpate-precompute and read by palpated. The layout is the contract
/// documented in docs/compliance-file.md; change both together.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/file/cut_region_data.hpp"

namespace palpate {

inline constexpr const char* kComplianceFormatName = "palpate-compliance";
inline constexpr int kComplianceFormatMajor = 1;
inline constexpr int kComplianceFormatMinor = 3;
/// The `format` of a shard (partial file): some columns of G and the
/// checkpoint of the run computing them (partial_file.hpp).
inline constexpr const char* kPartialFormatName = "palpate-compliance-partial";

/// One material region (a Gmsh physical volume, or the default).
struct MaterialRecord {
  std::string name;
  double young_modulus_pa = 0;
  double poisson_ratio = 0;
};

/// Storage type of /compliance/G.
enum class Precision { kFloat64, kFloat32 };

/// Everything in a compliance file except G itself.
struct ComplianceModel {
  Eigen::MatrixX3d vertices_m;   ///< #V × 3, metres (/mesh/vertices)
  Eigen::MatrixX4i tetrahedra;   ///< #T × 4, 0-based (/mesh/tetrahedra)
  Eigen::VectorXi tet_material;  ///< #T index into materials (/mesh/tetrahedron_material)
  std::vector<MaterialRecord> materials;
  Eigen::MatrixX3i surface_triangles;  ///< #F × 3, outward (/mesh/surface_triangles)
  Eigen::VectorXi fixed_vertices;      ///< sorted (/mesh/fixed_vertex_ids)
  Eigen::VectorXi source_vertex_ids;  ///< #V node index in the input file (/mesh/source_vertex_ids)
  Eigen::VectorXi compliance_vertices;  ///< n, compliance order (/compliance/vertex_ids)
  /// #V, m/N (/visualization/softness, since 1.1): for compliance vertex a,
  /// diagonal_block_largest_eigenvalues(G)[a] of the float64 G; 0 on every
  /// other vertex. Required for writing; empty when read from a 1.0 file.
  Eigen::VectorXd softness_m_per_n;
  Precision precision = Precision::kFloat64;
  /// The cuttable region of the hybrid model (/cut_region, since 1.3): when
  /// present, the mesh above is the rest of the organ (the outside) and G is
  /// its compliance on its boundary, Γ included (docs/compliance-file.md,
  /// "The cut region"). Absent from files precomputed without a region.
  std::optional<CutRegionData> cut_region;
  // Root attributes.
  int format_version_minor = kComplianceFormatMinor;  ///< read from the file; written as ours
  std::string method;                                 ///< "solves", "condensation" or "both"
  std::string producer;                               ///< e.g. "palpate-precompute 0.1.0"
  std::string created_utc;                            ///< ISO 8601
  std::string input_hash;                             ///< "sha256:<hex>" of the problem (hash.hpp)
  std::string material_summary;                       ///< human-readable
  std::string job_toml;        ///< the effective job, enough to reproduce the file
  std::string report_json;     ///< the precompute report
  std::string content_sha256;  ///< read from the file (1.2); written as computed
  /// Read from a file with a cut region (1.3): the digest of /cut_region's
  /// datasets, apart from content_sha256 so that 1.2 readers, which verify
  /// content_sha256 over the datasets they know, still read the file;
  /// written as computed.
  std::string cut_region_sha256;
};

/// Writes the file atomically (AtomicOutput): nothing appears at @p path
/// unless the whole file was written. /visualization/fixed is derived from
/// model.fixed_vertices; the root attribute content_sha256 (1.2) is the
/// digest of every dataset as stored but /cut_region's, whose own digest is
/// the root attribute cut_region_sha256 (1.3; docs/compliance-file.md).
/// @param G 3n × 3n compliance, m/N, in compliance order
/// @param progress optional: rows of G written out of 3n
/// @pre model.softness_m_per_n has one entry per vertex
/// @throws SystemError on I/O failure.
void write_compliance_file(const std::filesystem::path& path, const ComplianceModel& model,
                           CRef<Eigen::MatrixXd> G,
                           const std::function<void(long done, long total)>& progress = {});

/// Rows [first, first + count) of G into @p rows: count × 3n values, row-major, m/N.
using GRowSource = std::function<void(long first, long count, double* rows)>;

/// The same, with G given in row bands of @p band_rows rows by @p G_rows (in
/// order, once each): G need not be in memory (docs/precompute.md, "Batch
/// precomputation"). Memory: a band in double and, for float32, in float.
void write_compliance_file(const std::filesystem::path& path, const ComplianceModel& model,
                           const GRowSource& G_rows, long band_rows,
                           const std::function<void(long done, long total)>& progress = {});

/// Reads and checks a compliance file: format name and major version, shapes,
/// index ranges, finite values. Any minor version of major 1 is read; the
/// 1.1 /visualization/softness is read and checked when present; from 1.2
/// on, when @p G is read, the datasets must match content_sha256 (a corrupt
/// file is refused); the 1.3 /cut_region is read and checked when present,
/// and, when @p G is read, must match cut_region_sha256. A file that changes on disk while it is
/// read (written in place, or renamed over) is read again, up to 5 times 0.2 s apart, so that the
/// model comes from one file, whole.
/// @param G receives the 3n × 3n compliance (converted to double)
/// @throws InputError naming the file and the dataset at fault, or saying
///   that the file kept changing.
ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G);

/// The same, G kept as stored: a float32 file fills @p G32 (half the
/// memory) and leaves @p G empty; a float64 file fills @p G and leaves @p G32
/// empty. Both must be given.
ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G,
                                     Eigen::MatrixXf* G32);

}  // namespace palpate
