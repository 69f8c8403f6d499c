#include "palpate/file/atomic_file.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <csignal>
#include <cstring>

#include "palpate/core/error.hpp"

namespace palpate {

namespace {

// The temporary path the signal handler removes; async-signal-safe storage.
char g_pending_temp[4096];
volatile sig_atomic_t g_has_pending = 0;

void on_signal(int sig) {
  if (g_has_pending) ::unlink(g_pending_temp);
  std::signal(sig, SIG_DFL);
  ::raise(sig);
}

void fsync_path(const std::filesystem::path& p, int flags) {
  const int fd = ::open(p.c_str(), flags);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

}  // namespace

void require_output_directory(const std::filesystem::path& final_path) {
  if (final_path.filename().empty())
    throw InputError(fmt::format("output path '{}' names no file", final_path.string()));
  const auto dir =
      final_path.has_parent_path() ? final_path.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    throw InputError(fmt::format("output path '{}': directory '{}' does not exist",
                                 final_path.string(), dir.string()));
}

AtomicOutput::AtomicOutput(std::filesystem::path final_path) : final_(std::move(final_path)) {
  require_output_directory(final_);
  const auto dir = final_.has_parent_path() ? final_.parent_path() : std::filesystem::path(".");
  temp_ = dir / fmt::format(".{}.tmp-{}", final_.filename().string(), ::getpid());
  if (temp_.string().size() < sizeof(g_pending_temp)) {
    std::strcpy(g_pending_temp, temp_.c_str());
    g_has_pending = 1;
  }
}

AtomicOutput::~AtomicOutput() {
  g_has_pending = 0;
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicOutput::commit() {
  durable_rename(temp_, final_);
  committed_ = true;
  g_has_pending = 0;
}

void durable_rename(const std::filesystem::path& from, const std::filesystem::path& to) {
  fsync_path(from, O_RDONLY);
  std::error_code ec;
  std::filesystem::rename(from, to, ec);
  if (ec)
    throw SystemError(
        fmt::format("cannot move '{}' to '{}': {}", from.string(), to.string(), ec.message()));
  fsync_path(to.has_parent_path() ? to.parent_path() : ".", O_RDONLY | O_DIRECTORY);
}

std::vector<StaleTemporary> remove_stale_temporaries(const std::filesystem::path& final_path) {
  std::vector<StaleTemporary> removed;
  if (final_path.filename().empty()) return removed;
  const auto dir =
      final_path.has_parent_path() ? final_path.parent_path() : std::filesystem::path(".");
  const std::string prefix = fmt::format(".{}.tmp-", final_path.filename().string());
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!name.starts_with(prefix)) continue;
    const std::string_view digits = std::string_view(name).substr(prefix.size());
    long pid = 0;
    const auto [rest, status] = std::from_chars(digits.data(), digits.data() + digits.size(), pid);
    if (status != std::errc() || rest != digits.data() + digits.size() || pid <= 0 ||
        pid == ::getpid())
      continue;
    // Only when that process is gone: a live one (another run writing the
    // same output, or an unrelated process that reused the pid) keeps it.
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
    std::error_code removal;
    if (std::filesystem::remove(it->path(), removal)) removed.push_back({it->path(), pid});
  }
  return removed;
}

void install_interrupt_cleanup() {
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) std::signal(sig, on_signal);
}

}  // namespace palpate
