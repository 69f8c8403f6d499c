#pragma once
// A program (palpated, palpate-pliers, palpate-client) as a child process of
// a test or a benchmark, its output in a file that the caller reads while it
// runs. The caller runs inside a private network namespace (CTest and the
// benchmark scripts do).

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace palpate::testing {

/// Call first in a child just forked from @p parent: the child dies
/// (SIGKILL) when its parent does, so that a test or a benchmark killed by
/// its timeout leaves no process behind (one palpated lived on for 47
/// minutes that way). If the parent is already gone, the child exits.
inline void die_with_parent(pid_t parent) {
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (getppid() != parent) _exit(125);
}

/// Exit code of a wait status: the code, or 128 + the signal that ended it.
inline int exit_code(int status) {
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

class ChildProcess {
 public:
  /// What goes to the output file; the rest stays the test's.
  enum class Capture { kStdoutAndStderr, kStderr };

  ChildProcess(const std::string& program, const std::vector<std::string>& args,
               const std::filesystem::path& output, Capture capture = Capture::kStdoutAndStderr)
      : output_(output) {
    const pid_t parent = getpid();
    std::fflush(nullptr);  // what the caller printed is not printed twice
    pid_ = fork();
    if (pid_ == 0) {
      die_with_parent(parent);
      if (capture == Capture::kStderr) {
        if (std::freopen(output.c_str(), "w", stderr) == nullptr) _exit(126);
      } else {
        if (std::freopen(output.c_str(), "w", stdout) == nullptr) _exit(126);
        dup2(fileno(stdout), fileno(stderr));
      }
      std::vector<char*> argv{const_cast<char*>(program.c_str())};
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(program.c_str(), argv.data());
      _exit(127);
    }
  }
  ~ChildProcess() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  void signal(int signal) const { kill(pid_, signal); }

  /// Waits for the exit: its code, 128 + signal if a signal ended it, -1 on timeout.
  int wait(std::chrono::milliseconds timeout) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      if (!running()) return status_;
      if (std::chrono::steady_clock::now() >= until) return -1;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  /// False once it has exited (its code is then exit_status()).
  bool running() {
    int status = 0;
    if (!exited_ && waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      status_ = exit_code(status);
    }
    return !exited_;
  }
  /// Its exit code (as wait()), −1 while it runs.
  int exit_status() const { return status_; }
  /// SIGTERM, then its exit code; SIGKILL (and −1) if it is still there
  /// after @p grace.
  int terminate(std::chrono::milliseconds grace) {
    if (!running()) return status_;
    signal(SIGTERM);
    if (const int code = wait(grace); code != -1) return code;
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    exited_ = true;
    status_ = -1;
    return status_;
  }

  std::string output() const {
    std::ifstream in(output_);
    return {std::istreambuf_iterator<char>(in), {}};
  }

  /// Waits until the output holds @p text @p times times (or the deadline).
  bool wait_for_output(const std::string& text, std::chrono::steady_clock::time_point deadline,
                       int times = 1) const {
    for (;;) {
      if (count(output(), text) >= times) return true;
      if (std::chrono::steady_clock::now() >= deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }

  static int count(const std::string& haystack, const std::string& needle) {
    int n = 0;
    for (auto at = haystack.find(needle); at != std::string::npos;
         at = haystack.find(needle, at + needle.size()))
      ++n;
    return n;
  }

 private:
  std::filesystem::path output_;
  pid_t pid_ = -1;
  bool exited_ = false;
  int status_ = -1;
};

}  // namespace palpate::testing
