#pragma once
// Private to palpate_daemon: constraint requests in, replies out
// (docs/dds.md, "Requests and replies").

#include <dds/dds.h>

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "daemon_stats.hpp"
#include "palpate.h"
#include "palpate/transport/dds.hpp"
#include "reply_writers.hpp"
#include "served_model.hpp"
#include "serving_thread.hpp"

namespace palpate::daemon {

/// Serves requests in the request reader's data-available listener, on
/// Cyclone's receive thread: no thread wakes up between a request's arrival
/// and its reply (take, validate, solve, reply). Cyclone calls one reader's
/// listener from one thread at a time. Or, with realtime.serve = "waitset" or
/// "busy", on palpated's serving thread (ServingThread), which calls the same
/// function. The path allocates nothing of its own
/// and never throws: every failure is an error reply.
class RequestServer {
 public:
  /// Buffers sized for @p models (largest surface) and @p max_constraints.
  RequestServer(const std::vector<std::unique_ptr<ServedModel>>& models, std::string served_ids,
                ReplyWriters& replies, int max_constraints);
  ~RequestServer();
  RequestServer(const RequestServer&) = delete;
  RequestServer& operator=(const RequestServer&) = delete;

  /// Creates the request reader of @p request_topic with its listener:
  /// requests are served from then on (possibly before this returns). With
  /// @p serving_thread, the reader has no listener: that thread serves it
  /// once started.
  void listen(dds_entity_t participant, dds_entity_t request_topic,
              ServingThread* serving_thread = nullptr);
  /// Deletes the reader: no listener call after this returns.
  void stop();

  /// Requests served, error replies, and each request's solve time and
  /// request-to-reply time (µs).
  ServerStats& stats() { return stats_; }

 private:
  static constexpr int kBatch = 16;  // requests taken per dds_take
  static void on_requests(dds_entity_t reader, void* arg);
  void serve(dds_entity_t reader);
  void handle(const palpate_ConstraintRequest& request, const dds_sample_info_t& info);
  RequestStatus solve(const palpate_ConstraintRequest& request);
  /// The request on @p served's solver, linear or warped, into reply_.
  template <typename Solver>
  RequestStatus answer(const palpate_ConstraintRequest& request, ServedModel& served,
                       Solver& solver);

  const std::vector<std::unique_ptr<ServedModel>>& models_;
  std::string served_ids_;  // "a, b" for error messages
  ReplyWriters& replies_;
  dds::Entity reader_;
  // Released before the listener is attached, acquired by it: what the
  // constructor set up happens before its first call in C++'s memory model,
  // not only through Cyclone's internal ordering (which ThreadSanitizer
  // cannot see in the uninstrumented libddsc).
  std::atomic<bool> listening_{false};

  // Buffers, sized once.
  std::vector<palpate_ConstraintRequest> requests_;
  std::vector<void*> request_pointers_;
  std::vector<dds_sample_info_t> request_infos_;
  palpate_ConstraintReply reply_{};
  std::vector<palpate_ConstraintResult> reply_results_;
  std::vector<double> reply_surface_;
  char message_[256] = {};  // a refusal's message, formatted here (no allocation)

  ServerStats stats_;
};

}  // namespace palpate::daemon
