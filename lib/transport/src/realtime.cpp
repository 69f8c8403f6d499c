#include "palpate/transport/realtime.hpp"

#include <fmt/format.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <fstream>
#include <thread>

#include "palpate/core/error.hpp"
#include "palpate/core/sanitizers.hpp"

namespace palpate::realtime {

namespace {

/// A line "Name:\t…" of /proc/self/status, or "".
std::string status_field(std::string_view name) {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.size() > name.size() && line.compare(0, name.size(), name) == 0 &&
        line[name.size()] == ':') {
      const auto value = line.find_first_not_of(" \t", name.size() + 1);
      return value == std::string::npos ? std::string() : line.substr(value);
    }
  return {};
}

/// Whether the effective capability set holds capability number @p bit.
bool has_capability(int bit) {
  const std::string hex = status_field("CapEff");
  unsigned long long caps = 0;
  if (hex.empty() ||
      std::from_chars(hex.data(), hex.data() + hex.size(), caps, 16).ec != std::errc())
    return false;
  return (caps >> bit) & 1ULL;
}
constexpr int kCapIpcLock = 14, kCapSysNice = 23;

std::string limit_text(rlim_t limit) {
  return limit == RLIM_INFINITY ? std::string("unlimited") : std::to_string(limit);
}

bool set_affinity(std::span<const int> cpus) {
  cpu_set_t set;
  CPU_ZERO(&set);
  for (const int cpu : cpus) CPU_SET(static_cast<std::size_t>(cpu), &set);
  return sched_setaffinity(0, sizeof set, &set) == 0;
}

[[noreturn]] void refuse_priority(const RealtimeOptions& options, const Names& names, int error) {
  rlimit rtprio{};
  getrlimit(RLIMIT_RTPRIO, &rtprio);
  throw InputError(fmt::format(
      "{} {}: the kernel refuses SCHED_FIFO at this priority ({}; RLIMIT_RTPRIO {}, {} "
      "CAP_SYS_NICE): run it as root, or allow it real-time priority {} (systemd: "
      "LimitRTPRIO={} and RestrictRealtime=no; /etc/security/limits.conf: '<user> - rtprio {}'); "
      "as root, its control group may have no real-time time (cpu.rt_runtime_us); or do without "
      "({} 0; docs/realtime.md)",
      names.priority, options.priority, std::strerror(error), limit_text(rtprio.rlim_cur),
      has_capability(kCapSysNice) ? "with" : "without", options.priority, options.priority,
      options.priority, names.priority));
}

[[noreturn]] void refuse_cpus(const RealtimeOptions& options, const Names& names, int error) {
  throw InputError(fmt::format(
      "{} [{}]: the kernel refuses to bind a thread there ({}): the process's cpuset (a control "
      "group's cpuset.cpus, systemd AllowedCPUs=) does not hold them; this process may run on {}",
      names.cpus, format_cpu_list(options.cpus), std::strerror(error),
      format_cpu_list(available_cpus())));
}

}  // namespace

std::vector<int> parse_cpu_list(std::string_view text, std::string_view what) {
  auto fail = [&](std::string_view why) {
    throw InputError(fmt::format(
        "{} '{}': {}; expected CPU numbers from 0 and ranges, as taskset -c: 1, 0,2 or 0-3", what,
        text, why));
  };
  std::vector<int> cpus;
  auto number = [&](std::string_view s) {
    int value = -1;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (s.empty() || ec != std::errc() || end != s.data() + s.size() || value < 0)
      fail(fmt::format("'{}' is not a CPU number", s));
    if (value >= CPU_SETSIZE) fail(fmt::format("CPU {} is beyond {}", value, CPU_SETSIZE - 1));
    return value;
  };
  if (text.empty()) fail("empty");
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    const std::string_view item = text.substr(start, comma - start);
    if (const auto dash = item.find('-'); dash != std::string_view::npos) {
      const int lo = number(item.substr(0, dash)), hi = number(item.substr(dash + 1));
      if (hi < lo) fail(fmt::format("the range {} goes down", item));
      for (int cpu = lo; cpu <= hi; ++cpu) cpus.push_back(cpu);
    } else {
      cpus.push_back(number(item));
    }
    start = comma + 1;
  }
  std::sort(cpus.begin(), cpus.end());
  cpus.erase(std::unique(cpus.begin(), cpus.end()), cpus.end());
  return cpus;
}

std::string format_cpu_list(std::span<const int> cpus) {
  std::string out;
  for (std::size_t i = 0; i < cpus.size();) {
    std::size_t j = i;
    while (j + 1 < cpus.size() && cpus[j + 1] == cpus[j] + 1) ++j;
    if (!out.empty()) out += ',';
    out += j == i ? std::to_string(cpus[i]) : fmt::format("{}-{}", cpus[i], cpus[j]);
    i = j + 1;
  }
  return out;
}

std::vector<int> available_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> cpus;
  if (sched_getaffinity(0, sizeof set, &set) != 0) return cpus;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
    if (CPU_ISSET(static_cast<std::size_t>(cpu), &set)) cpus.push_back(cpu);
  return cpus;
}

std::vector<int> online_cpus() {
  std::ifstream file("/sys/devices/system/cpu/online");
  std::string text;
  if (std::getline(file, text)) {
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
    try {
      return parse_cpu_list(text, "/sys/devices/system/cpu/online");
    } catch (const InputError&) {
    }
  }
  return available_cpus();
}

void validate(const RealtimeOptions& options, const Names& names) {
  if (options.priority < 0 || options.priority > kMaxPriority)
    throw InputError(fmt::format(
        "{} {}: expected a SCHED_FIFO priority from 1 (lowest) to {}, or 0 for the normal "
        "scheduling",
        names.priority, options.priority, kMaxPriority));
  const std::vector<int> online = online_cpus();
  for (const int cpu : options.cpus)
    if (!std::binary_search(online.begin(), online.end(), cpu))
      throw InputError(
          fmt::format("{} [{}]: CPU {} is not online on this machine ({})", names.cpus,
                      format_cpu_list(options.cpus), cpu,
                      online.empty() ? std::string("none found") : format_cpu_list(online)));
}

void check_permitted(const RealtimeOptions& options, const Names& names) {
  if (options.priority == 0 && options.cpus.empty()) return;
  int affinity_error = 0, priority_error = 0;
  std::thread probe([&] {
    if (!options.cpus.empty() && !set_affinity(options.cpus)) affinity_error = errno;
    sched_param param{};
    param.sched_priority = options.priority;
    if (options.priority > 0)
      priority_error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  });
  probe.join();
  if (affinity_error != 0) refuse_cpus(options, names, affinity_error);
  if (priority_error != 0) refuse_priority(options, names, priority_error);
}

void apply_to_this_thread(const RealtimeOptions& options, const Names& names) {
  if (!options.cpus.empty() && !set_affinity(options.cpus)) refuse_cpus(options, names, errno);
  if (options.priority > 0) {
    sched_param param{};
    param.sched_priority = options.priority;
    if (const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param); error != 0)
      refuse_priority(options, names, error);
  }
}

void lock_memory(const RealtimeOptions& options, const Names& names) {
  if (!options.lock_memory) return;
#ifdef PALPATE_SHADOW_MEMORY
  throw ResourceError(std::string(names.lock_memory) +
                      ": not in a build with AddressSanitizer or ThreadSanitizer, whose shadow "
                      "memory (terabytes reserved) it would try to make resident");
#endif
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) return;
  const int error = errno;
  rlimit memlock{};
  getrlimit(RLIMIT_MEMLOCK, &memlock);
  const std::string mapped = status_field("VmSize");
  throw ResourceError(fmt::format(
      "{}: mlockall failed ({}): the process maps {} and may lock {} bytes (RLIMIT_MEMLOCK), {} "
      "CAP_IPC_LOCK; run it as root or raise the limit (systemd: LimitMEMLOCK=infinity; ulimit "
      "-l unlimited; /etc/security/limits.conf: '<user> - memlock unlimited'), or leave {} off "
      "(docs/realtime.md)",
      names.lock_memory, std::strerror(error), mapped.empty() ? "?" : mapped,
      limit_text(memlock.rlim_cur), has_capability(kCapIpcLock) ? "with" : "without",
      names.lock_memory));
}

std::string cyclone_receive_thread_xml(int priority) {
  if (priority <= 0) return {};
  return fmt::format(
      "<Internal><MultipleReceiveThreads>false</MultipleReceiveThreads></Internal>"
      "<Threads><Thread name=\"recv\"><Scheduling><Class>realtime</Class><Priority>{}</Priority>"
      "</Scheduling></Thread></Threads>",
      priority);
}

ScopedAffinity::ScopedAffinity(std::span<const int> cpus) {
  static_assert(sizeof(cpu_set_t) <= sizeof saved_);
  if (cpus.empty()) return;
  auto* saved = reinterpret_cast<cpu_set_t*>(saved_);
  if (sched_getaffinity(0, sizeof(cpu_set_t), saved) != 0) return;
  changed_ = set_affinity(cpus);
}

ScopedAffinity::~ScopedAffinity() {
  if (changed_) sched_setaffinity(0, sizeof(cpu_set_t), reinterpret_cast<cpu_set_t*>(saved_));
}

}  // namespace palpate::realtime
