#pragma once
/// @file
/// One tool tick of a served model, whole: the pose in, every tool's
/// contacts solved together, the served cut region (when there is one) cut
/// by a live blade and stepped, and what the tool is sent, with its session
/// record built from exactly that (docs/tools.md; docs/model/hybrid-serving.md).
///
/// Per pose of tool t (update):
///  1. The contact engine solves every tool on the rest (ToolContactEngine::
///     solve), the region's last push on the rest discounted.
///  2. With a region: a cutting tool whose jaws are closed cuts what its edge
///     swept since its last live pose (rest geometry); the drawn triangles
///     the region covers are hidden from the tools; the region is stepped
///     over the time since its last step under the rest's new contact loads
///     and the tips of the tools in session; its push on the rest f_Γ is
///     given to the engine for the next tick (set_background_loads).
///  3. What tool t feels: its contact wrench plus the region's push on its
///     tip (torque about the hinge, the tip's base), through the device's
///     force limit and slew limit together (ToolContactEngine::answer): the
///     region's push can no more step the force faster than
///     max_force_rate_n_per_s than the contacts can.
/// The watchdog's and an END's outputs are the contacts' alone (a tool out
/// of session presses no region), through the same limits.
///
/// Not thread-safe: the caller serializes every call. Allocates nothing
/// after construction (a cut's first use of the region's buffers aside:
/// HybridRegion::cut).

#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <vector>

#include "palpate/runtime/hybrid_region.hpp"
#include "palpate/runtime/session_recorder.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace palpate {

class ToolTick {
 public:
  /// The engine on @p model (which must outlive this object) for @p tools;
  /// @p warping as ToolContactEngine's. @p region, when given (outliving
  /// this object; a linear engine's only), is stepped in the ticks: its
  /// covered triangles are hidden from the tools and room is made for its
  /// push on the rest.
  /// @throws InputError for a region with a warped engine.
  ToolTick(const SurfaceModel& model, std::vector<ToolGeometry> tools,
           const ContactSettings& settings, const SolverLimits& limits,
           const RotationField* warping = nullptr, HybridRegion* region = nullptr);

  ToolContactEngine& engine() { return engine_; }
  const ToolContactEngine& engine() const { return engine_; }
  /// The served cut region, or null.
  const HybridRegion* region() const { return region_; }

  /// Takes a checked pose (ToolContactEngine::check) of tool @p tool at
  /// @p now_s (s, the engine's clock) and makes the tick (steps 1–3 above).
  /// The RequestStatus is the contact solve's (on failure the region is
  /// still stepped, under the contacts kept).
  RequestStatus update(int tool, const ToolPoseInput& pose, double now_s);
  /// ToolContactEngine::watchdog: the tools whose output changed.
  std::uint64_t watchdog(double now_s);
  /// ToolContactEngine::end.
  bool end(int tool, double now_s);

  /// What tool @p tool is sent: the last update's, watchdog's or end's output.
  const ToolOutput& output(int tool) const { return engine_.output(tool); }
  /// Tetrahedra the last update's cut removed (0: no cut, or no region).
  int cut_tetrahedra() const { return cut_tetrahedra_; }
  /// True when the last update stepped the region (its state changed).
  bool region_stepped() const { return region_stepped_; }

  /// The session record of tool @p tool's last output at @p now_s (the
  /// session clock): its pose, the force, torque and grip it was sent, its
  /// state, and @p compute_ns; its contacts by mesh vertex id with their
  /// forces on the organ (views into this object's buffers, valid until the
  /// next call; at most the engine's max_constraints × 3).
  struct Record {
    const ToolTickRecord& tick;
    std::span<const std::uint32_t> vertex_ids;
    std::span<const double> forces_n;  ///< 3 per vertex, N, on the organ
  };
  Record make_record(int tool, double now_s, std::uint64_t compute_ns);
  /// make_record(), then into @p recorder with the output's events.
  void record(int tool, double now_s, std::uint64_t compute_ns, SessionRecorder& recorder);

 private:
  /// Step 2 after tool @p tool's solve.
  void step_region(int tool, double now_s);
  RegionTip tip_of(int tool) const;

  const SurfaceModel& model_;
  ToolContactEngine engine_;
  HybridRegion* region_ = nullptr;
  // The region's tick: when it was last stepped (−1: never), the tips in
  // session and their tools; each cutting tool's edge at its last live pose
  // (rest geometry) and whether that pose's edge was live.
  double region_time_s_ = -1;
  std::vector<RegionTip> region_tips_;
  std::vector<int> region_tip_tools_;
  std::vector<Blade> blades_;
  std::vector<char> blade_live_;
  int cut_tetrahedra_ = 0;
  bool region_stepped_ = false;
  // make_record()'s.
  ToolTickRecord record_;
  std::vector<std::uint32_t> record_vertices_;
  std::vector<double> record_forces_;
};

}  // namespace palpate
