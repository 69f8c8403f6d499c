#pragma once
/// @file
/// The haptic side of palpated's tool topics (docs/dds.md, docs/pliers.md):
/// a device publishes its tool's pose at 1 kHz on palpate_tool_pose and
/// reads, for each pose, palpated's answer on palpate_tool_response, in its
/// tool's own partition (dds::tool_partition): the force fed back and the
/// local contact model; state changes (touch, grasp, ...) come reliably on
/// palpate_tool_event, in the same partition, and the reason of a refused
/// pose on palpate_tool_notice. A client ends a tool's session with
/// end_session() (palpate_tool_command). Between answers a device renders
/// with render(), at its own rate (HapticRenderer: the local model at the
/// device's pose, the device's limits, passivity). Used by palpate-pliers
/// and the C API (palpate/device.h); a device may use it or speak the IDL
/// types directly.
///
/// Clock: send_pose() stamps ToolPose.send_time_ns with the steady clock
/// (std::chrono::steady_clock, CLOCK_MONOTONIC on Linux: nanoseconds since
/// an unspecified origin, the same for every process of the host, never set
/// back). palpated echoes it unchanged, so now_ns() − send_time_ns of a
/// feedback sample is the round trip on this host's clock alone.
///
/// The per-tick calls (send_pose, wait_feedback, take_late_feedback,
/// render) do not allocate once each tool is open (open_tool, or its first
/// pose); they are not thread-safe: one thread drives a ToolClient.

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "palpate/runtime/haptic_renderer.hpp"
#include "palpate/transport/messages.hpp"
#include "palpate/transport/presence.hpp"
#include "palpate/transport/realtime.hpp"

namespace palpate {

struct ToolClientOptions {
  std::uint32_t domain_id = 0;
  std::string dds_config;  ///< as palpated's dds.config; empty: loopback (or CYCLONEDDS_URI)
  /// Wait for feedback by polling (yielding the CPU between polls) instead of
  /// sleeping on a waitset: saves the wake-up of the waiting thread, costs
  /// its core while waiting (as ClientOptions::busy_wait).
  bool busy_wait = false;
  /// As ClientOptions::daemon_timeout: heartbeat silence after which
  /// daemon_presence() says palpated is lost (0: 3 periods + 1 s).
  std::chrono::milliseconds daemon_timeout{0};
  /// force_to_render(): a tool's last feedback is rendered for this long
  /// after it came, then ramped to zero over feedback_ramp, as palpated's
  /// watchdog does when poses stop (docs/tools.md; its defaults).
  std::chrono::milliseconds feedback_timeout{50};
  std::chrono::milliseconds feedback_ramp{250};
  /// render(): how each tool's renderer renders (its hold_s and ramp_s are
  /// taken from feedback_timeout and feedback_ramp).
  RenderSettings render{};
  /// Send palpated, with each pose, what render() rendered since the
  /// previous pose (palpate_tool_rendered), for its session recording
  /// (docs/session-recording.md, "What the device rendered").
  bool report_rendering = false;
  /// Real-time operation (docs/realtime.md): Cyclone's receive thread, which
  /// takes the answers, gets `priority` (SCHED_FIFO) and `cpus`; with
  /// `lock_memory` the process's memory is locked once the client is made.
  /// The thread driving the client (the device's loop) applies them to itself:
  /// realtime::apply_to_this_thread(options.realtime). Checked by the
  /// constructor (InputError: a value out of range, a priority the process
  /// may not use; ResourceError: memory it may not lock).
  RealtimeOptions realtime{};
};

class ToolClient {
 public:
  /// Tools one client can drive (distinct tool ids it sends poses for).
  static constexpr int kMaxTools = 8;

  /// Joins the domain (palpate's loopback configuration unless the options
  /// or CYCLONEDDS_URI give another) and creates the model and event
  /// readers, the pose writer and the feedback reader with palpated's QoS.
  /// @throws InputError for an unreadable dds_config, SystemError if DDS fails.
  explicit ToolClient(const ToolClientOptions& options);
  ~ToolClient();
  ToolClient(const ToolClient&) = delete;
  ToolClient& operator=(const ToolClient&) = delete;

  /// The steady clock in ns: the clock of send_time_ns and receive_time_ns.
  static std::int64_t now_ns();

  /// The description of @p model_id (as Client::wait_for_model: an unknown
  /// model is answered within about a second). std::nullopt if it is not served.
  std::optional<ModelInfo> wait_for_model(const std::string& model_id,
                                          std::chrono::milliseconds timeout);
  /// Ids of every model whose description came so far (to say which are
  /// served when the wanted one is not).
  std::vector<std::string> models_seen() const;

  /// Reads tool @p tool_id's responses and events from now on, in its
  /// partition (send_pose() opens a tool itself; open it before
  /// wait_for_daemon() so that the answers to its first poses are not lost
  /// while the readers are matched). Idempotent.
  /// @throws InputError for a bad id or more than kMaxTools tools.
  void open_tool(std::string_view tool_id);

  /// Waits until a daemon reads the pose and command topics and writes the
  /// notice topic and, for every open tool, its response and event topics
  /// (all volatile: samples written before the match are lost).
  /// @returns false on timeout.
  bool wait_for_daemon(std::chrono::milliseconds timeout);

  /// Publishes one pose of tool @p tool_id (1..63 characters) on @p model_id:
  /// the hinge @p position_m in the model frame (m), @p orientation_wxyz the
  /// unit quaternion tool → model, @p jaw_angle_rad the total opening.
  /// @p sequence must increase per tool (palpated drops stale ones).
  /// @returns send_time_ns, the steady clock written into the pose.
  /// @throws InputError for a bad id or more than kMaxTools tools, SystemError if the write fails.
  std::int64_t send_pose(std::string_view tool_id, std::string_view model_id,
                         std::uint64_t sequence, const std::array<double, 3>& position_m,
                         const std::array<double, 4>& orientation_wxyz, double jaw_angle_rad);

  /// The feedback of tool @p tool_id for pose @p sequence, or the first one
  /// for a newer sequence (its `sequence` says so: the answer to @p sequence
  /// was lost, or another client drives the same tool), waiting until
  /// @p deadline; std::nullopt if none came. Feedback of older sequences met
  /// on the way (answers that came after their own wait ended) is kept for
  /// take_late_feedback(); feedback for the client's other tools is kept for
  /// their own wait_feedback(). The tool must have sent a pose.
  std::optional<ToolFeedbackSample> wait_feedback(std::string_view tool_id, std::uint64_t sequence,
                                                  std::chrono::steady_clock::time_point deadline);
  /// Moves into @p out (oldest first) the feedback of @p tool_id that arrived
  /// after its wait: sequences older than the last one waited for. At most
  /// 64 are kept per tool (the oldest are dropped and counted in
  /// dropped_late_feedback()). @returns how many were written.
  std::size_t take_late_feedback(std::string_view tool_id, std::span<ToolFeedbackSample> out);
  /// Late feedback dropped because take_late_feedback() was not called in time.
  std::uint64_t dropped_late_feedback() const;
  /// Responses of a tool that came in another tool's partition, ignored:
  /// none from palpated, which writes each tool's in its own (a station no
  /// longer receives every other station's answers).
  std::uint64_t foreign_feedback() const;

  /// The events of this client's tools received since the last call, in
  /// arrival order per tool. Allocates only when there are events.
  std::vector<ToolEventSample> take_events();

  /// Why palpated refused poses of this client's tools, received since the
  /// last call, in arrival order: palpated sends the first refusal of each
  /// tool and reason, then at most one a second. Allocates only when there
  /// are notices.
  std::vector<ToolNoticeSample> take_notices();

  /// Ends the session of tool @p tool_id on @p model_id: palpated lets go at
  /// once (no watchdog ramp) and sends an `ended` event; the tool's next
  /// pose starts afresh. Waits up to @p timeout for palpated to acknowledge
  /// the command. @returns false if it was not acknowledged in time.
  /// @throws InputError for a tool that never sent a pose.
  bool end_session(std::string_view tool_id, std::string_view model_id,
                   std::chrono::milliseconds timeout);

  /// palpated's presence from its status heartbeat (Client::daemon_presence()).
  /// While it is lost, poses get no feedback; once it is back (the same
  /// process after a hang, or a restarted one) the next poses are answered:
  /// nothing to do but keep sending (docs/faults.md).
  DaemonPresence daemon_presence();

  /// The force the device should render now for tool @p tool_id (N, model
  /// frame): the latest feedback's force while it is fresh (at most
  /// feedback_timeout old); then that force ramped linearly to zero over
  /// feedback_ramp; zero before any feedback and while palpated is lost
  /// (daemon_presence()). A device renders this rather than the feedback's
  /// force, so that a daemon that dies, hangs or becomes unreachable leaves
  /// the hand with no force within feedback_timeout + feedback_ramp, not with
  /// the last force held. @p now_ns: now_ns(). Allocates nothing.
  std::array<double, 3> force_to_render(std::string_view tool_id, std::int64_t now_ns);

  /// The wrench the device should render now for tool @p tool_id, at the
  /// device's own rate (1 to 10 kHz), with the device at hinge
  /// @p position_m and orientation @p orientation_wxyz (tool → model):
  /// takes the answers that came (without waiting; a late answer still
  /// counts if it answers a newer pose), then HapticRenderer::render (the
  /// local model at this pose, contacts that only push, the hold-and-ramp
  /// of force_to_render, palpated's limits for the tool, the passivity
  /// observer). Zero before any answer and while palpated is lost. Answers
  /// it takes are also there for wait_feedback() and take_late_feedback().
  /// @p now_ns: now_ns(). Allocates nothing. The tool must be open.
  RenderedWrench render(std::string_view tool_id, const std::array<double, 3>& position_m,
                        const std::array<double, 4>& orientation_wxyz, std::int64_t now_ns);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate
