#pragma once
// palpated as a child process of a test (PALPATED_PATH), its stderr in a
// file. The caller runs inside a private network namespace (CTest does).

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "support/child_process.hpp"

namespace palpate::testing {

/// palpated as a child process, its stderr (its log) in a file.
class Daemon : public ChildProcess {
 public:
  Daemon(const std::vector<std::string>& args, const std::filesystem::path& log)
      : ChildProcess(PALPATED_PATH, args, log, Capture::kStderr) {}
  /// Sends @p signal (0: none) and returns the exit code (128 + signal if a
  /// signal ended it), -1 if it had not exited within 10 s.
  int stop(int signal) {
    if (signal != 0) this->signal(signal);
    return wait(std::chrono::seconds(10));
  }
  std::string log() const { return output(); }
};

}  // namespace palpate::testing
