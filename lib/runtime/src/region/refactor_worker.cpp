#include "palpate/runtime/region/refactor_worker.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

namespace palpate::detail {

bool CutQueue::offer(std::span<const int> vertices) {
  const std::lock_guard lock(mutex_);
  if (closed_) return false;
  vertices_.insert(vertices_.end(), vertices.begin(), vertices.end());
  return true;
}

bool CutQueue::take(std::vector<int>& batch) {
  batch.clear();
  const std::lock_guard lock(mutex_);
  if (vertices_.empty()) {
    closed_ = true;
    return false;
  }
  batch.swap(vertices_);
  return true;
}

void become_background_thread() {
  sched_param normal{};
  normal.sched_priority = 0;
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  cpu_set_t every;
  CPU_ZERO(&every);
  const long cpus = sysconf(_SC_NPROCESSORS_CONF);
  for (long c = 0; c < cpus && c < CPU_SETSIZE; ++c) CPU_SET(static_cast<int>(c), &every);
  pthread_setaffinity_np(pthread_self(), sizeof every, &every);
  setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 10);
}

}  // namespace palpate::detail
