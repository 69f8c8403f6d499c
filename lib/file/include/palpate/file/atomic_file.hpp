#pragma once
/// @file
/// Atomic output: a file is written under a temporary name beside its final
/// path and renamed into place only once complete, so an interrupted run
/// never leaves a partial file at the output path.

#include <filesystem>
#include <vector>

namespace palpate {

/// The temporary twin of an output file. Destroying it without commit()
/// removes the temporary; SIGINT/SIGTERM/SIGHUP remove it too (see
/// install_interrupt_cleanup()).
class AtomicOutput {
 public:
  explicit AtomicOutput(std::filesystem::path final_path);
  ~AtomicOutput();
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;

  /// Where to write: ".<name>.tmp-<pid>" in the same directory.
  const std::filesystem::path& temp_path() const { return temp_; }
  /// Flushes the temporary to disk and renames it to the final path.
  /// @throws SystemError if the file system refuses.
  void commit();

 private:
  std::filesystem::path final_;
  std::filesystem::path temp_;
  bool committed_ = false;
};

/// Flushes @p from to disk, renames it to @p to (replacing it) and flushes
/// the directory, so that after a crash one of the two names holds the whole
/// file. @throws SystemError if the file system refuses.
void durable_rename(const std::filesystem::path& from, const std::filesystem::path& to);

/// Checks that @p final_path names a file in an existing directory.
/// @throws InputError otherwise, naming the missing directory.
void require_output_directory(const std::filesystem::path& final_path);

/// A temporary file of an earlier run that was killed before it could remove it.
struct StaleTemporary {
  std::filesystem::path path;
  long pid = 0;  ///< of the run that wrote it (gone)
};

/// Removes the temporaries ".<name>.tmp-<pid>" of @p final_path left by runs
/// that were killed (SIGKILL, power loss: no handler ran), i.e. whose process
/// <pid> no longer exists. A temporary of a live process, or of this one, is
/// left alone (a pid reused by an unrelated process keeps its file too).
/// @returns what was removed; errors are ignored (nothing removed).
std::vector<StaleTemporary> remove_stale_temporaries(const std::filesystem::path& final_path);

/// Installs handlers for SIGINT, SIGTERM and SIGHUP that remove the current
/// AtomicOutput's temporary file and then end the process as the signal would.
void install_interrupt_cleanup();

}  // namespace palpate
