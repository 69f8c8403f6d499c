#include "tool_server.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
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
    const ToolContactEngine& engine = models_.front()->tools.tick->engine();
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
        const int tool = served->tools.tick->engine().tool_index(wire::bounded(rendered.tool_id));
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
  ToolTick& tick = *served->tools.tick;
  ToolContactEngine& engine = tick.engine();
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
  const RequestStatus status = tick.update(tool, input, now_s);
  if (tick.cut_tetrahedra() > 0) {
    const HybridRegion& region = *served->region;
    spdlog::info(
        "event=cut tool={} model={} tetrahedra={} remaining={} topology_version={} "
        "step_us={:.1f} update_rank={}",
        tool_id, model_id, tick.cut_tetrahedra(), region.tensor_mass().remaining_tetrahedra(),
        region.topology_version(), region.substep_s() * 1e6, region.update_rank());
  }
  if (tick.region_stepped()) served->shown.show_region(*served->region);
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
  const std::int32_t kind = wire::received_kind(command);
  if (kind != palpate_TOOL_COMMAND_END) {
    spdlog::warn(
        "event=tool_command_ignored tool=\"{}\" model=\"{}\" reason=unknown_kind "
        "kind={}",
        tool_id, model_id, kind);
    return;
  }
  for (const auto& served : models_) {
    if (served->model.id != model_id) continue;
    ToolTick& tick = *served->tools.tick;
    const int tool = tick.engine().tool_index(tool_id);
    if (tool < 0) break;
    const std::lock_guard lock(served->tools.mutex);
    if (tick.end(tool, clock_.seconds())) {
      spdlog::info("event=tool_session_ended tool={} model={} last_sequence={}", tool_id, model_id,
                   command.pose_sequence);
      publish(*served, tool, 0);
    }
    return;
  }
  spdlog::warn("event=tool_command_ignored tool=\"{}\" model=\"{}\" reason=unknown_tool", tool_id,
               model_id);
}

void ToolServer::publish(ServedModel& served, int tool, std::uint64_t compute_ns) {
  ToolTick& tick = *served.tools.tick;
  const ToolContactEngine& engine = tick.engine();
  const ToolOutput& out = tick.output(tool);
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

  if (served.tools.recorder)
    tick.record(tool, clock_.seconds(), compute_ns, *served.tools.recorder);
}

void ToolServer::run_watchdogs() {
  for (const auto& served : models_) {
    const std::lock_guard lock(served->tools.mutex);
    ToolTick& tick = *served->tools.tick;
    const std::uint64_t changed = tick.watchdog(clock_.seconds());
    for (int t = 0; t < tick.engine().tool_count(); ++t)
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
