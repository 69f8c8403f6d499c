#include "palpate/client.hpp"

#include <fmt/format.h>
#include <sched.h>

#include <cstring>
#include <map>

#include "palpate.h"
#include "palpate/daemon_config.hpp"
#include "palpate/dds.hpp"
#include "palpate/error.hpp"

namespace palpate {

namespace {

using Clock = std::chrono::steady_clock;

std::string bounded(const char* text, std::size_t size) { return {text, strnlen(text, size)}; }

template <typename T, std::size_t N>
std::array<T, N> to_array(const T (&values)[N]) {
  std::array<T, N> a;
  std::copy_n(values, N, a.begin());
  return a;
}

/// A reader and the waitset that wakes on its data.
struct WaitableReader {
  dds::Entity reader;
  dds::Entity waitset;

  WaitableReader() = default;
  /// A reader of @p topic under @p parent (the participant or a subscriber).
  WaitableReader(dds_entity_t participant, dds_entity_t parent, dds_entity_t topic,
                 const dds_qos_t* qos, const char* what) {
    reader = dds::Entity(dds::check(dds_create_reader(parent, topic, qos, nullptr), what));
    waitset = dds::Entity(dds::check(dds_create_waitset(participant), what));
    const dds_entity_t condition =
        dds::check(dds_create_readcondition(reader.get(), DDS_ANY_STATE), what);
    dds::check(dds_waitset_attach(waitset.get(), condition, 0), what);
  }

  bool busy_wait = false;  // poll instead of sleeping on the waitset

  /// Takes samples and hands each valid one to @p accept until it returns
  /// true (then true) or the deadline passes (then false).
  template <typename Sample, typename Accept>
  bool take_until(Clock::time_point deadline, Accept accept) {
    for (;;) {
      // One sample at a time: a batch would lose the samples after the
      // accepted one (two model descriptions arriving together, say).
      void* sample = nullptr;
      dds_sample_info_t info;
      const dds_return_t n = dds_take(reader.get(), &sample, &info, 1, 1);
      if (n < 0) throw SystemError(std::string("taking samples: ") + dds_strretcode(n));
      if (n > 0) {
        const bool done = info.valid_data && accept(*static_cast<const Sample*>(sample));
        dds_return_loan(reader.get(), &sample, n);
        if (done) return true;
        continue;
      }
      const auto now = Clock::now();
      if (now >= deadline) return false;
      if (busy_wait) {
        sched_yield();
        continue;
      }
      dds_attach_t triggered;
      dds_waitset_wait(
          waitset.get(), &triggered, 1,
          std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - now).count());
    }
  }
};

void check_client_id(const std::string& id) {
  if (!is_valid_id(id))
    throw InputError("client id '" + id +
                     "': expected 1 to 63 characters among A-Z a-z 0-9 _ - . (it names the "
                     "reply partition)");
}

}  // namespace

struct Client::Impl {
  ClientOptions options;
  std::shared_ptr<dds::Entity> domain;
  dds::Entity participant;
  dds_entity_t request_writer = 0;
  WaitableReader models, replies, surfaces, statuses;
  std::map<std::string, ModelInfo> known_models;
  std::uint64_t next_request_id = 1;
  std::uint64_t foreign_replies = 0;
  palpate_ConstraintRequest request{};
  std::vector<palpate_Constraint> constraints;
};

Client::Client(const ClientOptions& options) : impl_(std::make_unique<Impl>()) {
  check_client_id(options.client_id);
  Impl& c = *impl_;
  c.options = options;
  c.domain = dds::acquire_domain(options.domain_id, dds::resolve_domain_config(options.dds_config));
  c.participant = dds::Entity(dds::check(
      dds_create_participant(options.domain_id, nullptr, nullptr), "creating the DDS participant"));
  const dds_entity_t p = c.participant.get();
  auto topic = [&](const dds_topic_descriptor_t* type, const char* name) {
    return dds::check(dds_create_topic(p, type, name, nullptr, nullptr),
                      fmt::format("creating topic {}", name));
  };
  c.models = WaitableReader(p, p, topic(&palpate_ModelDescription_desc, dds::kModelTopic),
                            dds::model_qos().get(), "creating the model reader");
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
  if (options.subscribe_status)
    c.statuses = WaitableReader(p, p, topic(&palpate_DaemonStatus_desc, dds::kStatusTopic),
                                dds::status_qos().get(), "creating the status reader");
  std::strncpy(c.request.client_id, options.client_id.c_str(), sizeof c.request.client_id - 1);
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
  Impl& c = *impl_;
  auto known = [&]() -> std::optional<ModelInfo> {
    if (auto it = c.known_models.find(model_id); it != c.known_models.end()) return it->second;
    return std::nullopt;
  };
  if (auto m = known()) return m;
  c.models.take_until<palpate_ModelDescription>(
      Clock::now() + timeout, [&](const palpate_ModelDescription& d) {
        ModelInfo info;
        info.model_id = bounded(d.model_id, sizeof d.model_id);
        info.units = bounded(d.units, sizeof d.units);
        info.material_summary = bounded(d.material_summary, sizeof d.material_summary);
        info.input_hash = bounded(d.input_hash, sizeof d.input_hash);
        info.compliance_vertex_count = static_cast<int>(d.compliance_vertex_count);
        info.vertex_ids.assign(d.vertex_ids._buffer, d.vertex_ids._buffer + d.vertex_ids._length);
        info.rest_positions_m.assign(d.rest_positions._buffer,
                                     d.rest_positions._buffer + d.rest_positions._length);
        info.triangles.assign(d.triangles._buffer, d.triangles._buffer + d.triangles._length);
        const bool wanted = info.model_id == model_id;
        c.known_models[info.model_id] = std::move(info);
        return wanted;
      });
  return known();
}

std::uint64_t Client::send(const std::string& model_id, std::span<const ConstraintSpec> constraints,
                           bool want_surface, bool update_state) {
  Impl& c = *impl_;
  c.constraints.resize(constraints.size());
  for (std::size_t j = 0; j < constraints.size(); ++j) {
    const ConstraintSpec& s = constraints[j];
    palpate_Constraint& out = c.constraints[j];
    out.vertex = s.vertex;
    out.kind = static_cast<palpate_ConstraintKind>(s.kind);
    std::copy(s.value.begin(), s.value.end(), out.value);
    std::copy(s.normal.begin(), s.normal.end(), out.normal);
  }
  palpate_ConstraintRequest& r = c.request;
  std::memset(r.model_id, 0, sizeof r.model_id);
  std::strncpy(r.model_id, model_id.c_str(), sizeof r.model_id - 1);
  r.request_id = c.next_request_id++;
  r.want_surface = want_surface;
  r.update_state = update_state;
  r.constraints._buffer = c.constraints.data();
  r.constraints._length = r.constraints._maximum = static_cast<std::uint32_t>(c.constraints.size());
  r.constraints._release = false;
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
        Reply& out = reply.emplace();
        out.request_id = r.request_id;
        out.model_id = bounded(r.model_id, sizeof r.model_id);
        out.status = static_cast<RequestStatus>(r.status);
        out.message = bounded(r.message, sizeof r.message);
        out.condition_estimate = r.condition_estimate;
        out.total_force_n = to_array(r.total_force);
        out.solve_ns = r.solve_ns;
        out.results.resize(r.results._length);
        for (std::uint32_t j = 0; j < r.results._length; ++j) {
          const palpate_ConstraintResult& in = r.results._buffer[j];
          out.results[j] = {in.vertex, to_array(in.force), to_array(in.displacement)};
        }
        out.surface_displacement_m.assign(
            r.surface_displacement._buffer,
            r.surface_displacement._buffer + r.surface_displacement._length);
        return true;
      });
  return reply;
}

std::uint64_t Client::foreign_replies() const { return impl_->foreign_replies; }

Reply Client::request(const std::string& model_id, std::span<const ConstraintSpec> constraints,
                      bool want_surface, bool update_state, std::chrono::milliseconds timeout) {
  const std::uint64_t id = send(model_id, constraints, want_surface, update_state);
  auto reply = wait_reply(id, timeout);
  if (!reply)
    throw SystemError(fmt::format(
        "no reply to request {} of client {} within {} ms (is palpated running on domain {}?)", id,
        impl_->options.client_id, timeout.count(), impl_->options.domain_id));
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
        if (bounded(s.model_id, sizeof s.model_id) != model_id || s.sequence_number < min_sequence)
          return false;
        if (request_id != 0 && s.source_request_id != request_id) return false;
        SurfaceSample& out = sample.emplace();
        out.model_id = model_id;
        out.sequence_number = s.sequence_number;
        out.source_client_id = bounded(s.source_client_id, sizeof s.source_client_id);
        out.source_request_id = s.source_request_id;
        out.total_force_n = to_array(s.total_force);
        out.displacement_m.assign(s.displacement._buffer,
                                  s.displacement._buffer + s.displacement._length);
        return true;
      });
  return sample;
}

std::optional<StatusSample> Client::wait_status(std::chrono::milliseconds timeout) {
  PALPATE_DEMAND(impl_->options.subscribe_status);
  std::optional<StatusSample> status;
  impl_->statuses.take_until<palpate_DaemonStatus>(
      Clock::now() + timeout, [&](const palpate_DaemonStatus& s) {
        auto latency = [](const palpate_Latency& l) {
          return LatencySummary{l.p50_us, l.p99_us, l.p999_us, l.max_us};
        };
        status = StatusSample{bounded(s.daemon_id, sizeof s.daemon_id),
                              s.uptime_ns,
                              s.requests_served,
                              s.error_replies,
                              s.request_rate_hz,
                              s.surface_rate_hz,
                              latency(s.solve),
                              latency(s.request_to_reply),
                              s.models,
                              s.clients};
        return true;
      });
  return status;
}

}  // namespace palpate
