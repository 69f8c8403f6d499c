#pragma once
// Private to palpate_daemon: a mutex with priority inheritance, for the
// state the serving thread shares with threads of normal priority (the
// stream thread's watchdog and heartbeat, the discovery thread). When a
// real-time serving thread waits for one of them, the holder runs at the
// waiter's priority until it lets go: a loaded machine cannot hold the
// serving thread behind a holder it does not schedule (docs/realtime.md).
// Uncontended, it locks and unlocks in user space like std::mutex.

#include <pthread.h>

namespace palpate::daemon {

class PiMutex {
 public:
  PiMutex() {
    pthread_mutexattr_t attr;
    pthread_mutexattr_init(&attr);
    pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT);
    pthread_mutex_init(&mutex_, &attr);
    pthread_mutexattr_destroy(&attr);
  }
  ~PiMutex() { pthread_mutex_destroy(&mutex_); }
  PiMutex(const PiMutex&) = delete;
  PiMutex& operator=(const PiMutex&) = delete;

  void lock() { pthread_mutex_lock(&mutex_); }
  bool try_lock() { return pthread_mutex_trylock(&mutex_) == 0; }
  void unlock() { pthread_mutex_unlock(&mutex_); }

 private:
  pthread_mutex_t mutex_;
};

}  // namespace palpate::daemon
