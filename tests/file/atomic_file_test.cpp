// Atomic output (atomic_file.hpp): a committed temporary replaces the output
// and disappears; an abandoned one leaves nothing and an older output
// intact; missing directories are refused by name; the temporaries of dead
// runs are removed and those of live ones kept.

#include "palpate/file/atomic_file.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "support/expect_error.hpp"
#include "support/files.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::listing;
using testing::slurp;
using testing::TempDir;

void spit(const std::filesystem::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

/// The pid of a child that has exited and been reaped: no process has it
/// (until the kernel hands it out again, which takes a full turn of pid_max).
pid_t dead_pid() {
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);  // nothing else in the child (CHOLMOD's OpenMP does not survive fork)
  EXPECT_GT(child, 0);
  int status = 0;
  EXPECT_EQ(::waitpid(child, &status, 0), child);
  return child;
}

std::string temporary_name(const std::string& output, long pid) {
  return "." + output + ".tmp-" + std::to_string(pid);
}

TEST(AtomicFile, CommitRenamesTheTemporaryIntoPlace) {
  TempDir dir;
  const auto final_path = dir / "out.h5";
  spit(final_path, "old");
  {
    AtomicOutput out(final_path);
    EXPECT_EQ(out.temp_path(), dir / temporary_name("out.h5", ::getpid()));
    spit(out.temp_path(), "new and whole");
    EXPECT_EQ(slurp(final_path), "old") << "the output is untouched until commit";
    out.commit();
    EXPECT_FALSE(std::filesystem::exists(out.temp_path()));
  }  // destroyed after commit: the committed file stays
  EXPECT_EQ(slurp(final_path), "new and whole");
  EXPECT_EQ(listing(dir.path()), std::vector<std::string>{"out.h5"});
}

TEST(AtomicFile, AbandoningLeavesNothingAndKeepsAnOlderOutput) {
  TempDir dir;
  {
    AtomicOutput out(dir / "fresh.h5");
    spit(out.temp_path(), "partial");
    ASSERT_TRUE(std::filesystem::exists(out.temp_path()));
  }
  EXPECT_TRUE(listing(dir.path()).empty());

  spit(dir / "kept.h5", "the older, complete file");
  {
    AtomicOutput out(dir / "kept.h5");
    spit(out.temp_path(), "partial");
  }
  EXPECT_EQ(listing(dir.path()), std::vector<std::string>{"kept.h5"});
  EXPECT_EQ(slurp(dir / "kept.h5"), "the older, complete file");

  // An exception between writing and commit is an abandonment too.
  try {
    AtomicOutput out(dir / "kept.h5");
    spit(out.temp_path(), "partial");
    throw std::runtime_error("the writer failed");
  } catch (const std::runtime_error&) {
  }
  EXPECT_EQ(listing(dir.path()), std::vector<std::string>{"kept.h5"});
  EXPECT_EQ(slurp(dir / "kept.h5"), "the older, complete file");
}

TEST(AtomicFile, CommitWithoutATemporaryIsASystemErrorAndChangesNothing) {
  TempDir dir;
  spit(dir / "kept.h5", "complete");
  AtomicOutput out(dir / "kept.h5");
  expect_error<SystemError>([&] { out.commit(); }, {out.temp_path().string(), "kept.h5"});
  EXPECT_EQ(slurp(dir / "kept.h5"), "complete");
}

TEST(AtomicFile, DurableRenameReplacesTheTargetOrSaysWhyNot) {
  TempDir dir;
  spit(dir / "a", "A");
  spit(dir / "b", "B");
  durable_rename(dir / "a", dir / "b");
  EXPECT_EQ(listing(dir.path()), std::vector<std::string>{"b"});
  EXPECT_EQ(slurp(dir / "b"), "A");
  expect_error<SystemError>([&] { durable_rename(dir / "missing", dir / "b"); },
                            {(dir / "missing").string(), (dir / "b").string()});
  EXPECT_EQ(slurp(dir / "b"), "A");
}

TEST(AtomicFile, AMissingOutputDirectoryIsRefusedByName) {
  TempDir dir;
  EXPECT_NO_THROW(require_output_directory(dir / "out.h5"));
  const auto missing = dir / "no" / "such";
  expect_error<InputError>(
      [&] { require_output_directory(missing / "out.h5"); },
      {(missing / "out.h5").string(), "directory '" + missing.string() + "'", "does not exist"});
  // A file where the directory should be.
  spit(dir / "plain", "x");
  expect_error<InputError>([&] { require_output_directory(dir / "plain" / "out.h5"); },
                           {(dir / "plain").string()});
  // A path that names no file.
  expect_error<InputError>([&] { require_output_directory(dir.path() / ""); }, {"names no file"});
  // The constructor checks first and creates nothing.
  EXPECT_THROW({ AtomicOutput out(missing / "out.h5"); }, InputError);
  EXPECT_FALSE(std::filesystem::exists(dir / "no"));
}

TEST(AtomicFile, RemovesTheTemporariesOfDeadRunsOnly) {
  TempDir dir;
  const auto output = dir / "out.h5";
  const pid_t dead = dead_pid();
  ASSERT_NE(dead, ::getpid());
  spit(dir / temporary_name("out.h5", dead), "left by a killed run");
  spit(dir / temporary_name("out.h5", ::getpid()), "this process's, being written");
  spit(dir / temporary_name("out.h5", ::getppid()), "a live process's");
  spit(dir / temporary_name("other.h5", dead), "another output's");
  spit(dir / ".out.h5.tmp-12ab", "not a pid");
  spit(dir / ".out.h5.checkpoint", "a checkpoint, kept on purpose");
  spit(output, "the output");

  const std::vector<StaleTemporary> removed = remove_stale_temporaries(output);
  ASSERT_EQ(removed.size(), 1u);
  EXPECT_EQ(removed[0].path, dir / temporary_name("out.h5", dead));
  EXPECT_EQ(removed[0].pid, dead);
  std::vector<std::string> expected{temporary_name("out.h5", ::getpid()),
                                    temporary_name("out.h5", ::getppid()),
                                    temporary_name("other.h5", dead),
                                    ".out.h5.tmp-12ab",
                                    ".out.h5.checkpoint",
                                    "out.h5"};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(listing(dir.path()), expected);
  // Nothing more to remove; a missing directory is no error.
  EXPECT_TRUE(remove_stale_temporaries(output).empty());
  EXPECT_TRUE(remove_stale_temporaries(dir / "missing" / "out.h5").empty());
}

}  // namespace
}  // namespace palpate
