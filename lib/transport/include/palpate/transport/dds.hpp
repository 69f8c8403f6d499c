#pragma once
/// @file
/// Cyclone DDS plumbing shared by palpated and its clients: RAII handles, one
/// status check, the domain configuration (loopback unless the user gives
/// one), and the topics with their QoS (docs/dds.md). Both sides take the
/// QoS from here so that they always match.

#include <dds/dds.h>

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "palpate/transport/realtime.hpp"

namespace palpate::dds {

/// Owns a dds_entity_t; dds_delete on destruction (children go with it).
class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t handle) : handle_(handle) {}
  Entity(Entity&& other) noexcept : handle_(other.release()) {}
  Entity& operator=(Entity&& other) noexcept {
    if (this != &other) reset(other.release());
    return *this;
  }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  ~Entity() { reset(); }

  dds_entity_t get() const { return handle_; }
  explicit operator bool() const { return handle_ > 0; }
  dds_entity_t release() { return std::exchange(handle_, 0); }
  void reset(dds_entity_t handle = 0) {
    if (handle_ > 0) dds_delete(handle_);
    handle_ = handle;
  }

 private:
  dds_entity_t handle_ = 0;
};

/// Throws SystemError "<what>: <Cyclone's message>" when @p status is an
/// error code (negative), InputError when it is DDS Security's "not allowed"
/// (the participant's permissions); returns it otherwise (handles are positive).
dds_return_t check(dds_return_t status, std::string_view what);

/// Owns a dds_qos_t.
struct QosDeleter {
  void operator()(dds_qos_t* qos) const { dds_delete_qos(qos); }
};
using Qos = std::unique_ptr<dds_qos_t, QosDeleter>;

/// The configuration palpate uses when the user gives none: loopback only,
/// no multicast, unicast discovery to 127.0.0.1.
std::string_view loopback_config();

/// Where a process's DDS configuration comes from.
struct DomainConfig {
  std::string text;    ///< passed to dds_create_domain: XML or file:// URIs
  std::string origin;  ///< for logs: "built-in loopback", "--dds-config", "CYCLONEDDS_URI"
  /// SCHED_FIFO priority of Cyclone's receive thread (0: normal
  /// scheduling), asked for by a fragment appended to `text`
  /// (realtime::cyclone_receive_thread_xml).
  int receive_priority = 0;
  /// CPUs of Cyclone's threads (empty: any): the domain is created by a
  /// thread bound to them, and its threads inherit them.
  std::vector<int> cpus{};
};

/// The user's configuration when there is one (@p user_config: a file path,
/// a file:// URI or an XML fragment; then the CYCLONEDDS_URI environment
/// variable), else loopback_config(); with @p realtime's priority and CPUs
/// for Cyclone's receive thread (the priority as a configuration fragment
/// appended after a comma, which Cyclone reads last: it overrides the same
/// settings of the first part; nothing about interfaces or multicast).
/// @throws InputError when @p user_config names a file that cannot be read.
DomainConfig resolve_domain_config(const std::string& user_config,
                                   const RealtimeOptions& realtime = {});

/// The domain entity of @p domain_id in this process, created with @p config
/// on first use and shared by every participant of the process (Cyclone
/// accepts one dds_create_domain per domain and process): the first
/// participant's configuration, real-time settings included, holds for all.
std::shared_ptr<Entity> acquire_domain(std::uint32_t domain_id, const DomainConfig& config);

/// A participant and the domain it lives in (kept alive as long as it).
struct Participant {
  DomainConfig config;             ///< where the domain's configuration came from
  std::shared_ptr<Entity> domain;  ///< declared before entity: outlives it
  Entity entity;
  dds_entity_t get() const { return entity.get(); }
};

/// A participant of domain @p domain_id (acquired with @p config).
/// @throws InputError when a configuration given by the user is the cause
/// (with DDS Security: this participant's own certificate, key, permissions
/// or governance), SystemError otherwise.
dds_entity_t create_participant(std::uint32_t domain_id, const DomainConfig& config);

/// Joins domain @p domain_id with the configuration resolve_domain_config()
/// gives for @p user_config and @p realtime: what every client of palpated
/// does first.
/// @throws InputError (configuration) or SystemError naming what failed.
Participant join_domain(std::uint32_t domain_id, const std::string& user_config,
                        const RealtimeOptions& realtime = {});

// ------------------------------------------------------------------ topics

/// Creates (or finds) topic @p name of @p type on @p participant.
/// @throws SystemError naming the topic.
dds_entity_t topic(dds_entity_t participant, const dds_topic_descriptor_t* type, const char* name);

inline constexpr const char* kModelTopic = "palpate_model";
inline constexpr const char* kRequestTopic = "palpate_request";
inline constexpr const char* kReplyTopic = "palpate_reply";
inline constexpr const char* kSurfaceTopic = "palpate_surface";
inline constexpr const char* kStatusTopic = "palpate_status";
inline constexpr const char* kToolPoseTopic = "palpate_tool_pose";
inline constexpr const char* kToolFeedbackTopic = "palpate_tool_feedback";
inline constexpr const char* kToolEventTopic = "palpate_tool_event";
inline constexpr const char* kToolCommandTopic = "palpate_tool_command";
inline constexpr const char* kToolNoticeTopic = "palpate_tool_notice";
inline constexpr const char* kToolResponseTopic = "palpate_tool_response";
inline constexpr const char* kToolRenderedTopic = "palpate_tool_rendered";

/// Partition of the replies to client @p client_id.
std::string reply_partition(std::string_view client_id);
inline constexpr std::string_view kReplyPartitionPrefix = "palpate.client.";
/// Partition of tool @p tool_id's responses and events (palpate_tool_response,
/// palpate_tool_event): a station reads its own tools' only.
std::string tool_partition(std::string_view tool_id);
inline constexpr std::string_view kToolPartitionPrefix = "palpate.tool.";

/// Model descriptions: reliable, transient-local, keep-last 1 per model.
Qos model_qos();
/// Requests and replies: reliable, volatile, keep-last 16, no latency budget.
Qos request_reply_qos();
/// Surface stream: reliable, transient-local, keep-last 1 per model.
Qos surface_qos();
/// Status heartbeat: reliable, volatile, keep-last 1.
Qos status_qos();
/// Tool poses and feedback, the 1 kHz loop: best effort, volatile, keep-last
/// 1 per tool, no latency budget. A lost sample is superseded by the next.
Qos tool_stream_qos();
/// Tool events (grasp, release, ...): reliable, volatile, keep-last 64 per tool.
Qos tool_event_qos();
/// Tool commands (end of a session): reliable, volatile, keep-last 8 per tool.
Qos tool_command_qos();
/// Tool notices (a refused pose and why): reliable, volatile, keep-last 16 per tool.
Qos tool_notice_qos();

}  // namespace palpate::dds
