#include "palpate/daemon/service.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "daemon_stats.hpp"
#include "palpate.h"
#include "palpate/core/error.hpp"
#include "palpate/core/organ_size.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/realtime.hpp"
#include "palpate/transport/wire.hpp"
#include "reply_writers.hpp"
#include "request_server.hpp"
#include "served_model.hpp"
#include "serving_thread.hpp"
#include "stream_publisher.hpp"
#include "tool_server.hpp"

namespace palpate {

using daemon::Clock;

/// The wiring: the models, the DDS domain and its topics, and the servers
/// (daemon/src/: request_server, tool_server, stream_publisher, reply_writers).
struct Service::Impl {
  DaemonConfig config;
  daemon::DaemonClock clock;
  std::vector<std::unique_ptr<daemon::ServedModel>> models;
  std::string served_ids;  // "a, b" for error messages

  // Declared in construction order, destroyed in reverse: the servers stop
  // listening before the participant that owns their entities goes.
  std::shared_ptr<dds::Entity> domain;
  dds::Entity participant;
  dds::Entity model_writer, subscriptions_reader, waitset, stop_condition;
  dds_entity_t subscriptions_condition = 0;
  std::unique_ptr<daemon::ReplyWriters> replies;
  std::unique_ptr<daemon::RequestServer> requests;
  std::unique_ptr<daemon::ToolServer> tools;
  std::unique_ptr<daemon::StreamPublisher> stream;
  std::unique_ptr<daemon::ServingThread> serving;  // realtime.serve = "waitset" or "busy"
  std::atomic<bool> stopping{false};
  std::string stream_failure;  // set by the stream thread before it stops the service

  explicit Impl(const DaemonConfig& c);
  ~Impl();
  void load_models();
  void join_domain();
  void publish_descriptions();
  void warn_of_rt_throttling();
  void stop();
};

Service::Impl::Impl(const DaemonConfig& c) : config(c) {
  // Before the long part: a priority this process may not use stops it now.
  realtime::check_permitted(config.realtime);
  load_models();
  join_domain();
  auto topic = [this](const dds_topic_descriptor_t* type, const char* name) {
    return dds::topic(participant.get(), type, name);
  };
  const dds_entity_t model_topic = topic(&palpate_ModelDescription_desc, dds::kModelTopic);
  const dds_entity_t request_topic = topic(&palpate_ConstraintRequest_desc, dds::kRequestTopic);
  const dds_entity_t reply_topic = topic(&palpate_ConstraintReply_desc, dds::kReplyTopic);
  const dds_entity_t surface_topic = topic(&palpate_SurfaceDisplacement_desc, dds::kSurfaceTopic);
  const dds_entity_t status_topic = topic(&palpate_DaemonStatus_desc, dds::kStatusTopic);
  const daemon::ToolServer::Topics tool_topics{
      .pose = topic(&palpate_ToolPose_desc, dds::kToolPoseTopic),
      .feedback = topic(&palpate_ToolFeedback_desc, dds::kToolFeedbackTopic),
      .event = topic(&palpate_ToolEvent_desc, dds::kToolEventTopic),
      .command = topic(&palpate_ToolCommand_desc, dds::kToolCommandTopic),
      .notice = topic(&palpate_ToolNotice_desc, dds::kToolNoticeTopic),
      .response = topic(&palpate_ToolResponse_desc, dds::kToolResponseTopic),
      .rendered = topic(&palpate_ToolRendered_desc, dds::kToolRenderedTopic)};

  model_writer = dds::Entity(
      dds::check(dds_create_writer(participant.get(), model_topic, dds::model_qos().get(), nullptr),
                 "creating the model writer"));
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

  replies =
      std::make_unique<daemon::ReplyWriters>(participant.get(), reply_topic, config.max_clients);
  requests = std::make_unique<daemon::RequestServer>(models, served_ids, *replies,
                                                     config.limits.max_constraints);
  tools = std::make_unique<daemon::ToolServer>(models, served_ids, clock);
  stream = std::make_unique<daemon::StreamPublisher>(
      daemon::StreamPublisher::Sources{models, requests->stats(), tools->stats(), clock,
                                       [this] { return replies->count(); },
                                       [this] { tools->run_watchdogs(); }},
      config, participant.get(), surface_topic, status_topic);

  publish_descriptions();
  // Every buffer is made: from here on no page fault on the serving path.
  realtime::lock_memory(config.realtime);
  // The listeners (or the serving thread) are made last: they may serve at once.
  if (config.serve != ServeMode::kListener)
    serving =
        std::make_unique<daemon::ServingThread>(participant.get(), config.serve, config.realtime);
  requests->listen(participant.get(), request_topic, serving.get());
  tools->listen(participant.get(), tool_topics, serving.get());
  if (serving) serving->start();
  if (config.serve == ServeMode::kBusy && config.realtime.priority > 0) warn_of_rt_throttling();
  spdlog::info("event=realtime serve={} priority={} cpus=\"{}\" lock_memory={}",
               serve_mode_name(config.serve), config.realtime.priority,
               config.realtime.cpus.empty() ? std::string("any")
                                            : realtime::format_cpu_list(config.realtime.cpus),
               config.realtime.lock_memory);
}

// A SCHED_FIFO thread that never sleeps meets the kernel's real-time
// throttling: after sched_rt_runtime_us of each sched_rt_period_us (950 of
// 1000 ms by default) every real-time thread of its CPU waits out the rest.
void Service::Impl::warn_of_rt_throttling() {
  long runtime_us = 0, period_us = 0;
  std::ifstream("/proc/sys/kernel/sched_rt_runtime_us") >> runtime_us;
  std::ifstream("/proc/sys/kernel/sched_rt_period_us") >> period_us;
  if (runtime_us < 0) return;
  spdlog::warn(
      "event=realtime_throttled serve=busy priority={} sched_rt_runtime_us={} "
      "sched_rt_period_us={} hint=\"a polling SCHED_FIFO thread is stopped {} ms of every {} ms "
      "with the receive thread of its CPU: give it a CPU of its own and sysctl "
      "kernel.sched_rt_runtime_us=-1, or serve = waitset (docs/realtime.md)\"",
      config.realtime.priority, runtime_us, period_us, (period_us - runtime_us) / 1000,
      period_us / 1000);
}

void Service::Impl::load_models() {
  const auto wall_start = std::chrono::system_clock::now() - (Clock::now() - clock.started);
  const std::int64_t start_unix_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(wall_start.time_since_epoch()).count();
  daemon::ServedModel::Options options;
  options.limits = config.limits;
  options.max_displacement_fraction = config.max_displacement_fraction;
  options.max_force_n = config.max_force_n;
  options.tools = config.tools;
  options.contact = config.contact;
  options.record_directory = config.record_directory;
  options.daemon_id = config.daemon_id;
  options.start_unix_ns = start_unix_ns;
  for (const auto& entry : config.models) {
    const auto start = Clock::now();
    SurfaceModel loaded = load_surface_model(entry.id, entry.file, /*keep_float32=*/true);
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    // A float32 file stays float32 in memory: half the bytes (docs/precompute.md,
    // "Batch precomputation"); the algebra still runs in double.
    spdlog::info(
        "event=model_loaded model={} file={} compliance_vertices={} mesh_vertices={} triangles={} "
        "G_MB={:.1f} G_precision={} seconds={:.2f}",
        loaded.id, loaded.path.string(), loaded.compliance_vertex_count(),
        loaded.mesh_vertex_count(), loaded.surface.triangle_count(), loaded.G_bytes() / 1e6,
        loaded.float32() ? "float32" : "float64", seconds);
    if (!loaded.cut_region_spec.empty() && entry.warped)
      spdlog::warn("event=cut_region_not_simulated model={} region=\"{}\" hint=\"{}\"", loaded.id,
                   loaded.cut_region_spec, palpate::kCutRegionNotSimulated);
    // What precompute warned of, said again where the file is served: a
    // mesh in millimetres read as metres serves an organ hundreds of metres
    // across whose every press is a thousandth of what it should be.
    if (const double across = bounding_diagonal_m(loaded.surface.rest_positions_m);
        !plausible_organ_size(across))
      spdlog::warn(
          "event=organ_size_suspicious model={} across_m={:.3g} accepted_m={:g}-{:g} hint=\"not "
          "an organ's size: was the mesh in other units (palpate-precompute --mesh-unit)?\"",
          loaded.id, across, kPlausibleOrganMinM, kPlausibleOrganMaxM);
    served_ids += (served_ids.empty() ? "" : ", ") + loaded.id;
    models.push_back(
        std::make_unique<daemon::ServedModel>(std::move(loaded), options, entry.warped));
    if (const HybridRegion* region = models.back()->region.get()) {
      spdlog::info(
          "event=cut_region_served model={} region=\"{}\" tetrahedra={} interface_vertices={} "
          "step={} step_us={:.1f}",
          entry.id, models.back()->model.cut_region_spec, region->tensor_mass().tetrahedron_count(),
          region->interface_vertices().size(),
          region->integrator() == RegionIntegrator::kImplicit ? "implicit" : "explicit",
          region->substep_s() * 1e6);
    }
    if (entry.warped)
      spdlog::info("event=model_warped model={} request_radius_m={:.4g} tool_radius_m={:.4g}",
                   entry.id, models.back()->request_field->smoothing_radius_m(),
                   models.back()->tool_field->smoothing_radius_m());
  }
}

void Service::Impl::join_domain() {
  // Cyclone's receive thread gets the real-time priority and CPUs: it runs
  // the listeners, or wakes the serving thread.
  const dds::DomainConfig dds_config =
      dds::resolve_domain_config(config.dds_config, config.realtime);
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
}

Service::Impl::~Impl() {
  // No listener or serving call after these; then the last ticks are written.
  if (serving) serving->stop();
  if (tools) tools->stop();
  if (requests) requests->stop();
  if (tools) tools->close_recorders();
  stream.reset();
  tools.reset();
  requests.reset();
  replies.reset();
  participant.reset();  // deletes every entity of the participant
}

void Service::Impl::publish_descriptions() {
  for (const auto& served : models) {
    const palpate_ModelDescription d = wire::describe(
        served->model, served->request_limits.max_displacement_m,
        served->request_limits.max_force_n, served->warped(), served->region != nullptr);
    dds::check(dds_write(model_writer.get(), &d), "publishing model " + served->model.id);
  }
}

Service::Service(const DaemonConfig& config) : impl_(std::make_unique<Impl>(config)) {}
Service::~Service() = default;

void Service::run() {
  Impl& s = *impl_;
  s.stream->start([&s](const std::string& failure) {
    s.stream_failure = failure;
    s.stop();
  });
  spdlog::info("event=serving models={} domain={}", s.models.size(), s.config.domain_id);
  try {
    // This thread follows client discovery; requests and poses are served
    // by their readers' listeners.
    dds_attach_t triggered[2];
    while (!s.stopping.load()) {
      const dds_return_t n = dds_waitset_wait(s.waitset.get(), triggered, 2, DDS_INFINITY);
      if (n < 0) throw SystemError(std::string("waiting for discovery: ") + dds_strretcode(n));
      if (s.stopping.load()) break;
      s.replies->discover(s.subscriptions_reader.get());
    }
  } catch (...) {
    request_stop();
    s.stream->join();
    throw;
  }
  s.stream->join();
  if (!s.stream_failure.empty())
    throw SystemError("the surface stream failed: " + s.stream_failure);
  spdlog::info("event=stopped requests_served={} error_replies={}", s.requests->stats().served(),
               s.requests->stats().errors());
}

void Service::request_stop() { impl_->stop(); }

void Service::Impl::stop() {
  stopping.store(true);
  stream->request_stop();
  dds_set_guardcondition(stop_condition.get(), true);
}

}  // namespace palpate
