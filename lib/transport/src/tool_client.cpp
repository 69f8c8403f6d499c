#include "palpate/transport/tool_client.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <limits>

#include "client_common.hpp"
#include "palpate.h"
#include "palpate/core/error.hpp"
#include "palpate/core/ids.hpp"
#include "palpate/core/ring.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate {

namespace {

using Clock = detail::ClientClock;
using detail::WaitableReader;

/// What the client keeps per tool it drives.
struct ToolSlot {
  char id[64] = {};
  std::size_t id_length = 0;
  std::uint64_t last_sent = 0;  // the sequence of the last pose sent
  /// Highest sequence whose wait has ended (answered or timed out): feedback
  /// at or below it is late.
  std::uint64_t done = 0;
  // The tool's partition: its responses and its events.
  dds::Entity subscriber;
  WaitableReader responses, events;
  Ring<ToolFeedbackSample, 16> pending;  // taken by render() before their wait
  Ring<ToolFeedbackSample, 64> late;
  // The newest feedback taken (highest sequence), for force_to_render().
  bool has_feedback = false;
  std::uint64_t newest_sequence = 0;
  std::int64_t newest_receive_ns = 0;
  std::array<double, 3> newest_force_n{};
  HapticRenderer renderer;
  // What render() rendered since the last pose (report_rendering), the
  // newest kRendered kept.
  static constexpr std::size_t kRendered = 32;
  std::array<RenderedRecord, kRendered> rendered{};
  std::size_t rendered_count = 0;

  void saw(const ToolFeedbackSample& s) {
    if (has_feedback && s.sequence < newest_sequence) return;
    has_feedback = true;
    newest_sequence = s.sequence;
    newest_receive_ns = s.receive_time_ns;
    newest_force_n = s.force_n;
  }

  bool is(std::string_view tool_id) const {
    return id_length == tool_id.size() && std::memcmp(id, tool_id.data(), id_length) == 0;
  }
};

void copy_id(char (&out)[64], std::string_view id) {
  std::memset(out, 0, sizeof out);
  std::memcpy(out, id.data(), std::min(id.size(), sizeof out - 1));
}

/// One answer as the renderer takes it.
RenderAnswer render_answer(const ToolFeedbackSample& s) {
  RenderAnswer a;
  a.sequence = s.sequence;
  a.model = s.local;
  a.fed_back_force_n = Eigen::Vector3d(s.force_n[0], s.force_n[1], s.force_n[2]);
  a.fed_back_torque_nm = Eigen::Vector3d(s.torque_nm[0], s.torque_nm[1], s.torque_nm[2]);
  // Limits not told (0): palpated's fed-back force is already within them.
  constexpr double kNone = std::numeric_limits<double>::infinity();
  a.force_limit_n = s.force_limit_n > 0 ? s.force_limit_n : kNone;
  a.max_force_rate_n_per_s = s.max_force_rate_n_per_s > 0 ? s.max_force_rate_n_per_s : kNone;
  return a;
}

}  // namespace

struct ToolClient::Impl {
  ToolClientOptions options;
  dds::Participant participant;
  detail::ModelDescriptions models;
  dds_entity_t pose_writer = 0, command_writer = 0, rendered_writer = 0;
  palpate_ToolRendered rendered_sample{};
  std::array<palpate_RenderedStep, ToolSlot::kRendered> rendered_steps{};
  dds_entity_t response_topic = 0, event_topic = 0;
  WaitableReader notices;
  detail::DaemonWatch watch;
  palpate_ToolPose pose{};
  std::array<ToolSlot, kMaxTools> tools;
  int tool_count = 0;
  std::uint64_t dropped_late = 0, foreign = 0;

  ToolSlot* find(std::string_view tool_id) {
    for (int i = 0; i < tool_count; ++i)
      if (tools[static_cast<std::size_t>(i)].is(tool_id))
        return &tools[static_cast<std::size_t>(i)];
    return nullptr;
  }

  ToolSlot& open(std::string_view tool_id) {
    if (ToolSlot* slot = find(tool_id)) return *slot;
    // The only place that checks ids (and may throw, and allocates).
    if (!is_valid_id(tool_id))
      throw InputError(fmt::format(
          "tool id '{}': expected 1 to 63 characters among A-Z a-z 0-9 _ - .", tool_id));
    if (tool_count == kMaxTools)
      throw InputError(fmt::format("tool '{}': one client drives at most {} tools", tool_id,
                                   static_cast<int>(kMaxTools)));
    ToolSlot& slot = tools[static_cast<std::size_t>(tool_count)];
    copy_id(slot.id, tool_id);
    slot.id_length = tool_id.size();
    const dds_entity_t p = participant.get();
    const std::string partition = dds::tool_partition(tool_id);
    const char* partitions[] = {partition.c_str()};
    dds::Qos qos(dds_create_qos());
    dds_qset_partition(qos.get(), 1, partitions);
    slot.subscriber = dds::Entity(
        dds::check(dds_create_subscriber(p, qos.get(), nullptr), "creating a tool's subscriber"));
    slot.responses =
        WaitableReader(p, slot.subscriber.get(), response_topic, dds::tool_stream_qos().get(),
                       "creating a tool's response reader");
    slot.responses.busy_wait = options.busy_wait;
    slot.events = WaitableReader(p, slot.subscriber.get(), event_topic, dds::tool_event_qos().get(),
                                 "creating a tool's event reader");
    RenderSettings render = options.render;
    render.hold_s = std::chrono::duration<double>(options.feedback_timeout).count();
    render.ramp_s = std::chrono::duration<double>(options.feedback_ramp).count();
    slot.renderer = HapticRenderer(render);
    ++tool_count;
    return slot;
  }

  void keep_late(ToolSlot& slot, const ToolFeedbackSample& s) {
    if (!slot.late.push(s)) ++dropped_late;
  }

  /// One response of @p slot's tool as taken from DDS at @p received_ns;
  /// false for one of another tool (ignored).
  bool taken(ToolSlot& slot, const palpate_ToolResponse& r, std::int64_t received_ns,
             ToolFeedbackSample& out) {
    if (!slot.is(std::string_view(r.tool_id, strnlen(r.tool_id, sizeof r.tool_id)))) {
      ++foreign;
      return false;
    }
    out = wire::from_idl(r, received_ns);
    slot.saw(out);
    slot.renderer.take(render_answer(out), static_cast<double>(received_ns) * 1e-9);
    return true;
  }
};

ToolClient::ToolClient(const ToolClientOptions& options) : impl_(std::make_unique<Impl>()) {
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
  c.pose_writer =
      dds::check(dds_create_writer(p, topic(&palpate_ToolPose_desc, dds::kToolPoseTopic),
                                   dds::tool_stream_qos().get(), nullptr),
                 "creating the tool pose writer");
  c.response_topic = topic(&palpate_ToolResponse_desc, dds::kToolResponseTopic);
  c.event_topic = topic(&palpate_ToolEvent_desc, dds::kToolEventTopic);
  c.notices = WaitableReader(p, p, topic(&palpate_ToolNotice_desc, dds::kToolNoticeTopic),
                             dds::tool_notice_qos().get(), "creating the tool notice reader");
  c.command_writer =
      dds::check(dds_create_writer(p, topic(&palpate_ToolCommand_desc, dds::kToolCommandTopic),
                                   dds::tool_command_qos().get(), nullptr),
                 "creating the tool command writer");
  c.watch = detail::DaemonWatch(p, topic(&palpate_DaemonStatus_desc, dds::kStatusTopic),
                                options.daemon_timeout);
  if (options.report_rendering)
    c.rendered_writer =
        dds::check(dds_create_writer(p, topic(&palpate_ToolRendered_desc, dds::kToolRenderedTopic),
                                     dds::tool_stream_qos().get(), nullptr),
                   "creating the rendered-steps writer");
  realtime::lock_memory(options.realtime);
}

ToolClient::~ToolClient() = default;

std::int64_t ToolClient::now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
      .count();
}

std::optional<ModelInfo> ToolClient::wait_for_model(const std::string& model_id,
                                                    std::chrono::milliseconds timeout) {
  return impl_->models.wait_for(model_id, Clock::now() + timeout, &impl_->watch);
}

std::vector<std::string> ToolClient::models_seen() const { return impl_->models.known_ids(); }

void ToolClient::open_tool(std::string_view tool_id) { impl_->open(tool_id); }

bool ToolClient::wait_for_daemon(std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  auto writer_matched = [](dds_entity_t writer, const char* what) {
    dds_publication_matched_status_t status{};
    dds::check(dds_get_publication_matched_status(writer, &status), what);
    return status.current_count > 0;
  };
  auto reader_matched = [](const WaitableReader& reader, const char* what) {
    dds_subscription_matched_status_t status{};
    dds::check(dds_get_subscription_matched_status(reader.reader.get(), &status), what);
    return status.current_count > 0;
  };
  for (;;) {
    bool matched =
        writer_matched(impl_->pose_writer, "reading the pose writer's matched status") &&
        writer_matched(impl_->command_writer, "reading the command writer's matched status") &&
        reader_matched(impl_->notices, "reading the notice reader's matched status");
    for (int i = 0; i < impl_->tool_count && matched; ++i) {
      const ToolSlot& slot = impl_->tools[static_cast<std::size_t>(i)];
      matched = reader_matched(slot.responses, "reading a response reader's matched status") &&
                reader_matched(slot.events, "reading an event reader's matched status");
    }
    if (matched) return true;
    if (Clock::now() >= deadline) return false;
    dds_sleepfor(DDS_MSECS(5));
  }
}

std::int64_t ToolClient::send_pose(std::string_view tool_id, std::string_view model_id,
                                   std::uint64_t sequence, const std::array<double, 3>& position_m,
                                   const std::array<double, 4>& orientation_wxyz,
                                   double jaw_angle_rad) {
  Impl& c = *impl_;
  palpate_ToolPose& pose = c.pose;
  ToolSlot& slot = c.open(tool_id);
  if (!is_valid_id(model_id))
    throw InputError(fmt::format(
        "model id '{}': expected 1 to 63 characters among A-Z a-z 0-9 _ - .", model_id));
  slot.last_sent = sequence;
  wire::to_idl(tool_id, model_id, sequence, position_m, orientation_wxyz, jaw_angle_rad, pose);
  // Stamped last, as close to the write as possible.
  pose.send_time_ns = now_ns();
  dds::check(dds_write(c.pose_writer, &pose), "sending a tool pose");
  if (c.rendered_writer != 0 && slot.rendered_count > 0) {
    wire::to_idl(tool_id, model_id, sequence, {slot.rendered.data(), slot.rendered_count},
                 c.rendered_steps, c.rendered_sample);
    dds::check(dds_write(c.rendered_writer, &c.rendered_sample), "sending the rendered steps");
    slot.rendered_count = 0;
  }
  return pose.send_time_ns;
}

std::optional<ToolFeedbackSample> ToolClient::wait_feedback(
    std::string_view tool_id, std::uint64_t sequence,
    std::chrono::steady_clock::time_point deadline) {
  Impl& c = *impl_;
  ToolSlot* const slot = c.find(tool_id);
  PALPATE_DEMAND(slot != nullptr);  // a tool that never sent a pose has no feedback to wait for
  std::optional<ToolFeedbackSample> answer;
  auto consider = [&](const ToolFeedbackSample& s) {
    if (s.sequence < sequence) {
      c.keep_late(*slot, s);
      return false;
    }
    answer = s;
    return true;
  };
  // What render() took before this wait first.
  while (!slot->pending.empty() && !answer) {
    consider(slot->pending.front());
    slot->pending.pop();
  }
  if (!answer) {
    slot->responses.take_until<palpate_ToolResponse>(deadline, [&](const palpate_ToolResponse& r) {
      ToolFeedbackSample s;
      return c.taken(*slot, r, now_ns(), s) && consider(s);
    });
  }
  slot->done = std::max(slot->done, answer ? std::max(sequence, answer->sequence) : sequence);
  return answer;
}

std::size_t ToolClient::take_late_feedback(std::string_view tool_id,
                                           std::span<ToolFeedbackSample> out) {
  ToolSlot* const slot = impl_->find(tool_id);
  if (slot == nullptr) return 0;
  std::size_t n = 0;
  while (n < out.size() && !slot->late.empty()) {
    out[n++] = slot->late.front();
    slot->late.pop();
  }
  return n;
}

std::uint64_t ToolClient::dropped_late_feedback() const { return impl_->dropped_late; }
std::uint64_t ToolClient::foreign_feedback() const { return impl_->foreign; }

std::vector<ToolEventSample> ToolClient::take_events() {
  std::vector<ToolEventSample> events;
  // A deadline in the past: take what is there, do not wait.
  for (int i = 0; i < impl_->tool_count; ++i)
    impl_->tools[static_cast<std::size_t>(i)].events.take_until<palpate_ToolEvent>(
        Clock::time_point{}, [&](const palpate_ToolEvent& e) {
          events.push_back(wire::from_idl(e, now_ns()));
          return false;
        });
  return events;
}

std::vector<ToolNoticeSample> ToolClient::take_notices() {
  std::vector<ToolNoticeSample> notices;
  impl_->notices.take_until<palpate_ToolNotice>(
      Clock::time_point{}, [&](const palpate_ToolNotice& n) {
        if (impl_->find(wire::bounded(n.tool_id)) != nullptr)
          notices.push_back(wire::from_idl(n, now_ns()));
        return false;
      });
  return notices;
}

bool ToolClient::end_session(std::string_view tool_id, std::string_view model_id,
                             std::chrono::milliseconds timeout) {
  const ToolSlot* const slot = impl_->find(tool_id);
  if (slot == nullptr)
    throw InputError(fmt::format("tool '{}': no pose sent, no session to end", tool_id));
  palpate_ToolCommand command{};
  wire::to_idl_end(tool_id, model_id, slot->last_sent, command);
  dds::check(dds_write(impl_->command_writer, &command), "sending the end of a tool's session");
  return dds_wait_for_acks(impl_->command_writer,
                           DDS_MSECS(std::max<std::int64_t>(0, timeout.count()))) == DDS_RETCODE_OK;
}

DaemonPresence ToolClient::daemon_presence() { return impl_->watch.poll(Clock::now()); }

std::array<double, 3> ToolClient::force_to_render(std::string_view tool_id, std::int64_t now_ns) {
  Impl& c = *impl_;
  const ToolSlot* const slot = c.find(tool_id);
  if (slot == nullptr || !slot->has_feedback ||
      c.watch.poll(Clock::now()).state == DaemonState::kLost)
    return {0, 0, 0};
  const double age_s = static_cast<double>(now_ns - slot->newest_receive_ns) * 1e-9;
  const double hold_s = std::chrono::duration<double>(c.options.feedback_timeout).count();
  const double ramp_s = std::chrono::duration<double>(c.options.feedback_ramp).count();
  const double scale =
      age_s <= hold_s ? 1.0
                      : (ramp_s > 0 ? std::clamp(1 - (age_s - hold_s) / ramp_s, 0.0, 1.0) : 0.0);
  return {scale * slot->newest_force_n[0], scale * slot->newest_force_n[1],
          scale * slot->newest_force_n[2]};
}

RenderedWrench ToolClient::render(std::string_view tool_id, const std::array<double, 3>& position_m,
                                  const std::array<double, 4>& orientation_wxyz,
                                  std::int64_t now_ns) {
  Impl& c = *impl_;
  ToolSlot* const slot = c.find(tool_id);
  PALPATE_DEMAND(slot != nullptr);  // open_tool() or a first pose opens it
  // The answers that came, without waiting; each is also kept for its wait.
  slot->responses.take_until<palpate_ToolResponse>(
      Clock::time_point{}, [&](const palpate_ToolResponse& r) {
        ToolFeedbackSample s;
        if (!c.taken(*slot, r, ToolClient::now_ns(), s)) return false;
        if (s.sequence <= slot->done)
          c.keep_late(*slot, s);
        else if (!slot->pending.push(s))
          ++c.dropped_late;
        return false;
      });
  if (c.watch.poll(Clock::now()).state == DaemonState::kLost) slot->renderer.reset();
  const RenderedWrench w =
      slot->renderer.render(static_cast<double>(now_ns) * 1e-9,
                            Eigen::Vector3d(position_m[0], position_m[1], position_m[2]),
                            Eigen::Quaterniond(orientation_wxyz[0], orientation_wxyz[1],
                                               orientation_wxyz[2], orientation_wxyz[3])
                                .normalized());
  if (c.rendered_writer != 0) {
    // The newest kRendered steps since the last pose (older ones shift out).
    if (slot->rendered_count == ToolSlot::kRendered) {
      std::move(slot->rendered.begin() + 1, slot->rendered.end(), slot->rendered.begin());
      --slot->rendered_count;
    }
    RenderedRecord& r = slot->rendered[slot->rendered_count++];
    r.time_ns = now_ns;
    r.answer_sequence = slot->renderer.has_answer() ? slot->renderer.answer().sequence : 0;
    std::copy_n(position_m.data(), 3, r.position_m);
    for (int d = 0; d < 3; ++d) r.force_n[d] = w.force_n[d];
    r.damping = w.damping;
  }
  return w;
}

}  // namespace palpate
