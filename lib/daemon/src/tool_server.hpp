#pragma once
// Private to palpate_daemon: tool poses in, force feedback and events out,
// tool sessions recorded (docs/tools.md, docs/dds.md "Haptic tools").

#include <dds/dds.h>

#include <array>
#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "daemon_stats.hpp"
#include "palpate.h"
#include "palpate/transport/dds.hpp"
#include "served_model.hpp"
#include "serving_thread.hpp"

namespace palpate::daemon {

/// Serves poses in the pose reader's data-available listener, on Cyclone's
/// receive thread (or palpated's serving thread), as RequestServer serves
/// requests: take the pose, check
/// it, update the model's ToolTick (every tool solved together, the cut
/// region stepped; lib/runtime/src/tick/), convert its output and
/// write the tool's response (with its local model) in the tool's own
/// partition, its feedback for older clients and viewers, and its events
/// (in both), show the contacts, record the tick.
/// A refused pose is answered with a ToolNotice (its reason in one line; the
/// first of a tool and reason, then at most one a second). A client's END
/// command ends its tool's session at once (ToolContactEngine::end). The
/// watchdog runs on the stream thread; the three take turns under each
/// model's tools.mutex. Allocation-free after construction on the pose path.
class ToolServer {
 public:
  ToolServer(const std::vector<std::unique_ptr<ServedModel>>& models, std::string served_ids,
             const DaemonClock& clock);
  ~ToolServer();
  ToolServer(const ToolServer&) = delete;
  ToolServer& operator=(const ToolServer&) = delete;

  /// The tool topics, created by the caller.
  struct Topics {
    dds_entity_t pose, feedback, event, command, notice, response, rendered;
  };
  /// Creates the feedback, event and notice writers, each tool's response
  /// and event writers in its partition (dds::tool_partition), then the pose
  /// and command readers with their listeners: poses are served from then
  /// on (possibly before this returns). With @p serving_thread, the readers
  /// have no listeners: that thread serves them once started.
  void listen(dds_entity_t participant, const Topics& topics,
              ServingThread* serving_thread = nullptr);
  /// Deletes the readers: no listener call after this returns.
  void stop();

  /// Ramps out tools whose poses stopped, and sends their feedback.
  void run_watchdogs();
  /// Closes every model's session recording (after stop()).
  void close_recorders();

  /// Poses taken, poses refused, and each tick's compute time (µs, twice:
  /// the log keeps pairs).
  ServerStats& stats() { return stats_; }

 private:
  static constexpr int kBatch = 8;  // poses taken per dds_take
  static void on_poses(dds_entity_t reader, void* arg);
  static void on_commands(dds_entity_t reader, void* arg);
  static void on_rendered(dds_entity_t reader, void* arg);
  /// What devices rendered (palpate_tool_rendered) into their tools' session
  /// recordings.
  void serve_rendered(dds_entity_t reader);
  void serve(dds_entity_t reader);
  void take(const palpate_ToolPose& pose);
  void serve_commands(dds_entity_t reader);
  void take(const palpate_ToolCommand& command);
  /// Formats a refusal's message into message_ (cut to fit; no allocation).
  template <typename... Args>
  std::string_view format_message(fmt::format_string<Args...> format, Args&&... args) {
    const auto written =
        fmt::format_to_n(message_, sizeof message_ - 1, format, std::forward<Args>(args)...);
    *written.out = '\0';
    return {message_, static_cast<std::size_t>(written.out - message_)};
  }
  /// Tells the pose's client why it was refused (rate limited per tool and reason).
  void refuse(const palpate_ToolPose& pose, PoseProblem reason, std::string_view message);
  /// Feedback, events, shown state and recording of tool @p tool after a
  /// tick (with served.tools.mutex held).
  void publish(ServedModel& served, int tool, std::uint64_t compute_ns);
  const std::vector<std::unique_ptr<ServedModel>>& models_;
  std::string served_ids_;
  const DaemonClock& clock_;
  dds::Entity reader_, command_reader_, rendered_reader_, feedback_writer_, event_writer_,
      notice_writer_;
  std::array<RenderedRecord, 32> rendered_records_{};
  /// Per tool (the engines' tool index: every model has the same tools), in
  /// the tool's partition.
  struct ToolWriters {
    dds::Entity publisher, response, event;
  };
  std::vector<ToolWriters> tool_writers_;
  palpate_ToolResponse response_{};
  std::atomic<bool> listening_{false};  // as RequestServer::listening_

  palpate_ToolPose samples_[kBatch];
  void* sample_pointers_[kBatch] = {};
  dds_sample_info_t infos_[kBatch];

  WarningLimiter warnings_;  // the pose listener's only: Cyclone calls it from one thread at a time
  // When the last notice went, per (tool and model ids hashed, reason): the
  // pose listener's only. A reason is a PoseProblem, kNone's slot unused;
  // kUnknownTool is the last one, as the wire's reading of a notice takes it.
  static constexpr std::size_t kNoticeSlots = 64;
  static constexpr std::size_t kNoticeReasons =
      static_cast<std::size_t>(PoseProblem::kUnknownTool) + 1;
  static_assert(static_cast<std::size_t>(PoseProblem::kNone) == 0 &&
                    static_cast<std::size_t>(PoseProblem::kUnknownTool) < kNoticeReasons,
                "a notice slot for every PoseProblem, numbered from 0 to kUnknownTool");
  std::array<std::array<Clock::time_point, kNoticeReasons>, kNoticeSlots> last_notice_{};
  std::array<std::array<bool, kNoticeReasons>, kNoticeSlots> noticed_{};
  palpate_ToolNotice notice_{};
  char message_[256] = {};
  ServerStats stats_;
};

}  // namespace palpate::daemon
