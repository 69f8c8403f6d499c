#pragma once
/// @file
/// What a haptic tool is (its tip, jaws and the device's limits) and the
/// engine-wide contact settings: the configuration's [[tools]] and
/// [contact] tables in SI (docs/tools.md, docs/configuration.md), shared by
/// the contact engine, the daemon's configuration, the recordings and the
/// viewer.

#include <cstdint>
#include <string>

#include "palpate/core/units.hpp"

namespace palpate {

enum class TipShape : std::int8_t { kSphere, kCapsule };

/// One tool, from the configuration's [[tools]] tables (SI).
struct ToolGeometry {
  std::string id;  ///< the key of its ToolPose samples
  TipShape tip = TipShape::kCapsule;
  double tip_radius_m = 0.004;  ///< sphere or capsule radius
  double tip_length_m = 0.015;  ///< capsule: segment hinge → hinge + length·z; sphere: 0
  /// Coulomb friction between tip and tissue: a tip contact sticks (its
  /// vertex fully put back on the tip's surface) while its tangential force
  /// stays within friction × its normal force, and slides (normal-only
  /// constraint) beyond. 0: frictionless gliding; infinity: always sticks.
  double friction = 0.3;
  double jaw_length_m = 0.015;  ///< 0: a probe that cannot grasp
  double jaw_width_m = 0.005;
  double grasp_angle_rad = degrees(15);    ///< jaws closing below this grasp
  double release_angle_rad = degrees(25);  ///< jaws opening above this release
  double max_jaw_angle_rad = degrees(75);  ///< poses beyond are refused
  double force_limit_n = 8;                ///< the device's maximum force
  /// A cutting tool (an electrosurgical hook, scissors): its tip segment
  /// (hinge → hinge + tip_length·z) is a cutting edge, live while the jaws
  /// are closed below grasp_angle (the handle is the trigger); it removes
  /// the served cut region's tetrahedra it meets (docs/tools.md, "Cutting")
  /// and never grasps.
  bool cutting = false;
  double max_force_rate_n_per_s = 500;  ///< slew limit of the fed-back force
};

/// Engine-wide contact settings (configuration's [contact] table, SI).
struct ContactSettings {
  double watchdog_timeout_s = 0.05;  ///< no pose for this long: ramp the tool out
  double watchdog_ramp_s = 0.25;     ///< from full to no contact
  double search_margin_m = 0.01;     ///< vertices this far beyond the tip are examined
  int max_contacts_per_tool = 24;    ///< deepest tip contacts kept
  int max_iterations = 8;            ///< solves per tick (adhesion release, sliding)
  double workspace_margin_m = 0.5;   ///< poses farther from the organ's bounding box are refused
  /// The active set edits one factorization from solve to solve (rows
  /// leave by Givens rotations, join by a block append); false refactors
  /// every solve from scratch (the reference the tests and benchmarks
  /// compare it with; the same results to round-off).
  bool incremental_active_set = true;
};

}  // namespace palpate
