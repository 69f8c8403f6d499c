#pragma once
/// @file
/// A C++ client of palpated (docs/dds.md): model descriptions, constraint
/// requests and their replies, the surface stream and the status heartbeat.
/// Used by palpate-client, the tests and the benchmarks; an application may
/// use it or speak the IDL types directly.

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "palpate/transport/messages.hpp"
#include "palpate/transport/presence.hpp"
#include "palpate/transport/realtime.hpp"

namespace palpate {

struct ClientOptions {
  std::string client_id;  ///< unique per client; [A-Za-z0-9_.-], 1..63 characters
  std::uint32_t domain_id = 0;
  std::string dds_config;  ///< as palpated's dds.config; empty: loopback (or CYCLONEDDS_URI)
  bool subscribe_surface = false;  ///< also read the surface stream
  bool subscribe_status = false;   ///< also read the status heartbeat
  /// Wait for replies by polling (yielding the CPU between polls) instead of
  /// sleeping on a waitset: saves the wake-up of the waiting thread, costs
  /// its core while waiting. What a 1 kHz haptic loop does anyway.
  bool busy_wait = false;
  /// Silence of palpated's status heartbeat after which daemon_presence()
  /// says it is lost; 0: 3 heartbeat periods (as measured) + 1 s, i.e.
  /// 4 s at the default 1 Hz (docs/faults.md).
  std::chrono::milliseconds daemon_timeout{0};
  /// Real-time operation, as ToolClientOptions::realtime: Cyclone's receive
  /// thread gets the priority and CPUs, memory is locked once the client is
  /// made, and the requesting thread applies them to itself with
  /// realtime::apply_to_this_thread(options.realtime).
  RealtimeOptions realtime{};
};

class Client {
 public:
  /// Joins the domain and creates the readers and writers.
  /// @throws InputError for a bad client id, SystemError if DDS fails.
  explicit Client(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  const std::string& id() const;

  /// Waits until a daemon reads this client's requests and writes its replies.
  /// Requests sent before may be lost. @returns false on timeout.
  bool wait_for_service(std::chrono::milliseconds timeout);
  /// The description of @p model_id (late joiners get it too). std::nullopt
  /// on timeout, or as soon as palpated's heartbeat says every model it
  /// serves was described and none is @p model_id (within about a second):
  /// models_seen() then lists the served ones.
  std::optional<ModelInfo> wait_for_model(const std::string& model_id,
                                          std::chrono::milliseconds timeout);
  /// Ids of every model whose description came so far, sorted.
  std::vector<std::string> models_seen() const;

  /// Sends a request; returns its id.
  std::uint64_t send(const std::string& model_id, std::span<const ConstraintSpec> constraints,
                     bool want_surface = false, bool update_state = true);
  /// The reply to @p request_id; replies to other ids are dropped. std::nullopt on timeout.
  std::optional<Reply> wait_reply(std::uint64_t request_id, std::chrono::milliseconds timeout);
  /// Replies received that were addressed to another client (partitions
  /// should make this 0; the tests check it).
  std::uint64_t foreign_replies() const;
  /// wait_for_service, send and wait_reply, all within @p timeout: the
  /// first request of a new client is not lost to discovery.
  /// @throws SystemError on timeout, saying whether palpated was not
  /// matched or matched and did not answer.
  Reply request(const std::string& model_id, std::span<const ConstraintSpec> constraints,
                bool want_surface = false, bool update_state = true,
                std::chrono::milliseconds timeout = std::chrono::seconds(5));

  /// The first surface sample of @p model_id with sequence_number ≥ @p min_sequence
  /// and (when non-zero) source_request_id == @p request_id. Needs subscribe_surface.
  std::optional<SurfaceSample> wait_surface(const std::string& model_id, std::uint64_t min_sequence,
                                            std::uint64_t request_id,
                                            std::chrono::milliseconds timeout);
  /// The next status heartbeat. Needs subscribe_status.
  std::optional<StatusSample> wait_status(std::chrono::milliseconds timeout);

  /// palpated's presence now, from the heartbeats taken so far (takes those
  /// that came; does not wait). While it is lost, requests get no reply
  /// (request() times out): send them again once it is back; a restarted
  /// palpated answers this same client (docs/faults.md).
  DaemonPresence daemon_presence();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate
