#pragma once
/// @file
/// The feel of a gesture as a trace (docs/tools.md, "The feel under
/// regression tests"): a gesture file played through ToolContactEngine in
/// process, at its nominal rate in simulated time, every tool updated once a
/// tick in the gesture's tool order, exactly as palpate-pliers sends poses to
/// palpated; what each tool feels recorded after its own update. No DDS, no
/// wall clock: the same organ and build give the same trace, to the bit.

#include <filesystem>
#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/gesture.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_geometry.hpp"
#include "palpate/runtime/tool_state.hpp"

namespace palpate::feel {

/// What one tool feels after its update at one tick (ToolOutput, SI).
struct FeelSample {
  int tick = 0;  ///< 0-based; time = tick / rate
  double time_s = 0;
  int tool = 0;                                         ///< index into FeelTrace::tools
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();    ///< on the tool, limited
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();  ///< about the hinge
  double grip_n = 0;
  int contacts = 0;  ///< contact points of the tool (tip and held)
  int held = 0;      ///< of which held by the jaws
  ToolState state = ToolState::kFree;
};

/// A played gesture: samples ordered by tick, then by tool.
struct FeelTrace {
  std::string gesture;             ///< the gesture's name
  std::vector<std::string> tools;  ///< tool ids, in the gesture's order
  int ticks = 0;                   ///< ticks played (each has every tool)
  int stride = 1;                  ///< as written: every stride-th tick, plus transitions
  int failed_solves = 0;           ///< updates whose solve failed (output repeated); not written
  /// Per tool: the tick from which the trace is not compared, because
  /// round-off alone changes it beyond the tolerance there (find_horizon(),
  /// feel_compare.hpp); ticks when the whole trace is reproducible.
  std::vector<int> horizon;
  std::vector<FeelSample> samples;
};

/// The engine set-up a trace is played with: palpated's defaults (the
/// tools "left" and "right" of DaemonConfig::default_tools(), its [contact]
/// and [limits] defaults), 1 kHz.
struct FeelSetup {
  std::vector<ToolGeometry> tools;
  ContactSettings contact;
  SolverLimits limits;
  double rate_hz = 1000;
  static FeelSetup palpated_defaults();
};

/// Plays @p gesture on @p model, anchored as palpate-pliers anchors it
/// (place_gesture on the model's surface), for floor(duration·rate) + 1
/// ticks. @throws InputError when a tool of the gesture is not one of the
/// set-up's, or a pose is refused (with the engine's reason).
FeelTrace play(const SurfaceModel& model, const Gesture& gesture, const FeelSetup& setup);

/// Moves each entry of @p model's G (double) by a factor 1 + @p relative·η,
/// η uniform in [−1, 1] from a generator seeded with @p seed, keeping G
/// symmetric: round-off of the kind a different BLAS kernel or compiler
/// leaves in a compliance file (~1e-12).
void perturb_compliance(SurfaceModel& model, double relative, unsigned seed);

/// Writes @p trace as CSV, keeping every @p stride-th tick of each tool,
/// its last tick, and the tick before and the tick of every change of its
/// state, contact count or held count (so that a transition moved by one
/// tick changes a row). '#' lines first: the gesture, the tools, the stride,
/// each tool's horizon.
void write_csv(const std::filesystem::path& file, const FeelTrace& trace, int stride,
               const std::string& comment);

/// Reads what write_csv() wrote. @throws InputError naming the file and line.
FeelTrace read_csv(const std::filesystem::path& file);

}  // namespace palpate::feel
