#pragma once
// A program (palpated, palpate-pliers, palpate-client) as a child process of
// a test, its output in a file that the test reads while it runs. The caller
// runs inside a private network namespace (CTest does).

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

class ChildProcess {
 public:
  /// What goes to the output file; the rest stays the test's.
  enum class Capture { kStdoutAndStderr, kStderr };

  ChildProcess(const std::string& program, const std::vector<std::string>& args,
               const std::filesystem::path& output, Capture capture = Capture::kStdoutAndStderr)
      : output_(output) {
    pid_ = fork();
    if (pid_ == 0) {
      // Dies with the test: a test killed by CTest's timeout leaves no
      // process behind (one palpated lived on for 47 minutes that way).
      prctl(PR_SET_PDEATHSIG, SIGKILL);
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
    int status = 0;
    while (std::chrono::steady_clock::now() < until) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return -1;
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
};

}  // namespace palpate::testing
