#include "served_model.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <ctime>

namespace palpate::daemon {

namespace {

ShownState::Snapshot make_snapshot_of(std::size_t capacity, std::size_t point_capacity,
                                      const HybridRegion* region) {
  ShownState::Snapshot s;
  s.indices.resize(capacity);
  s.forces.resize(3 * capacity);
  s.points.resize(point_capacity);
  if (region != nullptr) {
    // Room for the most a cut can show: every face of every tetrahedron.
    const TensorMassModel& t = region->tensor_mass();
    const auto vertices = static_cast<std::size_t>(t.vertex_count());
    const auto interface = region->interface_vertices().size();
    s.region.positions.resize(3 * vertices);
    s.region.triangles.resize(3 * 4 * static_cast<std::size_t>(t.tetrahedron_count()));
    s.region.hidden_triangles.resize(static_cast<std::size_t>(region->interface_face_count()));
    s.region.interface_indices.resize(interface);
    s.region.interface_forces.resize(3 * interface);
  }
  return s;
}

std::unique_ptr<HybridRegion> region_of(const SurfaceModel& model,
                                        const ServedModel::Options& config, bool warped) {
  // The region is linear: a warped model serves the rest alone (Service says so).
  if (!model.cut_region || warped) return nullptr;
  HybridRegionSettings settings = config.region;
  settings.max_tips = std::max(1, static_cast<int>(config.tools.size()));
  return std::make_unique<HybridRegion>(model, settings);
}

}  // namespace

ShownState::ShownState(std::size_t capacity, std::size_t point_capacity, const HybridRegion* region)
    : region_(region), state_(make_snapshot_of(capacity, point_capacity, region)) {
  if (region == nullptr) return;
  visible_.reserve(4 * static_cast<std::size_t>(region->tensor_mass().tetrahedron_count()));
  show_region(*region);
}

ShownState::Snapshot ShownState::make_snapshot() const {
  return make_snapshot_of(state_.indices.size(), state_.points.size(), region_);
}

void ShownState::show_region(const HybridRegion& region) {
  const std::lock_guard lock(mutex_);
  Snapshot::Region& r = state_.region;
  const TensorMassModel& t = region.tensor_mass();
  r.vertex_count = t.vertex_count();
  for (int v = 0; v < r.vertex_count; ++v) {
    const Eigen::Vector3d x = region.position_m(v);
    std::copy_n(x.data(), 3, &r.positions[3 * static_cast<std::size_t>(v)]);
  }
  const std::vector<int>& gamma = region.interface_vertices();
  r.interface_count = static_cast<int>(gamma.size());
  std::copy_n(region.interface_compliance_indices().begin(), gamma.size(),
              r.interface_indices.begin());
  std::copy_n(region.interface_force_n().data(), 3 * gamma.size(), r.interface_forces.begin());
  if (r.topology_version != region.topology_version() + 1) {
    r.topology_version = region.topology_version() + 1;
    region.visible_triangles(visible_);
    r.triangle_count = static_cast<int>(visible_.size());
    for (std::size_t f = 0; f < visible_.size(); ++f)
      for (int c = 0; c < 3; ++c)
        r.triangles[3 * f + static_cast<std::size_t>(c)] =
            static_cast<std::uint32_t>(visible_[f][c]);
    r.hidden_count = region.covered_rest_triangles(r.hidden_triangles);
  }
  ++version_;
}

void ShownState::copy_region(const Snapshot::Region& from, Snapshot::Region& to) const {
  to.topology_version = from.topology_version;
  to.vertex_count = from.vertex_count;
  std::copy_n(from.positions.begin(), 3 * from.vertex_count, to.positions.begin());
  to.triangle_count = from.triangle_count;
  std::copy_n(from.triangles.begin(), 3 * from.triangle_count, to.triangles.begin());
  to.hidden_count = from.hidden_count;
  std::copy_n(from.hidden_triangles.begin(), from.hidden_count, to.hidden_triangles.begin());
  to.interface_count = from.interface_count;
  std::copy_n(from.interface_indices.begin(), from.interface_count, to.interface_indices.begin());
  std::copy_n(from.interface_forces.begin(), 3 * from.interface_count, to.interface_forces.begin());
}

void ShownState::show(std::span<const int> indices, std::span<const double> forces_n,
                      std::span<const ContactPoint> points, std::string_view source_prefix,
                      std::string_view source_id, std::uint64_t source_request,
                      const double* total_force_n) {
  const std::lock_guard lock(mutex_);
  const std::size_t k = std::min(indices.size(), state_.indices.size());
  state_.count = static_cast<int>(k);
  std::copy_n(indices.begin(), k, state_.indices.begin());
  std::copy_n(forces_n.begin(), 3 * k, state_.forces.begin());
  const std::size_t p = std::min(points.size(), state_.points.size());
  state_.point_count = static_cast<int>(p);
  std::copy_n(points.begin(), p, state_.points.begin());
  const std::size_t prefix = std::min(source_prefix.size(), sizeof state_.source - 1);
  std::memcpy(state_.source, source_prefix.data(), prefix);
  const std::size_t id = std::min(source_id.size(), sizeof state_.source - 1 - prefix);
  std::memcpy(state_.source + prefix, source_id.data(), id);
  state_.source[prefix + id] = '\0';
  state_.source_request = source_request;
  std::copy_n(total_force_n, 3, state_.total_force);
  ++version_;
}

bool ShownState::copy_if_newer(std::uint64_t& version, Snapshot& out) {
  const std::lock_guard lock(mutex_);
  if (version_ == version) return false;
  version = version_;
  out.count = state_.count;
  std::copy_n(state_.indices.begin(), state_.count, out.indices.begin());
  std::copy_n(state_.forces.begin(), 3 * state_.count, out.forces.begin());
  out.point_count = state_.point_count;
  std::copy_n(state_.points.begin(), state_.point_count, out.points.begin());
  std::memcpy(out.source, state_.source, sizeof out.source);
  out.source_request = state_.source_request;
  std::copy_n(state_.total_force, 3, out.total_force);
  if (region_ != nullptr) copy_region(state_.region, out.region);
  return true;
}

ServedModel::ServedModel(SurfaceModel loaded, const Options& config, bool warped)
    // A constraint at a point of a triangle loads up to 3 vertices; the
    // tools' points are constraints.
    : model(std::move(loaded)),
      region(region_of(model, config, warped)),
      shown(3 * static_cast<std::size_t>(config.limits.max_constraints),
            static_cast<std::size_t>(config.limits.max_constraints), region.get()) {
  // The organ's size: the diagonal of its surface's bounding box.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (int v = 0; v < model.surface.vertex_count(); ++v) {
    lo = lo.cwiseMin(model.surface.rest_position(v));
    hi = hi.cwiseMax(model.surface.rest_position(v));
  }
  request_limits = config.limits;
  request_limits.max_displacement_m = config.max_displacement_fraction * (hi - lo).norm();
  request_limits.max_force_n = config.max_force_n;
  solver = std::make_unique<ConstraintSolver>(model, request_limits);
  if (warped) {
    request_field = std::make_unique<RotationField>(
        model.surface, default_smoothing_radius(model.surface, kRequestEdges));
    tool_field = std::make_unique<RotationField>(
        model.surface, default_smoothing_radius(model.surface, kToolEdges));
    warped_solver = std::make_unique<WarpedSolver>(model, request_limits, *request_field);
  }
  tools.tick = std::make_unique<ToolTick>(model, config.tools, config.contact, config.limits,
                                          tool_field.get(), region.get());
  for (const ToolGeometry& tool : config.tools)
    tools.ids += (tools.ids.empty() ? "" : ", ") + tool.id;
  if (config.record_directory.empty()) return;
  try {
    SessionInfo info;
    info.model_id = model.id;
    info.model_file = model.path.string();
    info.input_hash = model.input_hash;
    info.daemon_id = config.daemon_id;
    info.tools = config.tools;
    info.contact = config.contact;
    info.start_unix_ns = config.start_unix_ns;
    const std::time_t seconds = static_cast<std::time_t>(config.start_unix_ns / 1'000'000'000);
    std::tm utc{};
    gmtime_r(&seconds, &utc);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", &utc);
    const auto file = config.record_directory / fmt::format("session-{}-{}.h5", model.id, stamp);
    tools.recorder = std::make_unique<SessionRecorder>(file, info);
    spdlog::info("event=recording_started model={} file={}", model.id, file.string());
  } catch (const std::exception& e) {
    spdlog::error("event=recording_failed model={} error=\"{}\"", model.id, e.what());
  }
}

}  // namespace palpate::daemon
