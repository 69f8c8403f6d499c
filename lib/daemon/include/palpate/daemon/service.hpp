#pragma once
/// @file
/// palpated's service: the loaded models served over DDS (docs/dds.md).
///
/// Threads: requests are served (take, validate, solve, reply) in the request
/// reader's listener, on Cyclone's receive thread, so that no thread wakes up
/// between a request and its reply; the caller of run() follows client
/// discovery; a third thread publishes the surface stream at the visual rate
/// and the status heartbeat. The request path allocates
/// nothing of its own and never throws: every failure is an error reply.

#include <memory>

#include "palpate/daemon/daemon_config.hpp"

namespace palpate {

class Service {
 public:
  /// Loads every model (InputError on a missing or malformed file), joins the
  /// DDS domain and publishes the model descriptions.
  /// @throws InputError, SystemError
  explicit Service(const DaemonConfig& config);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// Serves until request_stop(). @throws SystemError if DDS fails.
  void run();
  /// Makes run() return soon; callable from any thread (not from a signal handler).
  void request_stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate
