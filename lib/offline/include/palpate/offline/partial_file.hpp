#pragma once
/// @file
/// A shard's file: some columns of G (computed by 3N_S solves, per column
/// independent), written block by block into a chunked HDF5 dataset, with
/// the checkpoint of the run computing them, so that a killed run resumes
/// from its last complete block. `palpate-precompute merge` assembles the
/// shards into a compliance file (docs/precompute.md, "Batch precomputation").
///
/// Crash safety: every dataset a run updates is allocated when the file is
/// created (fixed addresses: no HDF5 metadata changes afterwards), and a
/// block is flagged complete only after its columns are flushed and synced.
/// A SIGKILL or a power loss mid-block leaves that block unflagged: the next
/// run solves it again.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/compliance.hpp"

namespace palpate {

/// What a shard computes; a checkpoint is resumed only by a run of the same.
struct ShardIdentity {
  std::string input_hash;  ///< of the problem (compliance-file.md, "input_hash")
  int columns_begin = 0;   ///< first column of G, a multiple of block_columns
  int columns_end = 0;     ///< one past the last; a multiple of block_columns, or m
  int columns_total = 0;   ///< m = 3n
  int block_columns = 0;   ///< B: block b is columns [b·B, (b+1)·B)
  Precision precision = Precision::kFloat64;
  bool operator==(const ShardIdentity&) const = default;
  int first_block() const { return columns_begin / block_columns; }
  int blocks() const { return (columns_end - columns_begin + block_columns - 1) / block_columns; }
  /// "columns 0:1024 of 4410, blocks of 64, float64, input sha256:0123abcd…"
  std::string describe() const;
};

/// An open shard file: the checkpoint a run writes, or a complete shard.
class PartialFile {
 public:
  /// Creates @p path (replacing it) for @p id: the model's datasets (all but
  /// G), G's chunked dataset and the checkpoint, every block pending.
  /// @param check_columns columns of the range to re-solve and check
  /// @param blas the BLAS in use (blas_description()), recorded for merge
  static std::unique_ptr<PartialFile> create(const std::filesystem::path& path,
                                             const ComplianceModel& model, const ShardIdentity& id,
                                             const std::vector<int>& check_columns,
                                             const std::string& blas);

  /// Opens an incomplete checkpoint to continue it. @returns null, with the
  /// reason in @p why, if it cannot be read or was made for another shard.
  /// @throws InputError if another process is writing it (it is locked).
  static std::unique_ptr<PartialFile> open_to_resume(const std::filesystem::path& path,
                                                     const ShardIdentity& id, std::string* why);

  /// Opens a shard to merge it, read-only.
  /// @throws InputError naming the file if it is not a complete shard.
  static std::unique_ptr<PartialFile> open_complete(const std::filesystem::path& path);

  ~PartialFile();
  PartialFile(const PartialFile&) = delete;
  PartialFile& operator=(const PartialFile&) = delete;

  const std::filesystem::path& path() const;
  const ShardIdentity& identity() const;
  const std::string& blas() const;  ///< of the run that created it
  const std::vector<int>& check_columns() const;
  /// Absolute numbers of the blocks not yet complete.
  std::vector<int> pending_blocks() const;

  /// Stores a solved block (its columns, their 3 × 3 diagonal-block entries
  /// in float64, its checks), flushes and syncs, then flags it complete.
  void write_block(const SolvedBlock& block);

  /// Marks the shard complete with its report (JSON); flushed and synced.
  void finish(const std::string& report_json);
  /// Closes the file (before renaming it).
  void close();

  // ---- reading (a complete shard) ----
  /// Everything but G (read_compliance_file's checks).
  ComplianceModel model() const;
  std::string report_json() const;
  /// Rows [first, first + count) of this shard's columns, into the row-major
  /// band @p band (count × columns_total) at columns [begin, end).
  void read_rows(long first, long count, double* band) const;
  /// For each column c of the range, G(3k + i, c), i = 0, 1, 2, k = c / 3:
  /// the entries of the diagonal blocks, in float64 (width × 3).
  Eigen::MatrixX3d diagonal_entries() const;
  /// The sampled columns' checks (each solved once).
  std::vector<ColumnCheck> checks() const;

 private:
  struct Impl;
  explicit PartialFile(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The checkpoint of a run writing @p output (a compliance file or a shard):
/// ".<name>.checkpoint" beside it. Unlike the ".<name>.tmp-<pid>" of an
/// atomic write, it survives its run on purpose: the next run of the same
/// output resumes it (docs/faults.md).
std::filesystem::path checkpoint_path(const std::filesystem::path& output);

}  // namespace palpate
