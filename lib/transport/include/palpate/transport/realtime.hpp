#pragma once
/// @file
/// Real-time operation of the threads on the haptic path (docs/realtime.md):
/// a SCHED_FIFO priority, a CPU affinity, locked memory, and the Cyclone DDS
/// configuration that gives Cyclone's receive thread the same priority and
/// CPUs. palpated takes them from its `[realtime]` table, the clients from
/// ToolClientOptions::realtime and ClientOptions::realtime (palpate-pliers
/// and palpate-client: `--rt-priority`, `--cpus`, `--lock-memory`). Linux.
///
/// Who gets what: Cyclone's receive thread (which runs palpated's listeners,
/// and wakes a waiting client) gets the priority through Cyclone's own
/// configuration (`<Threads><Thread name="recv"><Scheduling>`; Cyclone 0.10
/// names only the single receive thread there, so the fragment also asks for
/// one receive thread: `<Internal><MultipleReceiveThreads>false`), and the
/// CPUs by inheritance: the domain is created by a thread bound to them
/// (every Cyclone thread of the process then runs there). A thread of the
/// application (palpated's serving thread, a device's loop) applies them to
/// itself with apply_to_this_thread().

#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace palpate {

struct RealtimeOptions {
  /// SCHED_FIFO priority of the real-time threads, 1 to 99 (higher runs
  /// first); 0: they keep the normal scheduling (SCHED_OTHER).
  int priority = 0;
  /// CPUs (numbered from 0, as `taskset -c`) the real-time threads may run
  /// on; empty: any CPU the process may use.
  std::vector<int> cpus;
  /// Lock every page of the process in memory once it has started
  /// (mlockall(MCL_CURRENT | MCL_FUTURE)): no page fault on the haptic path.
  bool lock_memory = false;

  bool any() const { return priority > 0 || !cpus.empty() || lock_memory; }
};

namespace realtime {

/// The highest SCHED_FIFO priority on Linux.
inline constexpr int kMaxPriority = 99;

/// What messages call each option: a configuration's keys
/// (`realtime.priority`, the default) or a program's flags (`--rt-priority`).
struct Names {
  std::string_view priority = "realtime.priority";
  std::string_view cpus = "realtime.cpus";
  std::string_view lock_memory = "realtime.lock_memory";
};
/// The flags of palpate-pliers, palpate-client and palpated.
inline constexpr Names kFlagNames{"--rt-priority", "--cpus", "--lock-memory"};

/// Parses a CPU list in the kernel's format, as `taskset -c` takes it:
/// "1", "0,2", "0-3", "0-1,3". Sorted, without duplicates.
/// @throws InputError "<what> '<text>': …" saying what is accepted.
std::vector<int> parse_cpu_list(std::string_view text, std::string_view what);
/// The kernel's format of @p cpus: "0-1,3"; "" for none.
std::string format_cpu_list(std::span<const int> cpus);
/// The CPUs the calling thread may run on now (sched_getaffinity).
std::vector<int> available_cpus();
/// The CPUs online on this machine (/sys/devices/system/cpu/online),
/// isolated ones (isolcpus) included.
std::vector<int> online_cpus();

/// Checks the values: priority 0 to kMaxPriority, each CPU online. Needs
/// no privilege.
/// @throws InputError naming the option (@p names), the value and what is accepted.
void validate(const RealtimeOptions& options, const Names& names = {});

/// Checks that this process may bind a thread to options.cpus (its cpuset
/// holds them; an isolated CPU is fine) and use SCHED_FIFO at
/// options.priority (root, CAP_SYS_NICE or RLIMIT_RTPRIO ≥ the priority),
/// tried on a short-lived thread, so nothing of the caller changes.
/// @throws InputError saying what is missing and how to grant it.
void check_permitted(const RealtimeOptions& options, const Names& names = {});

/// Binds the calling thread to options.cpus (when given) and makes it
/// SCHED_FIFO at options.priority (when > 0). Allocates nothing unless it
/// fails: a device may call it at the start of its loop thread.
/// @throws InputError when the kernel refuses (what, why, how to grant it).
void apply_to_this_thread(const RealtimeOptions& options, const Names& names = {});

/// mlockall(MCL_CURRENT | MCL_FUTURE) when options.lock_memory.
/// @throws ResourceError naming RLIMIT_MEMLOCK and how to raise it.
void lock_memory(const RealtimeOptions& options, const Names& names = {});

/// The Cyclone DDS configuration fragment that makes Cyclone's receive
/// thread SCHED_FIFO at @p priority (one receive thread); "" for 0. Appended
/// to a domain's configuration by dds::resolve_domain_config(); always
/// loopback-neutral (no interface, no multicast setting).
std::string cyclone_receive_thread_xml(int priority);

/// Binds the calling thread to @p cpus (none: no change) until destroyed,
/// then restores its affinity: the threads it creates meanwhile (Cyclone's,
/// when it creates a domain) keep @p cpus.
class ScopedAffinity {
 public:
  explicit ScopedAffinity(std::span<const int> cpus);
  ~ScopedAffinity();
  ScopedAffinity(const ScopedAffinity&) = delete;
  ScopedAffinity& operator=(const ScopedAffinity&) = delete;

 private:
  bool changed_ = false;
  unsigned char saved_[128] = {};  // a cpu_set_t (1024 CPUs)
};

}  // namespace realtime
}  // namespace palpate
