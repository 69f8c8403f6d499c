#include "palpate/transport/dds.hpp"

#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "palpate/core/error.hpp"
#include "palpate_loopback_config.h"

namespace palpate::dds {

dds_return_t check(dds_return_t status, std::string_view what) {
  // DDS Security refused this participant an entity its own permissions do
  // not grant: a configuration matter, not a system failure.
  if (status == DDS_RETCODE_NOT_ALLOWED_BY_SECURITY)
    throw InputError(std::string(what) + ": " + dds_strretcode(status) +
                     "; this participant's DDS Security permissions do not allow it "
                     "(docs/security.md)");
  if (status < 0) throw SystemError(std::string(what) + ": " + dds_strretcode(status));
  return status;
}

std::string_view loopback_config() { return PALPATE_LOOPBACK_CONFIG; }

namespace {
DomainConfig resolve_base_config(const std::string& user_config) {
  if (!user_config.empty()) {
    const bool is_xml = user_config.find('<') != std::string::npos;
    const bool is_uri = user_config.rfind("file://", 0) == 0;
    if (!is_xml && !is_uri) {
      std::ifstream file(user_config);
      if (!file)
        throw InputError(
            "DDS configuration '" + user_config +
            "' cannot be read; give a Cyclone DDS XML file, a file:// URI or an XML fragment");
      return {"file://" + user_config, "file " + user_config};
    }
    return {user_config, "user configuration"};
  }
  if (const char* uri = std::getenv("CYCLONEDDS_URI"); uri != nullptr && *uri != '\0')
    return {uri, "CYCLONEDDS_URI"};
  return {std::string(loopback_config()), "built-in loopback"};
}
}  // namespace

DomainConfig resolve_domain_config(const std::string& user_config,
                                   const RealtimeOptions& realtime) {
  DomainConfig config = resolve_base_config(user_config);
  if (realtime.priority > 0) {
    config.text += ',';
    config.text += realtime::cyclone_receive_thread_xml(realtime.priority);
    config.receive_priority = realtime.priority;
  }
  config.cpus = realtime.cpus;
  return config;
}

std::shared_ptr<Entity> acquire_domain(std::uint32_t domain_id, const DomainConfig& config) {
  static std::mutex mutex;
  static std::map<std::uint32_t, std::weak_ptr<Entity>> domains;
  const std::lock_guard lock(mutex);
  if (auto existing = domains[domain_id].lock()) return existing;
  // Cyclone's threads, started here, inherit this thread's CPUs.
  const realtime::ScopedAffinity on_cpus(config.cpus);
  auto domain = std::make_shared<Entity>(
      check(dds_create_domain(domain_id, config.text.c_str()),
            "creating DDS domain " + std::to_string(domain_id) + " (" + config.origin + ")"));
  domains[domain_id] = domain;
  return domain;
}

Participant join_domain(std::uint32_t domain_id, const std::string& user_config,
                        const RealtimeOptions& realtime) {
  Participant p;
  p.config = resolve_domain_config(user_config, realtime);
  p.domain = acquire_domain(domain_id, p.config);
  p.entity = Entity(create_participant(domain_id, p.config));
  return p;
}

dds_entity_t create_participant(std::uint32_t domain_id, const DomainConfig& config) {
  const dds_entity_t participant = dds_create_participant(domain_id, nullptr, nullptr);
  // With DDS Security, Cyclone refuses the participant when its own
  // credentials do not hold (certificate, key, permissions, governance) and
  // prints why on stderr just before.
  if (participant < 0 && config.origin != "built-in loopback")
    throw InputError("creating the DDS participant: " + std::string(dds_strretcode(participant)) +
                     "; check the Cyclone DDS configuration (" + config.origin +
                     ") and, with DDS Security, the files it names (docs/security.md)");
  return check(participant, "creating the DDS participant");
}

dds_entity_t topic(dds_entity_t participant, const dds_topic_descriptor_t* type, const char* name) {
  return check(dds_create_topic(participant, type, name, nullptr, nullptr),
               std::string("creating topic ") + name);
}

std::string reply_partition(std::string_view client_id) {
  return std::string(kReplyPartitionPrefix) + std::string(client_id);
}

std::string tool_partition(std::string_view tool_id) {
  return std::string(kToolPartitionPrefix) + std::string(tool_id);
}

namespace {
Qos make_qos(dds_durability_kind_t durability, std::int32_t depth) {
  Qos qos(dds_create_qos());
  dds_qset_reliability(qos.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_durability(qos.get(), durability);
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, depth);
  return qos;
}
}  // namespace

Qos model_qos() { return make_qos(DDS_DURABILITY_TRANSIENT_LOCAL, 1); }
Qos request_reply_qos() {
  Qos qos = make_qos(DDS_DURABILITY_VOLATILE, 16);
  dds_qset_latency_budget(qos.get(), 0);
  return qos;
}
Qos surface_qos() { return make_qos(DDS_DURABILITY_TRANSIENT_LOCAL, 1); }
Qos status_qos() { return make_qos(DDS_DURABILITY_VOLATILE, 1); }
Qos tool_stream_qos() {
  Qos qos(dds_create_qos());
  dds_qset_reliability(qos.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(qos.get(), DDS_DURABILITY_VOLATILE);
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 1);
  dds_qset_latency_budget(qos.get(), 0);
  return qos;
}
Qos tool_event_qos() { return make_qos(DDS_DURABILITY_VOLATILE, 64); }
Qos tool_command_qos() { return make_qos(DDS_DURABILITY_VOLATILE, 8); }
Qos tool_notice_qos() { return make_qos(DDS_DURABILITY_VOLATILE, 16); }

}  // namespace palpate::dds
