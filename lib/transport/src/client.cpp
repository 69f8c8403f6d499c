#include "palpate/transport/client.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>

#include "client_common.hpp"
#include "palpate.h"
#include "palpate/core/error.hpp"
#include "palpate/core/ids.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate {

namespace {

using Clock = detail::ClientClock;
using detail::WaitableReader;

void check_client_id(const std::string& id) {
  if (!is_valid_id(id))
    throw InputError("client id '" + id +
                     "': expected 1 to 63 characters among A-Z a-z 0-9 _ - . (it names the "
                     "reply partition)");
}

}  // namespace

struct Client::Impl {
  ClientOptions options;
  dds::Participant participant;
  dds_entity_t request_writer = 0;
  detail::ModelDescriptions models;
  WaitableReader replies, surfaces, statuses;
  detail::DaemonWatch watch;
  std::uint64_t next_request_id = 1;
  std::uint64_t foreign_replies = 0;
  palpate_ConstraintRequest request{};
  std::vector<palpate_Constraint> constraints;
};

Client::Client(const ClientOptions& options) : impl_(std::make_unique<Impl>()) {
  check_client_id(options.client_id);
  Impl& c = *impl_;
  c.options = options;
  realtime::validate(options.realtime);
  realtime::check_permitted(options.realtime);
  c.participant = dds::join_domain(options.domain_id, options.dds_config, options.realtime);
  const dds_entity_t p = c.participant.get();
  auto topic = [p](const dds_topic_descriptor_t* type, const char* name) {
    return dds::topic(p, type, name);
  };
  c.models = detail::ModelDescriptions(p);
  c.request_writer =
      dds::check(dds_create_writer(p, topic(&palpate_ConstraintRequest_desc, dds::kRequestTopic),
                                   dds::request_reply_qos().get(), nullptr),
                 "creating the request writer");
  // Replies come only in this client's partition.
  const std::string partition = dds::reply_partition(options.client_id);
  const char* partitions[] = {partition.c_str()};
  dds::Qos subscriber_qos(dds_create_qos());
  dds_qset_partition(subscriber_qos.get(), 1, partitions);
  const dds_entity_t subscriber = dds::check(
      dds_create_subscriber(p, subscriber_qos.get(), nullptr), "creating the reply subscriber");
  c.replies = WaitableReader(p, subscriber, topic(&palpate_ConstraintReply_desc, dds::kReplyTopic),
                             dds::request_reply_qos().get(), "creating the reply reader");
  c.replies.busy_wait = options.busy_wait;
  if (options.subscribe_surface)
    c.surfaces = WaitableReader(p, p, topic(&palpate_SurfaceDisplacement_desc, dds::kSurfaceTopic),
                                dds::surface_qos().get(), "creating the surface reader");
  const dds_entity_t status_topic = topic(&palpate_DaemonStatus_desc, dds::kStatusTopic);
  if (options.subscribe_status)
    c.statuses =
        WaitableReader(p, p, status_topic, dds::status_qos().get(), "creating the status reader");
  c.watch = detail::DaemonWatch(p, status_topic, options.daemon_timeout);
  realtime::lock_memory(options.realtime);
}

Client::~Client() = default;

const std::string& Client::id() const { return impl_->options.client_id; }

bool Client::wait_for_service(std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    dds_publication_matched_status_t writer{};
    dds_subscription_matched_status_t reader{};
    dds_get_publication_matched_status(impl_->request_writer, &writer);
    dds_get_subscription_matched_status(impl_->replies.reader.get(), &reader);
    if (writer.current_count > 0 && reader.current_count > 0) return true;
    if (Clock::now() >= deadline) return false;
    dds_sleepfor(DDS_MSECS(5));
  }
}

std::optional<ModelInfo> Client::wait_for_model(const std::string& model_id,
                                                std::chrono::milliseconds timeout) {
  return impl_->models.wait_for(model_id, Clock::now() + timeout, &impl_->watch);
}

std::vector<std::string> Client::models_seen() const { return impl_->models.known_ids(); }

std::uint64_t Client::send(const std::string& model_id, std::span<const ConstraintSpec> constraints,
                           bool want_surface, bool update_state) {
  Impl& c = *impl_;
  palpate_ConstraintRequest& r = c.request;
  wire::to_idl(c.options.client_id, model_id, c.next_request_id++, constraints, want_surface,
               update_state, c.constraints, r);
  dds::check(dds_write(c.request_writer, &r), "sending a request");
  return r.request_id;
}

std::optional<Reply> Client::wait_reply(std::uint64_t request_id,
                                        std::chrono::milliseconds timeout) {
  std::optional<Reply> reply;
  Impl& c = *impl_;
  c.replies.take_until<palpate_ConstraintReply>(
      Clock::now() + timeout, [&](const palpate_ConstraintReply& r) {
        if (std::strncmp(r.client_id, c.options.client_id.c_str(), sizeof r.client_id) != 0) {
          ++c.foreign_replies;
          return false;
        }
        if (r.request_id != request_id) return false;
        reply = wire::from_idl(r);
        return true;
      });
  return reply;
}

std::uint64_t Client::foreign_replies() const { return impl_->foreign_replies; }

Reply Client::request(const std::string& model_id, std::span<const ConstraintSpec> constraints,
                      bool want_surface, bool update_state, std::chrono::milliseconds timeout) {
  // A request sent before palpated's reply writer has matched this client's
  // reply reader gets a reply nobody receives (docs/dds.md, "Reply
  // routing"): a first request right after the model was described lost it
  // on about half the runs. So the request waits for the match first, out
  // of its own timeout (two status reads when matched already).
  const auto deadline = Clock::now() + timeout;
  if (!wait_for_service(timeout))
    throw SystemError(fmt::format(
        "no palpated serves client {} on domain {}: its request reader and reply writer did not "
        "match within {} ms (is palpated running on domain {}, with a DDS configuration that "
        "reaches this process?)",
        impl_->options.client_id, impl_->options.domain_id, timeout.count(),
        impl_->options.domain_id));
  const std::uint64_t id = send(model_id, constraints, want_surface, update_state);
  const auto left =
      std::max(std::chrono::milliseconds(0),
               std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()));
  auto reply = wait_reply(id, left);
  if (!reply)
    throw SystemError(fmt::format(
        "no reply to request {} of client {} within {} ms: palpated on domain {} is matched "
        "but did not answer (see its log: event=reply_dropped, a stall, or it stopped)",
        id, impl_->options.client_id, timeout.count(), impl_->options.domain_id));
  return std::move(*reply);
}

std::optional<SurfaceSample> Client::wait_surface(const std::string& model_id,
                                                  std::uint64_t min_sequence,
                                                  std::uint64_t request_id,
                                                  std::chrono::milliseconds timeout) {
  PALPATE_DEMAND(impl_->options.subscribe_surface);
  std::optional<SurfaceSample> sample;
  impl_->surfaces.take_until<palpate_SurfaceDisplacement>(
      Clock::now() + timeout, [&](const palpate_SurfaceDisplacement& s) {
        if (wire::bounded(s.model_id) != model_id || s.sequence_number < min_sequence) return false;
        if (request_id != 0 && s.source_request_id != request_id) return false;
        sample = wire::from_idl(s);
        return true;
      });
  return sample;
}

std::optional<StatusSample> Client::wait_status(std::chrono::milliseconds timeout) {
  PALPATE_DEMAND(impl_->options.subscribe_status);
  std::optional<StatusSample> status;
  impl_->statuses.take_until<palpate_DaemonStatus>(Clock::now() + timeout,
                                                   [&](const palpate_DaemonStatus& s) {
                                                     status = wire::from_idl(s);
                                                     return true;
                                                   });
  return status;
}

DaemonPresence Client::daemon_presence() { return impl_->watch.poll(Clock::now()); }

}  // namespace palpate
