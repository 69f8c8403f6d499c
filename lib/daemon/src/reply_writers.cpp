#include "reply_writers.hpp"

#include <spdlog/spdlog.h>

#include <cstring>
#include <string>
#include <string_view>

#include "palpate.h"

namespace palpate::daemon {

ReplyWriters::ReplyWriters(dds_entity_t participant, dds_entity_t reply_topic, int max_clients)
    : participant_(participant), reply_topic_(reply_topic), max_clients_(max_clients) {
  writers_.reserve(static_cast<std::size_t>(max_clients));
}

bool ReplyWriters::names_a_partition(const char* client_id) {
  return client_id[0] != '\0' && std::strpbrk(client_id, "*?[]\\") == nullptr;
}

std::size_t ReplyWriters::count() {
  const std::lock_guard lock(mutex_);
  return writers_.size();
}

ReplyWriters::Writer* ReplyWriters::writer_for(const char* client_id) {
  for (auto& w : writers_)
    if (std::strcmp(w.id, client_id) == 0) return &w;
  if (!names_a_partition(client_id)) return nullptr;
  Writer* slot = nullptr;
  if (writers_.size() < writers_.capacity()) {
    slot = &writers_.emplace_back();
  } else {
    // Reuse the writer of a client that has gone (no matched reader).
    for (auto& w : writers_) {
      dds_publication_matched_status_t status{};
      if (dds_get_publication_matched_status(w.writer.get(), &status) == DDS_RETCODE_OK &&
          status.current_count == 0) {
        spdlog::info("event=client_forgotten client={}", w.id);
        w.writer.reset();
        w.publisher.reset();
        slot = &w;
        break;
      }
    }
    if (slot == nullptr) {
      spdlog::warn("event=too_many_clients client={} max_clients={}", client_id, max_clients_);
      return nullptr;
    }
  }
  const std::size_t length = strnlen(client_id, sizeof slot->id - 1);
  std::memcpy(slot->id, client_id, length);
  slot->id[length] = '\0';
  const std::string partition = dds::reply_partition(client_id);
  const char* partitions[] = {partition.c_str()};
  dds::Qos qos(dds_create_qos());
  dds_qset_partition(qos.get(), 1, partitions);
  const dds_entity_t publisher = dds_create_publisher(participant_, qos.get(), nullptr);
  if (publisher < 0) {
    spdlog::error("event=dds_error what=\"creating the reply publisher of client {}\" error={}",
                  client_id, dds_strretcode(publisher));
    slot->id[0] = '\0';
    return nullptr;
  }
  slot->publisher = dds::Entity(publisher);
  const dds_entity_t writer =
      dds_create_writer(publisher, reply_topic_, dds::request_reply_qos().get(), nullptr);
  if (writer < 0) {
    spdlog::error("event=dds_error what=\"creating the reply writer of client {}\" error={}",
                  client_id, dds_strretcode(writer));
    slot->publisher.reset();
    slot->id[0] = '\0';
    return nullptr;
  }
  slot->writer = dds::Entity(writer);
  spdlog::info("event=client_added client={} partition={}", client_id, partition);
  return slot;
}

void ReplyWriters::write(const Writer* writer, const palpate_ConstraintReply& reply) {
  if (writer == nullptr) {
    spdlog::warn(
        "event=reply_dropped client=\"{}\" request={} reason=\"no reply writer for this client "
        "id\"",
        reply.client_id, reply.request_id);
  } else if (const dds_return_t rc = dds_write(writer->writer.get(), &reply); rc < 0) {
    spdlog::error("event=dds_error what=\"writing a reply\" client={} error={}", reply.client_id,
                  dds_strretcode(rc));
  }
}

void ReplyWriters::discover(dds_entity_t subscriptions_reader) {
  // A client's reply reader announces its partition "palpate.client.<id>":
  // the reply writer is made before its first request.
  void* samples[8] = {};
  dds_sample_info_t infos[8];
  const dds_return_t n = dds_take(subscriptions_reader, samples, infos, 8, 8);
  if (n <= 0) return;
  for (dds_return_t i = 0; i < n; ++i) {
    if (!infos[i].valid_data || infos[i].instance_state != DDS_IST_ALIVE) continue;
    const auto* endpoint = static_cast<const dds_builtintopic_endpoint_t*>(samples[i]);
    if (endpoint->topic_name == nullptr || std::strcmp(endpoint->topic_name, dds::kReplyTopic) != 0)
      continue;
    std::uint32_t count = 0;
    char** names = nullptr;
    if (!dds_qget_partition(endpoint->qos, &count, &names)) continue;
    for (std::uint32_t p = 0; p < count; ++p) {
      const std::string_view name(names[p]);
      if (name.starts_with(dds::kReplyPartitionPrefix) &&
          name.size() > dds::kReplyPartitionPrefix.size() &&
          name.size() - dds::kReplyPartitionPrefix.size() < 64) {
        const std::lock_guard lock(mutex_);
        writer_for(names[p] + dds::kReplyPartitionPrefix.size());
      }
      dds_free(names[p]);
    }
    dds_free(names);
  }
  dds_return_loan(subscriptions_reader, samples, n);
}

}  // namespace palpate::daemon
