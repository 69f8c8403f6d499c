#pragma once
// Private to palpate_daemon: one model as palpated serves it, and the state
// it shows on the surface stream.

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/hybrid_region.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/session_recorder.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "palpate/runtime/tool_tick.hpp"
#include "palpate/runtime/warped_solver.hpp"
#include "pi_mutex.hpp"

namespace palpate::daemon {

/// What a model shows on the surface stream: the constrained vertices and
/// their forces of the latest state-changing request or tool tick, the
/// tools' contact points (a tick's), and who set it. The request and tool servers write it, the
/// stream publisher reads it; each takes its lock. Allocation-free after construction.
class ShownState {
 public:
  /// A copy of the state, for the stream publisher.
  struct Snapshot {
    int count = 0;
    std::vector<int> indices;    // compliance indices
    std::vector<double> forces;  // 3 per index, N, tool on organ
    int point_count = 0;
    std::vector<ContactPoint> points;  // the tools' contact points; none for a request
    char source[64] = {};              // client id, or "tool:<id>"
    std::uint64_t source_request = 0;
    double total_force[3] = {};
    /// The served cut region's part (docs/model/hybrid-serving.md, "The hybrid model as
    /// served"); all counts 0 without one.
    struct Region {
      /// 0: no region; else 1 + HybridRegion::topology_version(): changes
      /// with every change of the region's surface (a cut).
      std::uint64_t topology_version = 0;
      int vertex_count = 0;
      std::vector<double> positions;  // 3 per region vertex, m, deformed, model frame
      int triangle_count = 0;
      std::vector<std::uint32_t> triangles;  // 3 per visible triangle, region vertices, outward
      int hidden_count = 0;
      std::vector<std::uint32_t> hidden_triangles;  // drawn triangles of the rest it covers
      int interface_count = 0;
      std::vector<int> interface_indices;    // compliance indices of the Γ vertices it holds
      std::vector<double> interface_forces;  // 3 per: f_Γ, its push on the rest, N
    } region;
  };

  /// Room for @p capacity constrained vertices and @p point_capacity
  /// contact points, and for @p region's state when given (it must outlive
  /// this object).
  ShownState(std::size_t capacity, std::size_t point_capacity,
             const HybridRegion* region = nullptr);
  /// A snapshot sized for this state.
  Snapshot make_snapshot() const;

  /// Replaces the state; vertices and points beyond the capacity are cut.
  /// The source is @p source_prefix followed by @p source_id. @p points
  /// are the tools' contact points (empty for a request's state).
  void show(std::span<const int> indices, std::span<const double> forces_n,
            std::span<const ContactPoint> points, std::string_view source_prefix,
            std::string_view source_id, std::uint64_t source_request, const double* total_force_n);
  /// Replaces the region's part of the state by what @p region says now
  /// (the one given to the constructor); its surface's triangles only when
  /// its topology changed.
  void show_region(const HybridRegion& region);
  /// Copies the state into @p out when it changed since @p version (then
  /// updated); false when it did not.
  bool copy_if_newer(std::uint64_t& version, Snapshot& out);

 private:
  void copy_region(const Snapshot::Region& from, Snapshot::Region& to) const;
  const HybridRegion* region_ = nullptr;
  std::vector<std::array<int, 3>> visible_;  // show_region's scratch (capacity: every face)
  PiMutex mutex_;
  std::uint64_t version_ = 1;  // the rest state: a late viewer gets a surface before any request
  Snapshot state_;
};

/// One model: its compliance, the request server's solver, the shown state,
/// and the tools acting on it.
struct ServedModel {
  /// What the daemon's configuration says of every model.
  struct Options {
    SolverLimits limits;                     ///< the tools' (no bounds on values)
    double max_displacement_fraction = 0.1;  ///< of the organ's size, for requests
    double max_force_n = 50;                 ///< for requests
    std::vector<ToolGeometry> tools;
    ContactSettings contact;
    std::filesystem::path record_directory;  ///< empty: no recording
    std::string daemon_id;                   ///< for the recordings
    std::int64_t start_unix_ns = 0;  ///< wall clock at palpated's start: time 0 of the tools
    HybridRegionSettings region;     ///< how a file's cut region is stepped
  };

  /// Serves @p loaded, with its cut region stepped (HybridRegion) when the
  /// file has one and the model is linear. When recording is on, the model's session
  /// file starts now, before any pose, so that the pose listener never creates a file (a recorder
  /// that cannot start is logged and the model served without).
  /// @p warped: warped compliance for the requests, the tools and the
  /// stream (docs/model/warped.md, "Large rotations: warped compliance").
  ServedModel(SurfaceModel loaded, const Options& options, bool warped = false);

  SurfaceModel model;
  /// The file's cut region, stepped in the tools' ticks (tools.tick, under tools.mutex);
  /// null without one, or for a warped model (the region is linear).
  std::unique_ptr<HybridRegion> region;
  /// Warped models: the rotations of requests (RotationField at
  /// kRequestEdges) and of the tools and the stream (kToolEdges); the
  /// requests' solver. Null for a linear model.
  std::unique_ptr<RotationField> request_field, tool_field;
  std::unique_ptr<WarpedSolver> warped_solver;
  bool warped() const { return warped_solver != nullptr; }
  /// The request solver's limits: the tools', with the bounds on a
  /// request's values for this organ (docs/dds.md, "Checks, in order").
  SolverLimits request_limits;
  std::unique_ptr<ConstraintSolver> solver;  // the request listener's
  ShownState shown;

  /// The tools acting on the model: their tick (the contact engine, and the
  /// cut region stepped in it). The pose listener and the watchdog (stream
  /// thread) take turns under `mutex`.
  struct Tools {
    PiMutex mutex;
    std::unique_ptr<ToolTick> tick;
    std::unique_ptr<SessionRecorder> recorder;  // when recording
    std::string ids;  // the tools' ids, "left, right": for a pose naming another
  } tools;
};

}  // namespace palpate::daemon
