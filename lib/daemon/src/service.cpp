#include "palpate/daemon/service.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <ctime>
#include <mutex>
#include <thread>

#include "palpate.h"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/core/error.hpp"
#include "palpate/runtime/session_recorder.hpp"
#include "palpate/core/statistics.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace palpate {

// The wire enums and the library's must agree number for number.
static_assert(static_cast<int>(RequestStatus::kOk) == palpate_STATUS_OK);
static_assert(static_cast<int>(RequestStatus::kIllConditioned) == palpate_STATUS_ILL_CONDITIONED);
static_assert(static_cast<int>(RequestStatus::kInternalError) == palpate_STATUS_INTERNAL_ERROR);
static_assert(static_cast<int>(ConstraintKind::kNormalDisplacement) ==
              palpate_CONSTRAINT_NORMAL_DISPLACEMENT);
static_assert(static_cast<int>(ToolState::kGrasping) == palpate_TOOL_GRASPING);
static_assert(static_cast<int>(ToolEventKind::kResumed) == palpate_TOOL_EVENT_RESUMED);

namespace {

using Clock = std::chrono::steady_clock;

/// Copies @p text into a bounded IDL string, truncating.
template <std::size_t N>
void copy_bounded(char (&destination)[N], std::string_view text) {
  const std::size_t n = std::min(text.size(), N - 1);
  std::memcpy(destination, text.data(), n);
  destination[n] = '\0';
}

/// A client id names its reply partition: not empty, no partition wildcards.
bool names_a_partition(const char* client_id) {
  return client_id[0] != '\0' && std::strpbrk(client_id, "*?[]\\") == nullptr;
}

/// Nearest-rank percentiles of the latencies of one heartbeat interval.
palpate_Latency percentiles(std::vector<double>& values_us, std::size_t count) {
  palpate_Latency latency{};
  if (count == 0) return latency;
  std::sort(values_us.begin(), values_us.begin() + static_cast<std::ptrdiff_t>(count));
  const std::span<const double> sorted(values_us.data(), count);
  auto at = [&](double q) { return sorted_percentile(sorted, q); };
  latency.p50_us = at(0.50);
  latency.p99_us = at(0.99);
  latency.p999_us = at(0.999);
  latency.max_us = values_us[count - 1];
  return latency;
}

/// Latencies of the request thread, handed to the status thread once per
/// heartbeat. Fixed capacity: samples beyond it in one interval are dropped
/// from the percentiles (not from the counts).
class LatencyLog {
 public:
  static constexpr std::size_t kCapacity = 1 << 17;
  LatencyLog() : solve_us_(kCapacity), reply_us_(kCapacity) {}

  void record(double solve_us, double request_to_reply_us) {
    const std::lock_guard lock(mutex_);
    if (count_ == kCapacity) return;
    solve_us_[count_] = solve_us;
    reply_us_[count_] = request_to_reply_us;
    ++count_;
  }
  /// Swaps the interval's samples into @p solve_us, @p reply_us (same capacity); returns their
  /// count.
  std::size_t drain(std::vector<double>& solve_us, std::vector<double>& reply_us) {
    const std::lock_guard lock(mutex_);
    solve_us.swap(solve_us_);
    reply_us.swap(reply_us_);
    return std::exchange(count_, 0);
  }

 private:
  std::mutex mutex_;
  std::vector<double> solve_us_, reply_us_;
  std::size_t count_ = 0;
};

/// A model, its solver (request thread only) and the state it shows.
struct ServedModel {
  SurfaceModel model;
  std::unique_ptr<ConstraintSolver> solver;

  // The shown state: written by the request thread, read by the stream thread.
  std::mutex mutex;
  std::uint64_t version = 0;
  int shown_count = 0;
  std::vector<int> shown_indices;
  std::vector<double> shown_forces;
  char shown_client[64] = {};
  std::uint64_t shown_request = 0;
  double shown_total_force[3] = {};

  // Tools: the pose listener and the watchdog (stream thread) take turns.
  std::mutex tool_mutex;
  std::unique_ptr<ToolContactEngine> tools;
  std::unique_ptr<SessionRecorder> recorder;  // made at the first pose when recording
  bool recorder_failed = false;
  std::vector<std::uint32_t> record_vertices;  // one tool's contacts, for the recorder
  std::vector<double> record_forces;

  // Stream thread only.
  palpate_SurfaceDisplacement sample{};  // its buffer is `displacement`
  std::uint64_t published_version = 0;
  std::vector<int> stream_indices;
  std::vector<double> stream_forces;
  std::vector<std::uint32_t> stream_vertex_ids;  // mesh vertex ids of stream_indices, for the sample
  Eigen::VectorXd displacement;
};

/// Logs a repeated warning at most once per second per reason, with the
/// number of occurrences folded into it.
class WarningLimiter {
 public:
  template <typename... Args>
  void warn(int reason, fmt::format_string<Args...> format, Args&&... args) {
    const auto now = Clock::now();
    Slot& slot = slots_[static_cast<std::size_t>(reason) % slots_.size()];
    ++slot.count;
    if (slot.logged && now - slot.last < std::chrono::seconds(1)) return;
    spdlog::warn("{} occurrences={}", fmt::format(format, std::forward<Args>(args)...),
                 slot.count);
    slot.count = 0;
    slot.logged = true;
    slot.last = now;
  }

 private:
  struct Slot {
    std::uint64_t count = 0;
    bool logged = false;
    Clock::time_point last{};
  };
  std::array<Slot, 16> slots_{};
};

struct ClientWriter {
  char id[64] = {};
  dds::Entity publisher;
  dds::Entity writer;
};

}  // namespace

struct Service::Impl {
  DaemonConfig config;
  std::vector<std::unique_ptr<ServedModel>> models;
  std::string served_ids;  // "a, b" for error messages

  std::shared_ptr<dds::Entity> domain;
  dds::Entity participant;
  dds::Entity model_writer, request_reader, surface_writer, status_writer, subscriptions_reader;
  dds::Entity reply_topic;
  dds::Entity waitset, stop_condition;
  dds_entity_t subscriptions_condition = 0;
  std::mutex clients_mutex;  // discovery (service thread) and requests (listener) both add clients
  std::vector<ClientWriter> clients;

  // Request thread buffers, sized once.
  static constexpr int kBatch = 16;
  std::vector<palpate_ConstraintRequest> requests;
  std::vector<void*> request_pointers;
  std::vector<dds_sample_info_t> request_infos;
  palpate_ConstraintReply reply{};
  std::vector<palpate_ConstraintResult> reply_results;
  std::vector<double> reply_surface;

  // Tools.
  dds::Entity pose_reader, feedback_writer, event_writer;
  palpate_ToolPose pose_samples[8];
  void* pose_pointers[8] = {};
  dds_sample_info_t pose_infos[8];
  std::mutex pose_mutex;  // warnings and counters of the pose path
  WarningLimiter pose_warnings;
  LatencyLog tool_latencies;
  std::atomic<std::uint64_t> tool_poses{0}, tool_poses_refused{0};

  // Counters and the stream/status thread.
  std::vector<double> tool_us = std::vector<double>(LatencyLog::kCapacity),
                      tool_us_unused = std::vector<double>(LatencyLog::kCapacity);
  LatencyLog latencies;
  std::atomic<std::uint64_t> requests_served{0}, errors{0}, surface_samples{0};
  std::atomic<bool> stopping{false};
  // Released before each listener is attached, acquired by the listeners:
  // what the constructor set up happens before their first call in C++'s
  // memory model, not only through Cyclone's internal ordering (which
  // ThreadSanitizer cannot see in the uninstrumented libddsc).
  std::atomic<bool> listening{false};
  std::string stream_failure;  // set by the stream thread before it stops the service
  std::mutex stream_mutex;
  std::condition_variable stream_wake;
  Clock::time_point started = Clock::now();

  explicit Impl(const DaemonConfig& c);
  ~Impl();
  void publish_descriptions();
  void serve_requests(dds_entity_t reader);
  static void on_requests(dds_entity_t reader, void* arg);
  void handle(const palpate_ConstraintRequest& request, const dds_sample_info_t& info);
  RequestStatus solve(const palpate_ConstraintRequest& request, ServedModel*& served);
  void discover_clients();
  ClientWriter* client_writer(const char* client_id);
  static void on_poses(dds_entity_t reader, void* arg);
  void serve_poses(dds_entity_t reader);
  void take_pose(const palpate_ToolPose& pose);
  void publish_tool(ServedModel& served, int tool, std::uint64_t compute_ns, bool record);
  void run_watchdogs();
  void close_recorders();
  double seconds_since_start() const {
    return std::chrono::duration<double>(Clock::now() - started).count();
  }
  void stream_loop();
  void stop();
  void publish_surfaces();
  void publish_status(double interval_s, std::uint64_t served_in_interval,
                      std::uint64_t surfaces_in_interval, std::vector<double>& solve_us,
                      std::vector<double>& reply_us);
};

Service::Impl::Impl(const DaemonConfig& c) : config(c) {
  std::size_t max_surface = 0;
  for (const auto& entry : config.models) {
    auto served = std::make_unique<ServedModel>();
    const auto start = Clock::now();
    // A float32 file stays float32 in memory: half the bytes (docs/precompute.md,
    // "Batch precomputation"); the algebra still runs in double.
    served->model = load_surface_model(entry.id, entry.file, /*keep_float32=*/true);
    const auto& m = served->model;
    served->solver = std::make_unique<ConstraintSolver>(m, config.limits);
    const auto k = static_cast<std::size_t>(config.limits.max_constraints);
    served->shown_indices.resize(k);
    served->shown_forces.resize(3 * k);
    served->stream_indices.resize(k);
    served->stream_forces.resize(3 * k);
    served->stream_vertex_ids.resize(k);
    served->displacement = Eigen::VectorXd::Zero(m.compliance_rows());
    served->tools =
        std::make_unique<ToolContactEngine>(m, config.tools, config.contact, config.limits);
    served->record_vertices.resize(k);
    served->record_forces.resize(3 * k);
    served->version = 1;  // the rest state: a late viewer gets a surface before any request
    max_surface = std::max(max_surface, static_cast<std::size_t>(m.compliance_rows()));
    spdlog::info(
        "event=model_loaded model={} file={} compliance_vertices={} mesh_vertices={} triangles={} "
        "G_MB={:.1f} G_precision={} seconds={:.2f}",
        m.id, m.path.string(), m.compliance_vertex_count(), m.mesh_vertex_count(),
        m.drawn_triangles.size() / 3, m.G_bytes() / 1e6, m.float32() ? "float32" : "float64",
        std::chrono::duration<double>(Clock::now() - start).count());
    served_ids += (served_ids.empty() ? "" : ", ") + m.id;
    models.push_back(std::move(served));
  }
  reply_results.resize(static_cast<std::size_t>(config.limits.max_constraints));
  reply_surface.resize(max_surface);
  reply.results._buffer = reply_results.data();
  reply.results._maximum = static_cast<std::uint32_t>(reply_results.size());
  reply.surface_displacement._buffer = reply_surface.data();
  reply.surface_displacement._maximum = static_cast<std::uint32_t>(reply_surface.size());
  requests.resize(kBatch);
  request_infos.resize(kBatch);
  for (auto& r : requests) request_pointers.push_back(&r);
  clients.reserve(static_cast<std::size_t>(config.max_clients));

  const dds::DomainConfig dds_config = dds::resolve_domain_config(config.dds_config);
  spdlog::info("event=dds_domain domain={} configuration=\"{}\"", config.domain_id,
               dds_config.origin);
  try {
    domain = dds::acquire_domain(config.domain_id, dds_config);
  } catch (const SystemError& e) {
    if (dds_config.origin == "built-in loopback") throw;
    throw InputError(std::string(e.what()) + "; check the Cyclone DDS configuration (" +
                     dds_config.origin + ")");
  }
  participant = dds::Entity(dds::create_participant(config.domain_id, dds_config));
  auto topic = [this](const dds_topic_descriptor_t* type, const char* name) {
    return dds::topic(participant.get(), type, name);
  };
  const dds_entity_t model_topic = topic(&palpate_ModelDescription_desc, dds::kModelTopic);
  const dds_entity_t request_topic = topic(&palpate_ConstraintRequest_desc, dds::kRequestTopic);
  reply_topic = dds::Entity(topic(&palpate_ConstraintReply_desc, dds::kReplyTopic));
  const dds_entity_t surface_topic = topic(&palpate_SurfaceDisplacement_desc, dds::kSurfaceTopic);
  const dds_entity_t status_topic = topic(&palpate_DaemonStatus_desc, dds::kStatusTopic);
  const dds_entity_t pose_topic = topic(&palpate_ToolPose_desc, dds::kToolPoseTopic);
  const dds_entity_t feedback_topic = topic(&palpate_ToolFeedback_desc, dds::kToolFeedbackTopic);
  const dds_entity_t event_topic = topic(&palpate_ToolEvent_desc, dds::kToolEventTopic);

  model_writer = dds::Entity(
      dds::check(dds_create_writer(participant.get(), model_topic, dds::model_qos().get(), nullptr),
                 "creating the model writer"));
  surface_writer = dds::Entity(dds::check(
      dds_create_writer(participant.get(), surface_topic, dds::surface_qos().get(), nullptr),
      "creating the surface writer"));
  status_writer = dds::Entity(dds::check(
      dds_create_writer(participant.get(), status_topic, dds::status_qos().get(), nullptr),
      "creating the status writer"));
  feedback_writer = dds::Entity(dds::check(
      dds_create_writer(participant.get(), feedback_topic, dds::tool_stream_qos().get(), nullptr),
      "creating the tool feedback writer"));
  event_writer = dds::Entity(dds::check(
      dds_create_writer(participant.get(), event_topic, dds::tool_event_qos().get(), nullptr),
      "creating the tool event writer"));
  subscriptions_reader = dds::Entity(dds::check(
      dds_create_reader(participant.get(), DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, nullptr, nullptr),
      "creating the discovery reader"));

  waitset = dds::Entity(dds::check(dds_create_waitset(participant.get()), "creating the waitset"));
  stop_condition = dds::Entity(
      dds::check(dds_create_guardcondition(participant.get()), "creating the guard condition"));
  subscriptions_condition = dds::check(
      dds_create_readcondition(subscriptions_reader.get(), DDS_ANY_STATE), "read condition");
  dds::check(dds_waitset_attach(waitset.get(), stop_condition.get(), 0), "waitset");
  dds::check(dds_waitset_attach(waitset.get(), subscriptions_condition, 1), "waitset");

  publish_descriptions();

  // Requests are served from Cyclone's receive thread, in the reader's
  // data-available listener: no wake-up of another thread between the
  // request's arrival and its reply. Cyclone calls one reader's listener
  // from one thread at a time. Made last: it may fire at once.
  listening.store(true, std::memory_order_release);
  dds_listener_t* listener = dds_create_listener(this);
  dds_lset_data_available(listener, &Impl::on_requests);
  const dds_entity_t reader =
      dds_create_reader(participant.get(), request_topic, dds::request_reply_qos().get(), listener);
  dds_delete_listener(listener);
  request_reader = dds::Entity(dds::check(reader, "creating the request reader"));

  // Poses too are served in their reader's listener.
  for (int i = 0; i < 8; ++i) pose_pointers[i] = &pose_samples[i];
  listening.store(true, std::memory_order_release);
  dds_listener_t* pose_listener = dds_create_listener(this);
  dds_lset_data_available(pose_listener, &Impl::on_poses);
  const dds_entity_t poses = dds_create_reader(participant.get(), pose_topic,
                                               dds::tool_stream_qos().get(), pose_listener);
  dds_delete_listener(pose_listener);
  pose_reader = dds::Entity(dds::check(poses, "creating the tool pose reader"));
}

// The listeners take from the reader Cyclone names: they may fire before
// dds_create_reader has returned, so before request_reader and pose_reader
// hold the handle (a data race ThreadSanitizer found; the first request or
// pose then failed with a bad handle).
void Service::Impl::on_requests(dds_entity_t reader, void* arg) {
  try {
    Impl& impl = *static_cast<Impl*>(arg);
    (void)impl.listening.load(std::memory_order_acquire);
    impl.serve_requests(reader);
  } catch (const std::exception& e) {
    spdlog::error("event=requests_failed error=\"{}\"", e.what());
  }
}

Service::Impl::~Impl() {
  pose_reader.reset();  // no listener call after this
  request_reader.reset();
  close_recorders();
  // Request samples own the constraint buffers Cyclone allocated into them.
  for (auto& r : requests) dds_sample_free(&r, &palpate_ConstraintRequest_desc, DDS_FREE_CONTENTS);
  participant.reset();  // deletes every entity of the participant
}

void Service::Impl::publish_descriptions() {
  for (const auto& served : models) {
    const SurfaceModel& m = served->model;
    palpate_ModelDescription d{};
    copy_bounded(d.model_id, m.id);
    copy_bounded(d.units, "m, N (SI)");
    copy_bounded(d.material_summary, m.material_summary);
    copy_bounded(d.input_hash, m.input_hash);
    d.compliance_vertex_count = static_cast<std::uint32_t>(m.compliance_vertex_count());
    auto view = [](auto& sequence, auto& vector) {
      sequence._buffer = const_cast<std::remove_cvref_t<decltype(*vector.data())>*>(vector.data());
      sequence._length = sequence._maximum = static_cast<std::uint32_t>(vector.size());
      sequence._release = false;
    };
    view(d.vertex_ids, m.drawn_vertex_ids);
    view(d.rest_positions, m.drawn_rest_positions_m);
    view(d.triangles, m.drawn_triangles);
    dds::check(dds_write(model_writer.get(), &d), "publishing model " + m.id);
  }
}

ClientWriter* Service::Impl::client_writer(const char* client_id) {
  // Called with clients_mutex held.
  for (auto& client : clients)
    if (std::strcmp(client.id, client_id) == 0) return &client;
  if (!names_a_partition(client_id)) return nullptr;
  ClientWriter* slot = nullptr;
  if (clients.size() < clients.capacity()) {
    slot = &clients.emplace_back();
  } else {
    // Reuse the writer of a client that has gone (no matched reader).
    for (auto& client : clients) {
      dds_publication_matched_status_t status{};
      if (dds_get_publication_matched_status(client.writer.get(), &status) == DDS_RETCODE_OK &&
          status.current_count == 0) {
        spdlog::info("event=client_forgotten client={}", client.id);
        client.writer.reset();
        client.publisher.reset();
        slot = &client;
        break;
      }
    }
    if (slot == nullptr) {
      spdlog::warn("event=too_many_clients client={} max_clients={}", client_id,
                   config.max_clients);
      return nullptr;
    }
  }
  copy_bounded(slot->id, client_id);
  const std::string partition = dds::reply_partition(client_id);
  const char* partitions[] = {partition.c_str()};
  dds::Qos qos(dds_create_qos());
  dds_qset_partition(qos.get(), 1, partitions);
  dds_entity_t publisher = dds_create_publisher(participant.get(), qos.get(), nullptr);
  if (publisher < 0) {
    spdlog::error("event=dds_error what=\"creating the reply publisher of client {}\" error={}",
                  client_id, dds_strretcode(publisher));
    slot->id[0] = '\0';
    return nullptr;
  }
  slot->publisher = dds::Entity(publisher);
  dds_entity_t writer =
      dds_create_writer(publisher, reply_topic.get(), dds::request_reply_qos().get(), nullptr);
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

void Service::Impl::discover_clients() {
  // A client's reply reader announces its partition "palpate.client.<id>":
  // the reply writer is made before its first request.
  void* samples[8] = {};
  dds_sample_info_t infos[8];
  const dds_return_t n = dds_take(subscriptions_reader.get(), samples, infos, 8, 8);
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
        const std::lock_guard lock(clients_mutex);
        client_writer(names[p] + dds::kReplyPartitionPrefix.size());
      }
      dds_free(names[p]);
    }
    dds_free(names);
  }
  dds_return_loan(subscriptions_reader.get(), samples, n);
}

RequestStatus Service::Impl::solve(const palpate_ConstraintRequest& request, ServedModel*& served) {
  served = nullptr;
  for (const auto& candidate : models)
    if (std::strncmp(candidate->model.id.c_str(), request.model_id, sizeof request.model_id) == 0)
      served = candidate.get();
  if (served == nullptr) {
    std::snprintf(reply.message, sizeof reply.message, "model '%s' is not served here; served: %s",
                  request.model_id, served_ids.c_str());
    return RequestStatus::kUnknownModel;
  }
  ConstraintSolver& solver = *served->solver;
  const std::uint32_t k = request.constraints._length;
  RequestStatus status = solver.begin(k);
  for (std::uint32_t j = 0; j < k && status == RequestStatus::kOk; ++j) {
    const palpate_Constraint& c = request.constraints._buffer[j];
    status = solver.add(c.vertex, static_cast<std::int32_t>(c.kind), c.value, c.normal);
  }
  if (status == RequestStatus::kOk) status = solver.solve();
  reply.condition_estimate = solver.condition_estimate();
  if (status != RequestStatus::kOk) {
    copy_bounded(reply.message, solver.message());
    return status;
  }

  const auto forces = solver.forces();
  const auto displacements = solver.displacements();
  reply.results._length = k;
  for (std::uint32_t j = 0; j < k; ++j) {
    palpate_ConstraintResult& result = reply_results[j];
    result.vertex = request.constraints._buffer[j].vertex;
    for (int d = 0; d < 3; ++d) {
      result.force[d] = forces(3 * j + d);
      result.displacement[d] = displacements(3 * j + d);
    }
  }
  const Eigen::Vector3d total = solver.total_force();
  for (int d = 0; d < 3; ++d) reply.total_force[d] = total[d];
  if (request.want_surface) {
    const auto n = static_cast<Eigen::Index>(served->model.compliance_rows());
    solver.surface_displacement(Eigen::Map<Eigen::VectorXd>(reply_surface.data(), n));
    reply.surface_displacement._length = static_cast<std::uint32_t>(n);
  }
  if (request.update_state) {
    // The latest successful state-changing request defines what the model
    // shows: its vertices and forces; the stream thread does the big product.
    const std::lock_guard lock(served->mutex);
    served->shown_count = static_cast<int>(k);
    std::copy_n(solver.indices().begin(), k, served->shown_indices.begin());
    std::copy_n(forces.data(), 3 * k, served->shown_forces.begin());
    copy_bounded(served->shown_client, reply.client_id);
    served->shown_request = request.request_id;
    for (int d = 0; d < 3; ++d) served->shown_total_force[d] = total[d];
    ++served->version;
  }
  return RequestStatus::kOk;
}

void Service::Impl::handle(const palpate_ConstraintRequest& request,
                           const dds_sample_info_t& info) {
  const auto start = Clock::now();
  copy_bounded(
      reply.client_id,
      std::string_view(request.client_id, strnlen(request.client_id, sizeof request.client_id)));
  copy_bounded(
      reply.model_id,
      std::string_view(request.model_id, strnlen(request.model_id, sizeof request.model_id)));
  reply.request_id = request.request_id;
  reply.message[0] = '\0';
  reply.condition_estimate = 1;
  reply.total_force[0] = reply.total_force[1] = reply.total_force[2] = 0;
  reply.results._length = 0;
  reply.surface_displacement._length = 0;

  // A request that cannot be answered (no valid reply partition) changes nothing.
  if (!names_a_partition(reply.client_id)) {
    errors.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn(
        "event=request_ignored client=\"{}\" request={} reason=\"client id cannot name a reply "
        "partition\"",
        reply.client_id, request.request_id);
    return;
  }
  ServedModel* served = nullptr;
  RequestStatus status = RequestStatus::kInternalError;
  try {
    status = solve(request, served);
  } catch (const std::exception& e) {
    copy_bounded(reply.message, e.what());
  }
  reply.status = static_cast<palpate_ReplyStatus>(status);
  if (status != RequestStatus::kOk) {
    reply.results._length = 0;
    reply.surface_displacement._length = 0;
    errors.fetch_add(1, std::memory_order_relaxed);
    spdlog::debug("event=request_refused client={} request={} status={} message=\"{}\"",
                  reply.client_id, request.request_id, status_name(status), reply.message);
  }

  const std::lock_guard lock(clients_mutex);
  ClientWriter* client = client_writer(reply.client_id);
  reply.solve_ns = static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start).count());
  if (client == nullptr) {
    spdlog::warn(
        "event=reply_dropped client=\"{}\" request={} reason=\"no reply writer for this client "
        "id\"",
        reply.client_id, request.request_id);
  } else if (const dds_return_t rc = dds_write(client->writer.get(), &reply); rc < 0) {
    spdlog::error("event=dds_error what=\"writing a reply\" client={} error={}", reply.client_id,
                  dds_strretcode(rc));
  }
  requests_served.fetch_add(1, std::memory_order_relaxed);
  const double solve_us = static_cast<double>(reply.solve_ns) * 1e-3;
  const double request_to_reply_us = static_cast<double>(dds_time() - info.source_timestamp) * 1e-3;
  latencies.record(solve_us, request_to_reply_us);
}

void Service::Impl::serve_requests(dds_entity_t reader) {
  for (;;) {
    const dds_return_t n = dds_take(reader, request_pointers.data(),
                                    request_infos.data(), kBatch, kBatch);
    if (n < 0) throw SystemError(std::string("taking requests: ") + dds_strretcode(n));
    for (dds_return_t i = 0; i < n; ++i)
      if (request_infos[i].valid_data) handle(requests[i], request_infos[i]);
    if (n < kBatch) return;
  }
}

void Service::Impl::on_poses(dds_entity_t reader, void* arg) {
  try {
    Impl& impl = *static_cast<Impl*>(arg);
    (void)impl.listening.load(std::memory_order_acquire);
    impl.serve_poses(reader);
  } catch (const std::exception& e) {
    spdlog::error("event=poses_failed error=\"{}\"", e.what());
  }
}

void Service::Impl::serve_poses(dds_entity_t reader) {
  for (;;) {
    const dds_return_t n = dds_take(reader, pose_pointers, pose_infos, 8, 8);
    if (n < 0) throw SystemError(std::string("taking tool poses: ") + dds_strretcode(n));
    for (dds_return_t i = 0; i < n; ++i)
      if (pose_infos[i].valid_data) take_pose(pose_samples[i]);
    if (n < 8) return;
  }
}

namespace {
enum PoseWarning { kUnknownModel, kUnknownTool, kBadPose, kSolveFailed };
}

void Service::Impl::take_pose(const palpate_ToolPose& pose) {
  const auto start = Clock::now();
  const std::string_view tool_id(pose.tool_id, strnlen(pose.tool_id, sizeof pose.tool_id));
  const std::string_view model_id(pose.model_id, strnlen(pose.model_id, sizeof pose.model_id));
  ServedModel* served = nullptr;
  for (const auto& candidate : models)
    if (candidate->model.id == model_id) served = candidate.get();
  if (served == nullptr) {
    tool_poses_refused.fetch_add(1, std::memory_order_relaxed);
    pose_warnings.warn(kUnknownModel,
                       "event=pose_ignored tool=\"{}\" model=\"{}\" reason=unknown_model "
                       "served=\"{}\"",
                       tool_id, model_id, served_ids);
    return;
  }
  const int tool = served->tools->tool_index(tool_id);
  if (tool < 0) {
    tool_poses_refused.fetch_add(1, std::memory_order_relaxed);
    pose_warnings.warn(kUnknownTool,
                       "event=pose_ignored tool=\"{}\" model={} reason=unknown_tool "
                       "hint=\"tools are configured in [[tools]]\"",
                       tool_id, model_id);
    return;
  }
  ToolPoseInput input;
  input.sequence = pose.pose_sequence;
  input.send_time_ns = pose.send_time_ns;
  input.position_m = Eigen::Vector3d(pose.position[0], pose.position[1], pose.position[2]);
  input.orientation = Eigen::Quaterniond(pose.orientation[0], pose.orientation[1],
                                         pose.orientation[2], pose.orientation[3]);
  input.jaw_angle_rad = pose.jaw_angle;
  const std::lock_guard lock(served->tool_mutex);
  ToolContactEngine& engine = *served->tools;
  if (const PoseProblem problem = engine.check(tool, input); problem != PoseProblem::kNone) {
    tool_poses_refused.fetch_add(1, std::memory_order_relaxed);
    pose_warnings.warn(kBadPose + static_cast<int>(problem) * 4,
                       "event=pose_ignored tool={} model={} sequence={} reason={} "
                       "position=[{:g},{:g},{:g}] jaw_angle={:g}",
                       tool_id, model_id, pose.pose_sequence, pose_problem_name(problem),
                       pose.position[0], pose.position[1], pose.position[2], pose.jaw_angle);
    return;
  }
  const RequestStatus status = engine.update(tool, input, seconds_since_start());
  if (status != RequestStatus::kOk)
    pose_warnings.warn(kSolveFailed, "event=tool_solve_failed tool={} model={} status={} message=\"{}\"",
                       tool_id, model_id, status_name(status), engine.solver_message());
  tool_poses.fetch_add(1, std::memory_order_relaxed);
  publish_tool(*served, tool,
               static_cast<std::uint64_t>(
                   std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start)
                       .count()),
               true);
}

void Service::Impl::publish_tool(ServedModel& served, int tool, std::uint64_t compute_ns,
                                 bool record) {
  // Called with served.tool_mutex held.
  const ToolContactEngine& engine = *served.tools;
  const ToolOutput& out = engine.output(tool);
  const ToolGeometry& geometry = engine.tool(tool);
  palpate_ToolFeedback feedback{};
  copy_bounded(feedback.tool_id, geometry.id);
  copy_bounded(feedback.model_id, served.model.id);
  feedback.pose_sequence = out.sequence;
  feedback.send_time_ns = out.send_time_ns;
  for (int d = 0; d < 3; ++d) {
    feedback.force[d] = out.force_n[d];
    feedback.torque[d] = out.torque_nm[d];
  }
  feedback.grip_force = out.grip_n;
  feedback.contacts = static_cast<std::uint32_t>(out.contacts);
  feedback.state = static_cast<palpate_ToolState>(out.state);
  feedback.force_limited = out.force_limited;
  feedback.watchdog = out.watchdog;
  feedback.compute_ns = compute_ns;
  if (const dds_return_t rc = dds_write(feedback_writer.get(), &feedback); rc < 0)
    spdlog::error("event=dds_error what=\"writing tool feedback\" tool={} error={}", geometry.id,
                  dds_strretcode(rc));
  const double compute_us = static_cast<double>(compute_ns) * 1e-3;
  tool_latencies.record(compute_us, compute_us);

  const double now_s = seconds_since_start();
  for (int e = 0; e < out.event_count; ++e) {
    const ToolEventKind kind = out.events[static_cast<std::size_t>(e)];
    palpate_ToolEvent event{};
    copy_bounded(event.tool_id, geometry.id);
    copy_bounded(event.model_id, served.model.id);
    event.kind = static_cast<palpate_ToolEventKind>(kind);
    event.pose_sequence = out.sequence;
    event.held_vertices = static_cast<std::uint32_t>(out.held);
    event.daemon_time_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
    if (const dds_return_t rc = dds_write(event_writer.get(), &event); rc < 0)
      spdlog::error("event=dds_error what=\"writing a tool event\" tool={} error={}",
                    geometry.id, dds_strretcode(rc));
    spdlog::info("event=tool_{} tool={} model={} sequence={} held={}", tool_event_name(kind),
                 geometry.id, served.model.id, out.sequence, out.held);
  }

  // The tools' contacts become the model's shown state.
  const auto indices = engine.contact_indices();
  const auto forces = engine.contact_forces();
  {
    const std::lock_guard lock(served.mutex);
    const std::size_t k = std::min(indices.size(), served.shown_indices.size());
    served.shown_count = static_cast<int>(k);
    std::copy_n(indices.begin(), k, served.shown_indices.begin());
    std::copy_n(forces.begin(), 3 * k, served.shown_forces.begin());
    copy_bounded(served.shown_client, "tool:" + geometry.id);
    served.shown_request = out.sequence;
    Eigen::Vector3d total = Eigen::Vector3d::Zero();
    for (std::size_t c = 0; c < k; ++c) total += Eigen::Map<const Eigen::Vector3d>(&forces[3 * c]);
    for (int d = 0; d < 3; ++d) served.shown_total_force[d] = total[d];
    ++served.version;
  }

  if (!record || config.record_directory.empty() || served.recorder_failed) return;
  if (!served.recorder) {
    try {
      SessionInfo info;
      info.model_id = served.model.id;
      info.model_file = served.model.path.string();
      info.input_hash = served.model.input_hash;
      info.daemon_id = config.daemon_id;
      info.tools = config.tools;
      info.contact = config.contact;
      const auto wall = std::chrono::system_clock::now();
      info.start_unix_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(wall.time_since_epoch()).count();
      const std::time_t seconds = std::chrono::system_clock::to_time_t(wall);
      std::tm utc{};
      gmtime_r(&seconds, &utc);
      char stamp[32];
      std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", &utc);
      const auto file =
          config.record_directory / fmt::format("session-{}-{}.h5", served.model.id, stamp);
      served.recorder = std::make_unique<SessionRecorder>(file, info);
      spdlog::info("event=recording_started model={} file={}", served.model.id, file.string());
    } catch (const std::exception& e) {
      served.recorder_failed = true;
      spdlog::error("event=recording_failed model={} error=\"{}\"", served.model.id, e.what());
      return;
    }
  }
  ToolTickRecord tick;
  tick.time_s = now_s;
  tick.tool = tool;
  tick.sequence = out.sequence;
  tick.send_time_ns = out.send_time_ns;
  const ToolPoseInput& pose = engine.pose(tool);
  for (int d = 0; d < 3; ++d) {
    tick.position_m[d] = pose.position_m[d];
    tick.force_n[d] = out.force_n[d];
    tick.torque_nm[d] = out.torque_nm[d];
  }
  tick.orientation_wxyz[0] = pose.orientation.w();
  tick.orientation_wxyz[1] = pose.orientation.x();
  tick.orientation_wxyz[2] = pose.orientation.y();
  tick.orientation_wxyz[3] = pose.orientation.z();
  tick.jaw_angle_rad = pose.jaw_angle_rad;
  tick.grip_n = out.grip_n;
  tick.state = out.state;
  tick.watchdog = out.watchdog;
  tick.force_limited = out.force_limited;
  tick.held = static_cast<std::uint32_t>(out.held);
  tick.compute_ns = compute_ns;
  const auto tools_of = engine.contact_tools();
  std::size_t m = 0;
  for (std::size_t c = 0; c < indices.size() && m < served.record_vertices.size(); ++c) {
    if (tools_of[c] != tool) continue;
    served.record_vertices[m] =
        served.model.drawn_vertex_ids[static_cast<std::size_t>(indices[c])];
    std::copy_n(&forces[3 * c], 3, &served.record_forces[3 * m]);
    ++m;
  }
  served.recorder->record(tick, {served.record_vertices.data(), m},
                          {served.record_forces.data(), 3 * m});
  for (int e = 0; e < out.event_count; ++e)
    served.recorder->record_event(now_s, tool, out.events[static_cast<std::size_t>(e)],
                                  out.sequence);
}

void Service::Impl::run_watchdogs() {
  for (const auto& served : models) {
    const std::lock_guard lock(served->tool_mutex);
    const std::uint64_t changed = served->tools->watchdog(seconds_since_start());
    for (int t = 0; t < served->tools->tool_count(); ++t)
      if (changed >> t & 1) publish_tool(*served, t, 0, true);
  }
}

void Service::Impl::close_recorders() {
  for (const auto& served : models) {
    const std::lock_guard lock(served->tool_mutex);
    if (!served->recorder) continue;
    try {
      served->recorder->close();
      spdlog::info("event=recording_closed model={} file={} ticks={} dropped={}", served->model.id,
                   served->recorder->path().string(), served->recorder->recorded(),
                   served->recorder->dropped());
    } catch (const std::exception& e) {
      spdlog::error("event=recording_failed model={} error=\"{}\"", served->model.id, e.what());
    }
    served->recorder.reset();
  }
}

void Service::Impl::publish_surfaces() {
  for (const auto& served : models) {
    palpate_SurfaceDisplacement& sample = served->sample;
    int count = 0;
    {
      const std::lock_guard lock(served->mutex);
      if (served->version == served->published_version) continue;
      served->published_version = served->version;
      count = served->shown_count;
      std::copy_n(served->shown_indices.begin(), count, served->stream_indices.begin());
      std::copy_n(served->shown_forces.begin(), 3 * count, served->stream_forces.begin());
      copy_bounded(sample.source_client_id, served->shown_client);
      sample.source_request_id = served->shown_request;
      std::copy_n(served->shown_total_force, 3, sample.total_force);
    }
    // u_S = G_SC f_C, off the request path.
    surface_displacement(served->model,
                         {served->stream_indices.data(), static_cast<std::size_t>(count)},
                         served->stream_forces.data(), served->displacement);
    copy_bounded(sample.model_id, served->model.id);
    ++sample.sequence_number;
    sample.displacement._buffer = served->displacement.data();
    sample.displacement._length = sample.displacement._maximum =
        static_cast<std::uint32_t>(served->displacement.size());
    sample.displacement._release = false;
    for (int c = 0; c < count; ++c)
      served->stream_vertex_ids[c] = served->model.drawn_vertex_ids[served->stream_indices[c]];
    sample.constrained_vertices._buffer = served->stream_vertex_ids.data();
    sample.constrained_vertices._length = sample.constrained_vertices._maximum =
        static_cast<std::uint32_t>(count);
    sample.constrained_vertices._release = false;
    sample.constrained_forces._buffer = served->stream_forces.data();
    sample.constrained_forces._length = sample.constrained_forces._maximum =
        static_cast<std::uint32_t>(3 * count);
    sample.constrained_forces._release = false;
    if (const dds_return_t rc = dds_write(surface_writer.get(), &sample); rc < 0)
      spdlog::error("event=dds_error what=\"writing the surface of {}\" error={}", served->model.id,
                    dds_strretcode(rc));
    else
      surface_samples.fetch_add(1, std::memory_order_relaxed);
  }
}

void Service::Impl::publish_status(double interval_s, std::uint64_t served_in_interval,
                                   std::uint64_t surfaces_in_interval,
                                   std::vector<double>& solve_us, std::vector<double>& reply_us) {
  const std::size_t n = latencies.drain(solve_us, reply_us);
  palpate_DaemonStatus status{};
  copy_bounded(status.daemon_id, config.daemon_id);
  status.uptime_ns = static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - started).count());
  status.requests_served = requests_served.load(std::memory_order_relaxed);
  status.error_replies = errors.load(std::memory_order_relaxed);
  status.request_rate_hz = static_cast<double>(served_in_interval) / interval_s;
  status.surface_rate_hz = static_cast<double>(surfaces_in_interval) / interval_s;
  status.solve = percentiles(solve_us, n);
  status.request_to_reply = percentiles(reply_us, n);
  status.models = static_cast<std::uint32_t>(models.size());
  {
    const std::lock_guard lock(clients_mutex);
    status.clients = static_cast<std::uint32_t>(clients.size());
  }
  status.tool_poses = tool_poses.load(std::memory_order_relaxed);
  status.tool_poses_refused = tool_poses_refused.load(std::memory_order_relaxed);
  {
    const std::size_t m = tool_latencies.drain(tool_us, tool_us_unused);
    status.tool_compute = percentiles(tool_us, m);
  }
  if (const dds_return_t rc = dds_write(status_writer.get(), &status); rc < 0)
    spdlog::error("event=dds_error what=\"writing the status\" error={}", dds_strretcode(rc));
}

void Service::Impl::stream_loop() {
  using namespace std::chrono;
  const auto surface_period =
      duration_cast<Clock::duration>(duration<double>(1.0 / config.surface_rate_hz));
  const auto status_period =
      duration_cast<Clock::duration>(duration<double>(1.0 / config.status_rate_hz));
  auto next_surface = Clock::now();
  auto next_status = Clock::now() + status_period;
  // The tools' watchdog: a few milliseconds of resolution on its timeout.
  const auto watchdog_period = duration_cast<Clock::duration>(milliseconds(5));
  auto next_watchdog = Clock::now() + watchdog_period;
  auto last_status = Clock::now();
  std::uint64_t last_served = 0, last_surfaces = 0;
  std::vector<double> solve_us(LatencyLog::kCapacity), reply_us(LatencyLog::kCapacity);
  std::unique_lock lock(stream_mutex);
  while (!stopping.load()) {
    stream_wake.wait_until(lock, std::min({next_surface, next_status, next_watchdog}),
                           [&] { return stopping.load(); });
    if (stopping.load()) break;
    auto now = Clock::now();
    if (now >= next_watchdog) {
      run_watchdogs();
      next_watchdog = std::max(next_watchdog + watchdog_period, now);
      now = Clock::now();
    }
    if (now >= next_surface) {
      publish_surfaces();
      next_surface = std::max(next_surface + surface_period, now);
    }
    if (now >= next_status) {
      const std::uint64_t s = requests_served.load(), f = surface_samples.load();
      publish_status(duration<double>(now - last_status).count(), s - last_served,
                     f - last_surfaces, solve_us, reply_us);
      last_served = s;
      last_surfaces = f;
      last_status = now;
      next_status = std::max(next_status + status_period, now);
    }
  }
}

Service::Service(const DaemonConfig& config) : impl_(std::make_unique<Impl>(config)) {}
Service::~Service() = default;

void Service::run() {
  Impl& s = *impl_;
  std::thread stream([&s] {
    try {
      s.stream_loop();
    } catch (const std::exception& e) {
      spdlog::critical("event=stream_thread_failed error=\"{}\"", e.what());
      s.stream_failure = e.what();
      s.stop();
    }
  });
  spdlog::info("event=serving models={} domain={}", s.models.size(), s.config.domain_id);
  try {
    // This thread follows client discovery; requests are served by the
    // request reader's listener.
    dds_attach_t triggered[2];
    while (!s.stopping.load()) {
      const dds_return_t n = dds_waitset_wait(s.waitset.get(), triggered, 2, DDS_INFINITY);
      if (n < 0) throw SystemError(std::string("waiting for discovery: ") + dds_strretcode(n));
      if (s.stopping.load()) break;
      s.discover_clients();
    }
  } catch (...) {
    request_stop();
    stream.join();
    throw;
  }
  stream.join();
  if (!s.stream_failure.empty())
    throw SystemError("the surface stream failed: " + s.stream_failure);
  spdlog::info("event=stopped requests_served={} error_replies={}", s.requests_served.load(),
               s.errors.load());
}

void Service::request_stop() { impl_->stop(); }

void Service::Impl::stop() {
  {
    const std::lock_guard lock(stream_mutex);
    stopping.store(true);
  }
  stream_wake.notify_all();
  dds_set_guardcondition(stop_condition.get(), true);
}

}  // namespace palpate
