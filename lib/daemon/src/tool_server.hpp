#pragma once
// Private to palpate_daemon: tool poses in, force feedback and events out,
// tool sessions recorded (docs/tools.md, docs/dds.md "Haptic tools").

#include <dds/dds.h>

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "daemon_stats.hpp"
#include "palpate.h"
#include "palpate/transport/dds.hpp"
#include "served_model.hpp"

namespace palpate::daemon {

/// Serves poses in the pose reader's data-available listener, on Cyclone's
/// receive thread, as RequestServer serves requests: take the pose, check
/// it, update the model's ToolContactEngine (every tool solved together),
/// write the tool's feedback and events, show the contacts, record the tick.
/// The watchdog runs on the stream thread; the two take turns under each
/// model's tools.mutex. Allocation-free after construction.
class ToolServer {
 public:
  ToolServer(const std::vector<std::unique_ptr<ServedModel>>& models, std::string served_ids,
             const DaemonClock& clock);
  ~ToolServer();
  ToolServer(const ToolServer&) = delete;
  ToolServer& operator=(const ToolServer&) = delete;

  /// Creates the feedback and event writers, then the pose reader with its
  /// listener: poses are served from then on (possibly before this returns).
  void listen(dds_entity_t participant, dds_entity_t pose_topic, dds_entity_t feedback_topic,
              dds_entity_t event_topic);
  /// Deletes the pose reader: no listener call after this returns.
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
  void serve(dds_entity_t reader);
  void take(const palpate_ToolPose& pose);
  /// Feedback, events, shown state and recording of tool @p tool after a
  /// tick (with served.tools.mutex held).
  void publish(ServedModel& served, int tool, std::uint64_t compute_ns);
  void record(ServedModel& served, int tool, std::uint64_t compute_ns);

  const std::vector<std::unique_ptr<ServedModel>>& models_;
  std::string served_ids_;
  const DaemonClock& clock_;
  dds::Entity reader_, feedback_writer_, event_writer_;
  std::atomic<bool> listening_{false};  // as RequestServer::listening_

  palpate_ToolPose samples_[kBatch];
  void* sample_pointers_[kBatch] = {};
  dds_sample_info_t infos_[kBatch];

  WarningLimiter warnings_;  // the listener's only: Cyclone calls it from one thread at a time
  ServerStats stats_;
};

}  // namespace palpate::daemon
