#pragma once
// palpated as a child process of a test (PALPATED_PATH), its stderr in a
// file. The caller runs inside a private network namespace (CTest does).

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

/// palpated as a child process, its stderr in a file.
class Daemon {
 public:
  Daemon(const std::vector<std::string>& args, const std::filesystem::path& log) : log_(log) {
    pid_ = fork();
    if (pid_ == 0) {
      // Dies with the test: a test killed by CTest's timeout leaves no
      // process behind (one palpated lived on for 47 minutes that way).
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      std::FILE* err = std::freopen(log.c_str(), "w", stderr);
      (void)err;
      std::vector<char*> argv{const_cast<char*>(PALPATED_PATH)};
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(PALPATED_PATH, argv.data());
      _exit(127);
    }
  }
  ~Daemon() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  /// Sends @p signal (0: none) and returns the exit code, -1 if it had to be killed.
  int stop(int signal) {
    if (signal != 0) kill(pid_, signal);
    int status = 0;
    for (int i = 0; i < 1000; ++i) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return -1;
  }
  std::string log() const {
    std::ifstream in(log_);
    return {std::istreambuf_iterator<char>(in), {}};
  }

 private:
  std::filesystem::path log_;
  pid_t pid_ = -1;
  bool exited_ = false;
};

}  // namespace palpate::testing
