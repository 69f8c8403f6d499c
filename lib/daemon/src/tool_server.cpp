#include "tool_server.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <functional>

#include "palpate/core/error.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate::daemon {

namespace {
/// Reasons of the pose path's rate-limited warnings (WarningLimiter): one
/// each, and kBadPose + each PoseProblem.
enum PoseWarning { kUnknownModel, kUnknownTool, kSolveFailed, kBadPose };
static_assert(kBadPose + static_cast<int>(PoseProblem::kUnknownTool) < 16);
}  // namespace

ToolServer::ToolServer(const std::vector<std::unique_ptr<ServedModel>>& models,
                       std::string served_ids, const DaemonClock& clock)
    : models_(models), served_ids_(std::move(served_ids)), clock_(clock) {
  for (int i = 0; i < kBatch; ++i) sample_pointers_[i] = &samples_[i];
}

ToolServer::~ToolServer() { stop(); }

void ToolServer::listen(dds_entity_t participant, const Topics& topics,
                        ServingThread* serving_thread) {
  feedback_writer_ = dds::Entity(dds::check(
      dds_create_writer(participant, topics.feedback, dds::tool_stream_qos().get(), nullptr),
      "creating the tool feedback writer"));
  event_writer_ = dds::Entity(
      dds::check(dds_create_writer(participant, topics.event, dds::tool_event_qos().get(), nullptr),
                 "creating the tool event writer"));
  notice_writer_ = dds::Entity(dds::check(
      dds_create_writer(participant, topics.notice, dds::tool_notice_qos().get(), nullptr),
      "creating the tool notice writer"));
  // Each tool's responses and events in its own partition: a station reads
  // its tools' only (not every other station's 1 kHz answers).
  if (!models_.empty()) {
    const ToolContactEngine& engine = *models_.front()->tools.engine;
    for (int t = 0; t < engine.tool_count(); ++t) {
      const std::string partition = dds::tool_partition(engine.tool(t).id);
      const char* partitions[] = {partition.c_str()};
      dds::Qos qos(dds_create_qos());
      dds_qset_partition(qos.get(), 1, partitions);
      ToolWriters writers;
      writers.publisher = dds::Entity(dds::check(
          dds_create_publisher(participant, qos.get(), nullptr), "creating a tool's publisher"));
      writers.response =
          dds::Entity(dds::check(dds_create_writer(writers.publisher.get(), topics.response,
                                                   dds::tool_stream_qos().get(), nullptr),
                                 "creating a tool's response writer"));
      writers.event =
          dds::Entity(dds::check(dds_create_writer(writers.publisher.get(), topics.event,
                                                   dds::tool_event_qos().get(), nullptr),
                                 "creating a tool's event writer"));
      tool_writers_.push_back(std::move(writers));
    }
  }
  listening_.store(true, std::memory_order_release);
  auto reader = [&](dds_entity_t topic, const dds::Qos& qos, dds_on_data_available_fn on_data,
                    const char* what) {
    dds_listener_t* listener = nullptr;
    if (serving_thread == nullptr) {
      listener = dds_create_listener(this);
      dds_lset_data_available(listener, on_data);
    }
    const dds_entity_t created = dds_create_reader(participant, topic, qos.get(), listener);
    if (listener != nullptr) dds_delete_listener(listener);
    dds::Entity entity(dds::check(created, what));
    if (serving_thread != nullptr) serving_thread->add(entity.get(), on_data, this);
    return entity;
  };
  command_reader_ = reader(topics.command, dds::tool_command_qos(), &ToolServer::on_commands,
                           "creating the tool command reader");
  // What devices rendered: kept from several of a tool's samples at once
  // (they come with each pose; a slow take must not lose them).
  const dds::Qos rendered_qos = dds::tool_stream_qos();
  dds_qset_history(rendered_qos.get(), DDS_HISTORY_KEEP_LAST, 16);
  rendered_reader_ = reader(topics.rendered, rendered_qos, &ToolServer::on_rendered,
                            "creating the rendered-steps reader");
  reader_ = reader(topics.pose, dds::tool_stream_qos(), &ToolServer::on_poses,
                   "creating the tool pose reader");
}

void ToolServer::stop() {
  reader_.reset();
  command_reader_.reset();
  rendered_reader_.reset();
}

// Takes from the reader Cyclone names (RequestServer::on_requests says why).
void ToolServer::on_poses(dds_entity_t reader, void* arg) {
  try {
    ToolServer& server = *static_cast<ToolServer*>(arg);
    (void)server.listening_.load(std::memory_order_acquire);
    server.serve(reader);
  } catch (const std::exception& e) {
    spdlog::error("event=poses_failed error=\"{}\"", e.what());
  }
}

void ToolServer::on_commands(dds_entity_t reader, void* arg) {
  try {
    ToolServer& server = *static_cast<ToolServer*>(arg);
    (void)server.listening_.load(std::memory_order_acquire);
    server.serve_commands(reader);
  } catch (const std::exception& e) {
    spdlog::error("event=tool_commands_failed error=\"{}\"", e.what());
  }
}

void ToolServer::on_rendered(dds_entity_t reader, void* arg) {
  try {
    ToolServer& server = *static_cast<ToolServer*>(arg);
    (void)server.listening_.load(std::memory_order_acquire);
    server.serve_rendered(reader);
  } catch (const std::exception& e) {
    spdlog::error("event=rendered_steps_failed error=\"{}\"", e.what());
  }
}

void ToolServer::serve_rendered(dds_entity_t reader) {
  for (;;) {
    void* sample = nullptr;
    dds_sample_info_t info;
    const dds_return_t n = dds_take(reader, &sample, &info, 1, 1);
    if (n < 0) throw SystemError(std::string("taking rendered steps: ") + dds_strretcode(n));
    if (n == 0) return;
    if (info.valid_data) {
      const auto& rendered = *static_cast<const palpate_ToolRendered*>(sample);
      const std::string_view model_id = wire::bounded(rendered.model_id);
      for (const auto& served : models_) {
        if (served->model.id != model_id) continue;
        const int tool = served->tools.engine->tool_index(wire::bounded(rendered.tool_id));
        if (tool < 0) break;
        const std::lock_guard lock(served->tools.mutex);
        if (!served->tools.recorder) break;
        const std::size_t count = wire::from_idl(rendered, tool, rendered_records_);
        for (std::size_t i = 0; i < count; ++i)
          served->tools.recorder->record_rendered(rendered_records_[i]);
        break;
      }
    }
    dds_return_loan(reader, &sample, n);
  }
}

void ToolServer::serve(dds_entity_t reader) {
  for (;;) {
    const dds_return_t n = dds_take(reader, sample_pointers_, infos_, kBatch, kBatch);
    if (n < 0) throw SystemError(std::string("taking tool poses: ") + dds_strretcode(n));
    for (dds_return_t i = 0; i < n; ++i)
      if (infos_[i].valid_data) take(samples_[i]);
    if (n < kBatch) return;
  }
}

void ToolServer::take(const palpate_ToolPose& pose) {
  const auto start = Clock::now();
  const std::string_view tool_id = wire::bounded(pose.tool_id);
  const std::string_view model_id = wire::bounded(pose.model_id);
  ServedModel* served = nullptr;
  for (const auto& candidate : models_)
    if (candidate->model.id == model_id) served = candidate.get();
  if (served == nullptr) {
    stats_.count_error();
    warnings_.warn(kUnknownModel,
                   "event=pose_ignored tool=\"{}\" model=\"{}\" reason=unknown_model "
                   "served=\"{}\"",
                   tool_id, model_id, served_ids_);
    refuse(
        pose, PoseProblem::kUnknownModel,
        format_message("model '{}' is not served by palpated; served: {}", model_id, served_ids_));
    return;
  }
  ToolContactEngine& engine = *served->tools.engine;
  const int tool = engine.tool_index(tool_id);
  if (tool < 0) {
    stats_.count_error();
    warnings_.warn(kUnknownTool,
                   "event=pose_ignored tool=\"{}\" model={} reason=unknown_tool "
                   "hint=\"tools are configured in [[tools]]\"",
                   tool_id, model_id);
    refuse(pose, PoseProblem::kUnknownTool,
           format_message("tool '{}' is not one of palpated's tools on model '{}': {} (its "
                          "[[tools]] configuration)",
                          tool_id, model_id, served->tools.ids));
    return;
  }
  ToolPoseInput input = wire::from_idl(pose);
  const std::lock_guard lock(served->tools.mutex);
  if (const PoseProblem problem = engine.check(tool, input); problem != PoseProblem::kNone) {
    stats_.count_error();
    warnings_.warn(kBadPose + static_cast<int>(problem),
                   "event=pose_ignored tool={} model={} sequence={} reason={} "
                   "position=[{:g},{:g},{:g}] jaw_angle={:g}",
                   tool_id, model_id, pose.pose_sequence, pose_problem_name(problem),
                   pose.position[0], pose.position[1], pose.position[2], pose.jaw_angle);
    refuse(pose, problem, engine.problem_message());
    return;
  }
  const double now_s = clock_.seconds();
  const RequestStatus status = engine.update(tool, input, now_s);
  if (served->region) step_region(*served, tool, now_s);
  if (status != RequestStatus::kOk)
    warnings_.warn(kSolveFailed,
                   "event=tool_solve_failed tool={} model={} status={} message=\"{}\"", tool_id,
                   model_id, status_name(status), engine.solver_message());
  stats_.count_served();
  publish(*served, tool,
          static_cast<std::uint64_t>(
              std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start).count()));
}

void ToolServer::refuse(const palpate_ToolPose& pose, PoseProblem reason,
                        std::string_view message) {
  const std::string_view tool_id = wire::bounded(pose.tool_id);
  const std::string_view model_id = wire::bounded(pose.model_id);
  const std::size_t slot =
      (std::hash<std::string_view>{}(tool_id) ^ std::hash<std::string_view>{}(model_id)*31) %
      kNoticeSlots;
  const auto kind = static_cast<std::size_t>(reason) % kNoticeReasons;
  const auto now = Clock::now();
  if (noticed_[slot][kind] && now - last_notice_[slot][kind] < std::chrono::seconds(1)) return;
  noticed_[slot][kind] = true;
  last_notice_[slot][kind] = now;
  wire::to_idl(reason, pose.pose_sequence, message, tool_id, model_id, notice_);
  if (const dds_return_t rc = dds_write(notice_writer_.get(), &notice_); rc < 0)
    spdlog::error("event=dds_error what=\"writing a tool notice\" tool={} error={}", tool_id,
                  dds_strretcode(rc));
}

void ToolServer::serve_commands(dds_entity_t reader) {
  constexpr int kCommands = 4;
  palpate_ToolCommand commands[kCommands];
  void* pointers[kCommands];
  dds_sample_info_t infos[kCommands];
  for (int i = 0; i < kCommands; ++i) pointers[i] = &commands[i];
  for (;;) {
    const dds_return_t n = dds_take(reader, pointers, infos, kCommands, kCommands);
    if (n < 0) throw SystemError(std::string("taking tool commands: ") + dds_strretcode(n));
    for (dds_return_t i = 0; i < n; ++i)
      if (infos[i].valid_data) take(commands[i]);
    if (n < kCommands) return;
  }
}

void ToolServer::take(const palpate_ToolCommand& command) {
  const std::string_view tool_id = wire::bounded(command.tool_id);
  const std::string_view model_id = wire::bounded(command.model_id);
  std::int32_t kind = 0;
  std::memcpy(&kind, &command.kind, sizeof kind);  // any number a sender wrote
  if (kind != palpate_TOOL_COMMAND_END) {
    spdlog::warn(
        "event=tool_command_ignored tool=\"{}\" model=\"{}\" reason=unknown_kind "
        "kind={}",
        tool_id, model_id, kind);
    return;
  }
  for (const auto& served : models_) {
    if (served->model.id != model_id) continue;
    ToolContactEngine& engine = *served->tools.engine;
    const int tool = engine.tool_index(tool_id);
    if (tool < 0) break;
    const std::lock_guard lock(served->tools.mutex);
    if (engine.end(tool, clock_.seconds())) {
      spdlog::info("event=tool_session_ended tool={} model={} last_sequence={}", tool_id, model_id,
                   command.pose_sequence);
      publish(*served, tool, 0);
    }
    return;
  }
  spdlog::warn("event=tool_command_ignored tool=\"{}\" model=\"{}\" reason=unknown_tool", tool_id,
               model_id);
}

void ToolServer::step_region(ServedModel& served, int tool, double now_s) {
  HybridRegion& region = *served.region;
  ServedModel::Tools& tools = served.tools;
  ToolContactEngine& engine = *tools.engine;
  const auto tip_of = [&](int t) {
    const ToolGeometry& g = engine.tool(t);
    const ToolPoseInput& pose = engine.pose(t);
    const double length = g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0;
    return RegionTip{pose.position_m,
                     pose.position_m + length * (pose.orientation * Eigen::Vector3d::UnitZ()),
                     g.tip_radius_m};
  };
  const ToolGeometry& g = engine.tool(tool);
  const auto slot = static_cast<std::size_t>(tool);
  const bool live = g.cutting && engine.pose(tool).jaw_angle_rad <= g.grasp_angle_rad;
  if (live) {
    // The edge on the region at rest; it cuts what it swept since its last
    // live pose (or what it lies in, on the first).
    const RegionTip edge = tip_of(tool);
    const Blade now{region.rest_point_of(edge.base_m), region.rest_point_of(edge.end_m)};
    const Blade before = tools.blade_live[slot] != 0 ? tools.blades[slot] : now;
    tools.blades[slot] = now;
    if (const int removed = region.cut(before, now); removed > 0) {
      for (int t = 0; t < served.model.surface.triangle_count(); ++t)
        engine.set_triangle_hidden(t, region.covers_rest_triangle(t));
      spdlog::info(
          "event=cut tool={} model={} tetrahedra={} remaining={} topology_version={} "
          "step_us={:.1f} update_rank={}",
          g.id, served.model.id, removed, region.tensor_mass().remaining_tetrahedra(),
          region.topology_version(), region.substep_s() * 1e6, region.update_rank());
    }
  }
  tools.blade_live[slot] = live ? 1 : 0;
  tools.region_tips.clear();
  tools.region_tip_tools.clear();
  for (int t = 0; t < engine.tool_count(); ++t) {
    if (!engine.in_session(t)) continue;
    tools.region_tips.push_back(tip_of(t));
    tools.region_tip_tools.push_back(t);
  }
  // The region's clock follows the poses: the time since its last step (a
  // 1 ms tick the first time).
  const double tick_s = tools.region_time_s < 0 ? 1e-3 : now_s - tools.region_time_s;
  if (tick_s <= 0) return;
  tools.region_time_s = now_s;
  region.advance(tick_s, engine.contact_indices(), engine.contact_forces(), tools.region_tips);
  // The tools meet the rest as the region pushes it, from the next tick on.
  const Eigen::VectorXd& push = region.interface_force_n();
  engine.set_background_loads(region.interface_compliance_indices(),
                              {push.data(), static_cast<std::size_t>(push.size())},
                              {region.interface_displacement_m().data(),
                               static_cast<std::size_t>(region.interface_displacement_m().size())});
  served.shown.show_region(region);
}

const ToolOutput& ToolServer::felt(const ServedModel& served, int tool) {
  const ToolContactEngine& engine = *served.tools.engine;
  if (!served.region) return engine.output(tool);
  felt_ = engine.output(tool);
  const auto& tools = served.tools.region_tip_tools;
  const auto at = std::find(tools.begin(), tools.end(), tool);
  if (at == tools.end()) return felt_;
  const int tip = static_cast<int>(at - tools.begin());
  const Eigen::Vector3d push = served.region->tip_force_n(tip);
  if (push.squaredNorm() == 0) return felt_;
  // The tip's base is the hinge: the torque is about the same point.
  felt_.force_n += push;
  felt_.torque_nm += served.region->tip_torque_nm(tip);
  felt_.local.force_n += push;
  felt_.local.torque_nm += served.region->tip_torque_nm(tip);
  const double limit = engine.tool(tool).force_limit_n;
  if (felt_.force_n.norm() > limit) {
    felt_.force_n *= limit / felt_.force_n.norm();
    felt_.force_limited = true;
  }
  return felt_;
}

void ToolServer::publish(ServedModel& served, int tool, std::uint64_t compute_ns) {
  const ToolContactEngine& engine = *served.tools.engine;
  const ToolOutput& out = felt(served, tool);
  const std::string& tool_id = engine.tool(tool).id;
  const ToolWriters* own = static_cast<std::size_t>(tool) < tool_writers_.size()
                               ? &tool_writers_[static_cast<std::size_t>(tool)]
                               : nullptr;
  if (own != nullptr) {
    wire::to_idl(out, engine.pose(tool), engine.tool(tool), served.model.id, compute_ns, response_);
    if (const dds_return_t rc = dds_write(own->response.get(), &response_); rc < 0)
      spdlog::error("event=dds_error what=\"writing a tool response\" tool={} error={}", tool_id,
                    dds_strretcode(rc));
  }
  palpate_ToolFeedback feedback{};
  wire::to_idl(out, tool_id, served.model.id, compute_ns, feedback);
  if (const dds_return_t rc = dds_write(feedback_writer_.get(), &feedback); rc < 0)
    spdlog::error("event=dds_error what=\"writing tool feedback\" tool={} error={}", tool_id,
                  dds_strretcode(rc));
  // Ticks of a pose only: the watchdog's and an END's (compute_ns 0) would
  // pull the percentiles down.
  if (compute_ns > 0) {
    const double compute_us = static_cast<double>(compute_ns) * 1e-3;
    stats_.latencies().record(compute_us, compute_us);
  }

  for (int e = 0; e < out.event_count; ++e) {
    const ToolEventKind kind = out.events[static_cast<std::size_t>(e)];
    palpate_ToolEvent event{};
    wire::to_idl(kind, out, tool_id, served.model.id,
                 std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::system_clock::now().time_since_epoch())
                     .count(),
                 event);
    for (const dds_entity_t writer : {event_writer_.get(), own ? own->event.get() : 0})
      if (writer > 0)
        if (const dds_return_t rc = dds_write(writer, &event); rc < 0)
          spdlog::error("event=dds_error what=\"writing a tool event\" tool={} error={}", tool_id,
                        dds_strretcode(rc));
    spdlog::info("event=tool_{} tool={} model={} sequence={} held={}", tool_event_name(kind),
                 tool_id, served.model.id, out.sequence, out.held);
  }

  // The tools' contacts become the model's shown state.
  const auto forces = engine.contact_forces();
  double total[3] = {0, 0, 0};
  for (std::size_t i = 0; i < forces.size(); ++i) total[i % 3] += forces[i];
  served.shown.show(engine.contact_indices(), forces, engine.contact_points(), "tool:", tool_id,
                    out.sequence, total);

  if (served.tools.recorder) record(served, tool, compute_ns);
}

void ToolServer::record(ServedModel& served, int tool, std::uint64_t compute_ns) {
  const ToolContactEngine& engine = *served.tools.engine;
  const ToolOutput& out = engine.output(tool);
  const ToolPoseInput& pose = engine.pose(tool);
  const double now_s = clock_.seconds();
  ToolTickRecord tick;
  tick.time_s = now_s;
  tick.tool = tool;
  tick.sequence = out.sequence;
  tick.send_time_ns = out.send_time_ns;
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
  // This tool's contacts, by mesh vertex id.
  const auto indices = engine.contact_indices();
  const auto forces = engine.contact_forces();
  const auto tools_of = engine.contact_tools();
  auto& vertices = served.tools.record_vertices;
  auto& vertex_forces = served.tools.record_forces;
  std::size_t m = 0;
  for (std::size_t c = 0; c < indices.size() && m < vertices.size(); ++c) {
    if (tools_of[c] != tool) continue;
    vertices[m] = served.model.surface.vertex_ids[static_cast<std::size_t>(indices[c])];
    std::copy_n(&forces[3 * c], 3, &vertex_forces[3 * m]);
    ++m;
  }
  SessionRecorder& recorder = *served.tools.recorder;
  recorder.record(tick, {vertices.data(), m}, {vertex_forces.data(), 3 * m});
  for (int e = 0; e < out.event_count; ++e)
    recorder.record_event(now_s, tool, out.events[static_cast<std::size_t>(e)], out.sequence);
}

void ToolServer::run_watchdogs() {
  for (const auto& served : models_) {
    const std::lock_guard lock(served->tools.mutex);
    ToolContactEngine& engine = *served->tools.engine;
    const std::uint64_t changed = engine.watchdog(clock_.seconds());
    for (int t = 0; t < engine.tool_count(); ++t)
      if (changed >> t & 1) publish(*served, t, 0);
  }
}

void ToolServer::close_recorders() {
  for (const auto& served : models_) {
    const std::lock_guard lock(served->tools.mutex);
    auto& recorder = served->tools.recorder;
    if (!recorder) continue;
    try {
      recorder->close();
      spdlog::info("event=recording_closed model={} file={} ticks={} dropped={}", served->model.id,
                   recorder->path().string(), recorder->recorded(), recorder->dropped());
    } catch (const std::exception& e) {
      spdlog::error("event=recording_failed model={} error=\"{}\"", served->model.id, e.what());
    }
    recorder.reset();
  }
}

}  // namespace palpate::daemon
