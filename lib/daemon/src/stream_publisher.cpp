#include "stream_publisher.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <span>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate::daemon {

StreamPublisher::StreamPublisher(Sources sources, const DaemonConfig& config,
                                 dds_entity_t participant, dds_entity_t surface_topic,
                                 dds_entity_t status_topic)
    : sources_(sources),
      config_(config),
      first_us_(LatencyLog::kCapacity),
      second_us_(LatencyLog::kCapacity) {
  surface_writer_ = dds::Entity(
      dds::check(dds_create_writer(participant, surface_topic, dds::surface_qos().get(), nullptr),
                 "creating the surface writer"));
  status_writer_ = dds::Entity(
      dds::check(dds_create_writer(participant, status_topic, dds::status_qos().get(), nullptr),
                 "creating the status writer"));
  status_.daemon_id = config_.daemon_id;
  streams_.resize(sources.models.size());
  for (std::size_t i = 0; i < streams_.size(); ++i) {
    const ServedModel& served = *sources.models[i];
    ModelStream& s = streams_[i];
    s.shown = served.shown.make_snapshot();
    s.vertex_ids.resize(s.shown.indices.size());
    s.contacts.resize(s.shown.points.size());
    // The tools' ids never change: read once, not under the tools' lock.
    const ToolContactEngine& engine = served.tools.tick->engine();
    for (int t = 0; t < engine.tool_count(); ++t) s.tool_ids.push_back(engine.tool(t).id);
    // The loads of the displacement field: the tools' and, with a served
    // cut region, its push on the rest at Γ.
    const std::size_t loads = s.shown.indices.size() + s.shown.region.interface_indices.size();
    s.load_indices.resize(loads);
    s.load_forces.resize(3 * loads);
    s.displacement = Eigen::VectorXd::Zero(served.model.compliance_rows());
    if (served.warped()) {
      s.omega.assign(static_cast<std::size_t>(served.model.compliance_rows()), 0.0);
      s.world_forces.assign(s.shown.forces.size(), 0.0);
    }
  }
}

StreamPublisher::~StreamPublisher() {
  request_stop();
  join();
}

void StreamPublisher::start(std::function<void(const std::string&)> on_failure) {
  thread_ = std::thread([this, on_failure = std::move(on_failure)] {
    try {
      loop();
    } catch (const std::exception& e) {
      spdlog::critical("event=stream_thread_failed error=\"{}\"", e.what());
      on_failure(e.what());
    }
  });
}

void StreamPublisher::request_stop() {
  {
    const std::lock_guard lock(mutex_);
    stopping_.store(true);
  }
  wake_.notify_all();
}

void StreamPublisher::join() {
  if (thread_.joinable()) thread_.join();
}

void StreamPublisher::publish_surfaces() {
  for (std::size_t i = 0; i < streams_.size(); ++i) {
    ServedModel& served = *sources_.models[i];
    ModelStream& s = streams_[i];
    if (!served.shown.copy_if_newer(s.published_version, s.shown)) continue;
    const auto count = static_cast<std::size_t>(s.shown.count);
    const ShownState::Snapshot::Region& region = s.shown.region;
    const auto gamma = static_cast<std::size_t>(region.interface_count);
    // u_S = G_SC f_C + G_SΓ f_Γ, off the request path: the tools' loads, and
    // the cut region's push on the rest at Γ (docs/model/hybrid-region.md, "The hybrid
    // model"; docs/dds.md, "The cut region"). f_Γ is not a tool's: it stays
    // out of the constrained vertices below. (The region is linear: for a
    // warped model its f_Γ enters the material field as the tools' material
    // loads do.)
    std::span<const int> load_indices(s.shown.indices.data(), count);
    const double* load_forces = s.shown.forces.data();
    if (gamma > 0) {
      std::copy_n(s.shown.indices.begin(), count, s.load_indices.begin());
      std::copy_n(region.interface_indices.begin(), gamma, s.load_indices.begin() + count);
      std::copy_n(s.shown.forces.begin(), 3 * count, s.load_forces.begin());
      std::copy_n(region.interface_forces.begin(), 3 * gamma, s.load_forces.begin() + 3 * count);
      load_indices = {s.load_indices.data(), count + gamma};
      load_forces = s.load_forces.data();
    }
    surface_displacement(served.model, load_indices, load_forces, s.displacement);
    const double* forces = s.shown.forces.data();
    if (served.warped()) {
      // The field is the material û: x − p = R̃(ω) û vertex by vertex, and a
      // load f̂ on vertex v is R̃(ω_v)⁻ᵀ f̂ in the world (docs/model/warped.md,
      // "Large rotations: warped compliance").
      served.tool_field->rotations(
          {s.displacement.data(), static_cast<std::size_t>(s.displacement.size())}, s.omega);
      for (Eigen::Index v = 0; v < s.displacement.size() / 3; ++v)
        s.displacement.segment<3>(3 * v) =
            integrated_rotation(Eigen::Map<const Eigen::Vector3d>(&s.omega[3 * std::size_t(v)])) *
            s.displacement.segment<3>(3 * v);
      for (std::size_t c = 0; c < count; ++c) {
        const auto v = static_cast<std::size_t>(s.shown.indices[c]);
        Eigen::Map<Eigen::Vector3d> world(&s.world_forces[3 * c]);
        world = integrated_rotation(Eigen::Map<const Eigen::Vector3d>(&s.omega[3 * v]))
                    .transpose()
                    .inverse() *
                Eigen::Map<const Eigen::Vector3d>(&s.shown.forces[3 * c]);
      }
      forces = s.world_forces.data();
    }
    palpate_SurfaceDisplacement& sample = s.sample;
    wire::to_idl(served.model.id, ++s.sequence_number, wire::bounded(s.shown.source),
                 s.shown.source_request, s.shown.total_force,
                 std::span<const double>(s.displacement.data(),
                                         static_cast<std::size_t>(s.displacement.size())),
                 sample);
    wire::view_loads(std::span<const int>(s.shown.indices.data(), count),
                     std::span<const double>(forces, 3 * count), served.model.surface.vertex_ids,
                     s.vertex_ids, sample);
    wire::view_contacts(std::span<const ContactPoint>(
                            s.shown.points.data(), static_cast<std::size_t>(s.shown.point_count)),
                        s.tool_ids, served.model.surface.vertex_ids, s.contacts, sample);
    // The region's surface and the rest's triangles it covers, in every
    // sample: the topic keeps the last one only, and a late viewer needs all.
    wire::view_region(
        region.topology_version,
        std::span<const double>(region.positions.data(),
                                3 * static_cast<std::size_t>(region.vertex_count)),
        std::span<const std::uint32_t>(region.triangles.data(),
                                       3 * static_cast<std::size_t>(region.triangle_count)),
        std::span<const std::uint32_t>(region.hidden_triangles.data(),
                                       static_cast<std::size_t>(region.hidden_count)),
        sample);
    if (const dds_return_t rc = dds_write(surface_writer_.get(), &sample); rc < 0)
      spdlog::error("event=dds_error what=\"writing the surface of {}\" error={}", served.model.id,
                    dds_strretcode(rc));
    else
      surface_samples_.fetch_add(1, std::memory_order_relaxed);
  }
}

void StreamPublisher::publish_status(double interval_s, std::uint64_t served_in_interval,
                                     std::uint64_t surfaces_in_interval) {
  StatusSample& status = status_;
  status.uptime_ns = sources_.clock.uptime_ns();
  status.requests_served = sources_.requests.served();
  status.error_replies = sources_.requests.errors();
  status.request_rate_hz = static_cast<double>(served_in_interval) / interval_s;
  status.surface_rate_hz = static_cast<double>(surfaces_in_interval) / interval_s;
  {
    const std::size_t n = sources_.requests.latencies().drain(first_us_, second_us_);
    status.solve = percentiles(first_us_, n);
    status.request_to_reply = percentiles(second_us_, n);
  }
  status.models = static_cast<std::uint32_t>(sources_.models.size());
  status.clients = static_cast<std::uint32_t>(sources_.clients());
  status.tool_poses = sources_.poses.served();
  status.tool_poses_refused = sources_.poses.errors();
  {
    const std::size_t n = sources_.poses.latencies().drain(first_us_, second_us_);
    status.tool_compute = percentiles(first_us_, n);
  }
  palpate_DaemonStatus sample{};
  wire::to_idl(status, sample);
  if (const dds_return_t rc = dds_write(status_writer_.get(), &sample); rc < 0)
    spdlog::error("event=dds_error what=\"writing the status\" error={}", dds_strretcode(rc));
}

void StreamPublisher::loop() {
  using namespace std::chrono;
  const auto surface_period =
      duration_cast<Clock::duration>(duration<double>(1.0 / config_.surface_rate_hz));
  const auto status_period =
      duration_cast<Clock::duration>(duration<double>(1.0 / config_.status_rate_hz));
  // The tools' watchdog: a few milliseconds of resolution on its timeout.
  const auto watchdog_period = duration_cast<Clock::duration>(milliseconds(5));
  auto next_surface = Clock::now();
  auto next_status = Clock::now() + status_period;
  auto next_watchdog = Clock::now() + watchdog_period;
  auto last_status = Clock::now();
  std::uint64_t last_served = 0, last_surfaces = 0;
  std::unique_lock lock(mutex_);
  while (!stopping_.load()) {
    wake_.wait_until(lock, std::min({next_surface, next_status, next_watchdog}),
                     [&] { return stopping_.load(); });
    if (stopping_.load()) break;
    auto now = Clock::now();
    if (now >= next_watchdog) {
      sources_.watchdog();
      next_watchdog = std::max(next_watchdog + watchdog_period, now);
      now = Clock::now();
    }
    if (now >= next_surface) {
      publish_surfaces();
      next_surface = std::max(next_surface + surface_period, now);
    }
    if (now >= next_status) {
      const std::uint64_t s = sources_.requests.served(), f = surface_samples_.load();
      publish_status(duration<double>(now - last_status).count(), s - last_served,
                     f - last_surfaces);
      last_served = s;
      last_surfaces = f;
      last_status = now;
      next_status = std::max(next_status + status_period, now);
    }
  }
}

}  // namespace palpate::daemon
