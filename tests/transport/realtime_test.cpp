// Real-time options (transport/realtime.hpp): CPU lists, the checks and
// their messages, the Cyclone fragment of the receive thread, what
// apply_to_this_thread does to a thread (and that it allocates nothing),
// and the refusal of a priority by a process without the privilege. No
// DDS participant is created here.

#include "palpate/transport/realtime.hpp"

#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <thread>

#include "palpate/core/error.hpp"
#include "palpate/core/sanitizers.hpp"
#include "palpate/transport/dds.hpp"
#include "support/allocation_counter.hpp"
#include "support/expect_error.hpp"

namespace palpate {
namespace {

using testing::expect_error;

TEST(Realtime, CpuListsAreReadAsTasksetTakesThem) {
  EXPECT_EQ(realtime::parse_cpu_list("1", "--cpus"), (std::vector<int>{1}));
  EXPECT_EQ(realtime::parse_cpu_list("0,2", "--cpus"), (std::vector<int>{0, 2}));
  EXPECT_EQ(realtime::parse_cpu_list("0-3", "--cpus"), (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(realtime::parse_cpu_list("4,0-1,1", "--cpus"), (std::vector<int>{0, 1, 4}))
      << "sorted, each once";
  EXPECT_EQ(realtime::format_cpu_list(std::vector<int>{0, 1, 2, 4, 6, 7}), "0-2,4,6-7");
  EXPECT_EQ(realtime::format_cpu_list(std::vector<int>{}), "");
  expect_error<InputError>([] { realtime::parse_cpu_list("", "--cpus"); },
                           {"--cpus '': empty", "as taskset -c"});
  expect_error<InputError>([] { realtime::parse_cpu_list("a", "--cpus"); },
                           {"--cpus 'a': 'a' is not a CPU number", "0-3"});
  expect_error<InputError>([] { realtime::parse_cpu_list("3-1", "realtime.cpus"); },
                           {"realtime.cpus '3-1': the range 3-1 goes down"});
  expect_error<InputError>([] { realtime::parse_cpu_list("1,", "--cpus"); },
                           {"'' is not a CPU number"});
  expect_error<InputError>([] { realtime::parse_cpu_list("-1", "--cpus"); },
                           {"is not a CPU number"});
  expect_error<InputError>([] { realtime::parse_cpu_list("5000", "--cpus"); },
                           {"CPU 5000 is beyond 1023"});
}

TEST(Realtime, ValuesAreCheckedAgainstLinuxAndThisProcess) {
  EXPECT_NO_THROW(realtime::validate({}));
  EXPECT_NO_THROW(realtime::validate({99, realtime::available_cpus(), true}));
  expect_error<InputError>(
      [] {
        realtime::validate({100, {}, false});
      },
      {"realtime.priority 100: expected a SCHED_FIFO priority from 1", "to 99, or 0"});
  expect_error<InputError>(
      [] {
        realtime::validate({-1, {}, false}, realtime::kFlagNames);
      },
      {"--rt-priority -1:"});
  const int absent = realtime::online_cpus().back() + 1;
  expect_error<InputError>(
      [&] {
        realtime::validate({0, {absent}, false});
      },
      {"realtime.cpus [" + std::to_string(absent) + "]: CPU " + std::to_string(absent) +
       " is not online on this machine (" + realtime::format_cpu_list(realtime::online_cpus()) +
       ")"});
  // Online CPUs include those this process does not run on now (isolcpus,
  // taskset): binding to them is checked when it is tried (check_permitted).
  const std::vector<int> online = realtime::online_cpus();
  for (const int cpu : realtime::available_cpus())
    EXPECT_TRUE(std::binary_search(online.begin(), online.end(), cpu)) << cpu;
}

TEST(Realtime, TheReceiveThreadFragmentAsksCycloneForOnePriorityThreadAndNothingElse) {
  EXPECT_EQ(realtime::cyclone_receive_thread_xml(0), "");
  const std::string xml = realtime::cyclone_receive_thread_xml(42);
  for (const char* must :
       {"<MultipleReceiveThreads>false</MultipleReceiveThreads>", "<Thread name=\"recv\">",
        "<Class>realtime</Class>", "<Priority>42</Priority>"})
    EXPECT_NE(xml.find(must), std::string::npos) << must << " in " << xml;
  // It must not widen the network: no interface, peer or multicast setting.
  for (const char* must_not : {"Interface", "Multicast", "Peer", "General", "Discovery"})
    EXPECT_EQ(xml.find(must_not), std::string::npos) << must_not << " in " << xml;

  // Appended after a comma to whatever configuration applies: loopback stays.
  unsetenv("CYCLONEDDS_URI");
  const auto config = dds::resolve_domain_config("", {42, {0}, false});
  EXPECT_EQ(config.text, std::string(dds::loopback_config()) + "," + xml);
  EXPECT_EQ(config.origin, "built-in loopback");
  EXPECT_EQ(config.receive_priority, 42);
  EXPECT_EQ(config.cpus, (std::vector<int>{0}));
  const auto plain = dds::resolve_domain_config("", {0, {}, true});
  EXPECT_EQ(plain.text, dds::loopback_config()) << "no priority, no fragment";
}

/// The calling thread's affinity, as a CPU list.
std::vector<int> thread_cpus() { return realtime::available_cpus(); }

TEST(Realtime, ApplyingBindsTheThreadWithoutAllocating) {
  const std::vector<int> all = realtime::available_cpus();
  ASSERT_FALSE(all.empty());
  const RealtimeOptions options{0, {all.back()}, false};
  std::vector<int> seen;
  std::uint64_t allocated = 1;
  std::thread([&] {
    const std::uint64_t before = testing::allocations_here();
    realtime::apply_to_this_thread(options);
    allocated = testing::allocations_here() - before;
    seen = thread_cpus();
  }).join();
  EXPECT_EQ(seen, options.cpus);
  EXPECT_EQ(allocated, 0u) << "a device's loop may call it";
  EXPECT_EQ(thread_cpus(), all) << "only that thread";

  // ScopedAffinity: bound while it lives, restored after.
  {
    const realtime::ScopedAffinity bound(options.cpus);
    EXPECT_EQ(thread_cpus(), options.cpus);
  }
  EXPECT_EQ(thread_cpus(), all);
}

// SCHED_FIFO when this process may use it (as root); checked the same way
// as palpated checks it. Run as root or not, the refusal is tested below.
TEST(Realtime, APermittedPriorityMakesTheThreadFifo) {
  bool permitted = true;
  try {
    realtime::check_permitted({5, {}, false});
  } catch (const InputError&) {
    permitted = false;
  }
  int policy = -1;
  sched_param param{};
  std::string error;
  std::thread([&] {
    try {
      realtime::apply_to_this_thread({5, {}, false});
    } catch (const InputError& e) {
      error = e.what();
    }
    pthread_getschedparam(pthread_self(), &policy, &param);
  }).join();
  if (permitted) {
    EXPECT_EQ(policy, SCHED_FIFO) << error;
    EXPECT_EQ(param.sched_priority, 5);
  } else {
    EXPECT_EQ(policy, SCHED_OTHER);
    EXPECT_NE(error.find("realtime.priority 5: the kernel refuses SCHED_FIFO"), std::string::npos)
        << error;
  }
}

/// The message of what @p f throws (InputError or ResourceError), run in a
/// child process with @p limit lowered to @p value and, when this process
/// is root, as nobody (so without root's capabilities): this process keeps
/// its own.
template <typename F>
std::string message_without_privilege(int limit, rlim_t value, F f) {
  int pipe_fds[2];
  if (pipe(pipe_fds) != 0) return "pipe failed";
  const pid_t child = fork();
  if (child < 0) return "fork failed";
  if (child == 0) {
    close(pipe_fds[0]);
    const rlimit lowered{value, value};
    setrlimit(static_cast<__rlimit_resource>(limit), &lowered);
    if (geteuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0)) _exit(3);
    std::string message = "no error";
    try {
      f();
    } catch (const std::exception& e) {
      message = e.what();
    }
    (void)!write(pipe_fds[1], message.data(), message.size());
    _exit(0);
  }
  close(pipe_fds[1]);
  std::string message;
  char buffer[1024];
  for (ssize_t n; (n = read(pipe_fds[0], buffer, sizeof buffer)) > 0;)
    message.append(buffer, static_cast<std::size_t>(n));
  close(pipe_fds[0]);
  int status = 0;
  waitpid(child, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return "the child could not drop root";
  return message;
}

// A process without the privilege (RLIMIT_RTPRIO 0, no CAP_SYS_NICE) is
// refused with the way to grant it.
TEST(Realtime, APriorityTheProcessMayNotUseIsRefusedWithTheWayToGrantIt) {
  const std::string message = message_without_privilege(RLIMIT_RTPRIO, 0, [] {
    realtime::check_permitted({50, {}, false}, realtime::kFlagNames);
  });
  for (const char* must :
       {"--rt-priority 50: the kernel refuses SCHED_FIFO at this priority", "RLIMIT_RTPRIO 0",
        "without CAP_SYS_NICE", "LimitRTPRIO=50 and RestrictRealtime=no", "rtprio 50",
        "(--rt-priority 0;"})
    EXPECT_NE(message.find(must), std::string::npos) << must << " in: " << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

// Likewise memory it may not lock (RLIMIT_MEMLOCK 64 kB, no CAP_IPC_LOCK):
// a ResourceError (exit 4) naming the limit and how to raise it.
TEST(Realtime, MemoryTheProcessMayNotLockIsRefusedWithTheLimit) {
  const std::string message = message_without_privilege(RLIMIT_MEMLOCK, 65536, [] {
    try {
      realtime::lock_memory({0, {}, true}, realtime::kFlagNames);
    } catch (const ResourceError& e) {
      throw std::runtime_error(std::string("ResourceError: ") + e.what());
    }
  });
  EXPECT_EQ(message.rfind("ResourceError: --lock-memory: ", 0), 0u) << message;
#ifdef PALPATE_SHADOW_MEMORY
  EXPECT_NE(message.find("AddressSanitizer or ThreadSanitizer"), std::string::npos) << message;
#else
  for (const char* must :
       {"mlockall failed", "may lock 65536 bytes (RLIMIT_MEMLOCK)", "without CAP_IPC_LOCK",
        "LimitMEMLOCK=infinity", "leave --lock-memory off"})
    EXPECT_NE(message.find(must), std::string::npos) << must << " in: " << message;
#endif
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

}  // namespace
}  // namespace palpate
