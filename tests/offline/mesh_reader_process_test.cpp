// The mesh reader process (read_mesh_isolated, mesh_reader_process.cpp)
// ends with the process that started it: a palpate-precompute killed during
// a long read leaves no reader behind.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "palpate/offline/mesh_io.hpp"
#include "support/child_process.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

/// How the reader ended, as the exit code of the process that watched it.
enum ReaderEnd : int { kKilled = 0, kNeverStarted = 1, kStillRunning = 2, kOther = 3 };

/// Runs in a child of the test: starts a stand-in for palpate-precompute
/// reading @p mesh (a FIFO nobody writes: its reader process blocks there
/// as in a long read), waits for that reader to block, kills the stand-in
/// with SIGKILL, and tells how the reader ended. As a subreaper, this
/// process is handed the orphaned reader, so it can wait for it. No time is
/// measured: the 10 s limits only keep a reader that does not end from
/// hanging the test.
ReaderEnd reader_end_after_parent_killed(const std::filesystem::path& mesh) {
  ::prctl(PR_SET_CHILD_SUBREAPER, 1);
  const pid_t self = ::getpid();
  const pid_t precompute = ::fork();
  if (precompute < 0) return kOther;
  if (precompute == 0) {
    testing::die_with_parent(self);
    try {
      read_mesh_isolated(mesh, {});
    } catch (...) {
    }
    _exit(0);
  }
  // The FIFO opens for writing once the reader has opened it, past its
  // set-up after fork; the reader then waits for data that never comes.
  const auto give_up = Clock::now() + 10s;
  int fifo = -1;
  while ((fifo = ::open(mesh.c_str(), O_WRONLY | O_NONBLOCK)) < 0 && Clock::now() < give_up)
    std::this_thread::sleep_for(5ms);
  pid_t reader = 0;
  std::ifstream("/proc/" + std::to_string(precompute) + "/task/" + std::to_string(precompute) +
                "/children") >>
      reader;
  ::kill(precompute, SIGKILL);
  ::waitpid(precompute, nullptr, 0);
  if (fifo < 0 || reader == 0) return kNeverStarted;
  for (int status = 0;;) {
    const pid_t ended = ::waitpid(reader, &status, WNOHANG);
    if (ended == reader)
      return WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL ? kKilled : kOther;
    if (ended < 0) return kOther;
    if (Clock::now() >= give_up + 10s) {
      ::kill(reader, SIGKILL);
      ::waitpid(reader, nullptr, 0);
      return kStillRunning;
    }
    std::this_thread::sleep_for(5ms);
  }
}

TEST(MeshIo, TheReaderProcessDiesWithPalpatePrecompute) {
  testing::TempDir dir;
  const auto fifo = dir / "stuck.msh";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const pid_t test = ::getpid();
  std::fflush(nullptr);
  const pid_t watcher = ::fork();
  ASSERT_GE(watcher, 0);
  if (watcher == 0) {
    testing::die_with_parent(test);
    _exit(reader_end_after_parent_killed(fifo));
  }
  int status = 0;
  ASSERT_EQ(::waitpid(watcher, &status, 0), watcher);
  ASSERT_TRUE(WIFEXITED(status)) << testing::exit_code(status);
  EXPECT_EQ(WEXITSTATUS(status), kKilled)
      << "1: no reader process seen; 2: the reader outlived palpate-precompute; 3: it ended "
         "otherwise than by SIGKILL";
}

}  // namespace
}  // namespace palpate
