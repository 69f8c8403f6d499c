#pragma once
// Private to palpate_daemon: one reply writer per client, in the client's
// own partition "palpate.client.<id>", so that a reply reaches only the
// client that asked (docs/dds.md, "Requests and replies").

#include <dds/dds.h>

#include <chrono>
#include <mutex>
#include <vector>

#include "palpate.h"
#include "palpate/transport/dds.hpp"
#include "pi_mutex.hpp"

namespace palpate::daemon {

class ReplyWriters {
 public:
  /// Writers of @p reply_topic in @p participant, for at most @p max_clients
  /// clients at once (a gone client's writer is reused).
  ReplyWriters(dds_entity_t participant, dds_entity_t reply_topic, int max_clients);

  /// A client id can name a reply partition: not empty, no partition wildcards.
  static bool names_a_partition(const char* client_id);

  /// Makes the writers of the clients whose reply readers discovery
  /// announced (samples of DCPSSubscription in @p subscriptions_reader),
  /// before their first request.
  void discover(dds_entity_t subscriptions_reader);

  /// Writes @p reply to its client (reply.client_id), stamping
  /// reply.solve_ns with the time since @p start just before the write.
  /// A client without a writer (too many clients, an id that names no
  /// partition) or a failed write is logged; the reply is dropped.
  template <typename Clock>
  void send(palpate_ConstraintReply& reply, typename Clock::time_point start);

  /// Clients with a writer.
  std::size_t count();

 private:
  struct Writer {
    char id[64] = {};
    dds::Entity publisher;
    dds::Entity writer;
  };
  Writer* writer_for(const char* client_id);  // with mutex_ held
  void write(const Writer* writer, const palpate_ConstraintReply& reply);

  dds_entity_t participant_, reply_topic_;
  int max_clients_;
  // Discovery (the service thread) and requests (the listener) both add clients.
  PiMutex mutex_;
  std::vector<Writer> writers_;
};

template <typename Clock>
void ReplyWriters::send(palpate_ConstraintReply& reply, typename Clock::time_point start) {
  const std::lock_guard lock(mutex_);
  const Writer* writer = writer_for(reply.client_id);
  reply.solve_ns = static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start).count());
  write(writer, reply);
}

}  // namespace palpate::daemon
