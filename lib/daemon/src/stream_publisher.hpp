#pragma once
// Private to palpate_daemon: the thread that publishes each model's surface
// at the visual rate and the status heartbeat, and runs the tools' watchdog
// (docs/dds.md, "Surface stream", "Status").

#include <dds/dds.h>

#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "daemon_stats.hpp"
#include "palpate.h"
#include "palpate/daemon/daemon_config.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/messages.hpp"
#include "served_model.hpp"

namespace palpate::daemon {

class StreamPublisher {
 public:
  /// Everything the stream and the heartbeat report on.
  struct Sources {
    const std::vector<std::unique_ptr<ServedModel>>& models;
    ServerStats& requests;  ///< served: requests; errors: error replies
    ServerStats& poses;     ///< served: poses taken; errors: poses refused
    const DaemonClock& clock;
    std::function<std::size_t()> clients;  ///< clients with a reply writer
    std::function<void()> watchdog;        ///< the tools' watchdog, every 5 ms
  };
  /// Writers of @p surface_topic and @p status_topic in @p participant.
  StreamPublisher(Sources sources, const DaemonConfig& config, dds_entity_t participant,
                  dds_entity_t surface_topic, dds_entity_t status_topic);
  ~StreamPublisher();
  StreamPublisher(const StreamPublisher&) = delete;
  StreamPublisher& operator=(const StreamPublisher&) = delete;

  /// Starts the thread. If it fails, it calls @p on_failure with the reason
  /// (from the thread) and stops.
  void start(std::function<void(const std::string&)> on_failure);
  /// Makes the thread stop soon; callable from any thread.
  void request_stop();
  /// Waits for the thread to end.
  void join();

 private:
  /// What the stream thread keeps per model.
  struct ModelStream {
    ShownState::Snapshot shown;
    std::uint64_t published_version = 0;
    std::uint64_t sequence_number = 0;             // of the last sample published
    palpate_SurfaceDisplacement sample{};          // its buffers are the vectors below
    std::vector<std::uint32_t> vertex_ids;         // mesh vertex ids of shown.indices
    std::vector<palpate_SurfaceContact> contacts;  // shown.points, as sent
    std::vector<std::string> tool_ids;             // of the model's tools, by index
    // The displacement field's loads: the shown ones then the cut region's
    // f_Γ (room for both).
    std::vector<int> load_indices;
    std::vector<double> load_forces;
    Eigen::VectorXd displacement;
    // Warped models: the rotation of every compliance vertex, and the loads
    // in the world (the shown ones are material).
    std::vector<double> omega, world_forces;
  };

  void loop();
  void publish_surfaces();
  void publish_status(double interval_s, std::uint64_t served_in_interval,
                      std::uint64_t surfaces_in_interval);

  Sources sources_;
  const DaemonConfig& config_;
  dds::Entity surface_writer_, status_writer_;
  std::vector<ModelStream> streams_;
  std::vector<double> first_us_, second_us_;  // latency buffers of one interval
  StatusSample status_;                       // the heartbeat's values, its daemon id set once
  std::atomic<std::uint64_t> surface_samples_{0};
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;
};

}  // namespace palpate::daemon
