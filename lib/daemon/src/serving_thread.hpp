#pragma once
// Private to palpate_daemon: palpated's own serving thread (realtime.serve =
// "waitset" or "busy", docs/realtime.md): the request, pose and command
// readers are served on it by the functions their listeners would run, so
// that palpated can give that thread a priority and CPUs.

#include <dds/dds.h>

#include <atomic>
#include <thread>
#include <vector>

#include "palpate/daemon/daemon_config.hpp"
#include "palpate/transport/dds.hpp"

namespace palpate::daemon {

class ServingThread {
 public:
  /// @p mode: kWaitset (sleeps on a waitset of the readers) or kBusy (polls
  /// them, yielding the CPU between rounds). @p realtime: the thread's
  /// priority and CPUs.
  ServingThread(dds_entity_t participant, ServeMode mode, const RealtimeOptions& realtime);
  ~ServingThread();
  ServingThread(const ServingThread&) = delete;
  ServingThread& operator=(const ServingThread&) = delete;

  /// Serves @p reader with @p serve(reader, @p arg) whenever it has data
  /// (the signature of a data-available listener). Before start().
  void add(dds_entity_t reader, dds_on_data_available_fn serve, void* arg);
  /// Starts the thread, which first applies the real-time options to
  /// itself. @throws InputError when the kernel refuses them (the thread is
  /// then gone).
  void start();
  /// Stops and joins the thread: no serve call after this returns.
  void stop();

 private:
  struct Reader {
    dds_entity_t reader;
    dds_on_data_available_fn serve;
    void* arg;
  };
  void run_waitset();
  void run_busy();

  ServeMode mode_;
  RealtimeOptions realtime_;
  std::vector<Reader> readers_;
  dds::Entity waitset_, wake_;
  std::atomic<bool> stopping_{false};
  std::thread thread_;
};

}  // namespace palpate::daemon
