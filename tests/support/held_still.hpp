#pragma once
/// @file
/// Issue 34's hold, shared by bench/held_still.cpp and the suite's held-still
/// test (tests/feel/held_still_test.cpp): on the flattest spots of an organ
/// (the normals within 20 mm of a compliance vertex all within a few
/// degrees of its own, none of them fixed, the spots 30 mm apart), a tip
/// pressed along the spot's normal at 20 mm/s, 1 mm at a time, and held 350
/// ticks at each depth until the device's force limit, through the device
/// limits of that issue (3 N, 100 N/s). A hold is *still* when, after 50
/// ticks of settling, the force fed back changes by at most 1 mN a tick at
/// p99 and its contact count stays the same; |Δ²F| = |F_t − 2F_{t−1} +
/// F_{t−2}| shows a tick-to-tick alternation. What the engine feeds back,
/// through its public interface only.

#include <functional>
#include <vector>

#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::testing {

/// One hold at one depth, after its settling.
struct Hold {
  int spot = 0;  ///< the compliance vertex pressed
  int depth_mm = 0;
  double mean_force_n = 0, step_p99_n = 0, second_p99_n = 0;
  int least_count = 0, most_count = 0;
  bool still() const { return step_p99_n <= 1e-3 && least_count == most_count; }
  /// With `slide`: then moved 1 mm sideways at 1 mm/s, the largest ratio of
  /// a tick's |ΔF| to issue 34's bound for it, 1 % of |F| + 1 mN (≤ 1 meets
  /// it), and the ticks over the bound.
  double slide_ratio = 0;
  int slide_over = 0;
};

/// The @p count flattest spots of @p organ, 30 mm apart (compliance vertices).
std::vector<int> flattest_spots(const SurfaceModel& organ, int count);

/// A tip of the hold (a sphere, or a capsule of the default length) of
/// radius @p radius_m and friction @p friction, with the hold's device limits.
ToolGeometry held_tip(bool capsule, double radius_m, double friction);

/// Called after every tick with the engine and the depth being reached or
/// held, mm (bench/held_still.cpp's --trace).
using HoldTrace = std::function<void(const ToolContactEngine&, int depth_mm)>;

/// Tip @p tip pressed at @p spot and held at every depth until its force
/// limit; with @p slide, each hold is followed by a slow slide sideways (1 mm
/// at 1 mm/s, along the spot's tangent), and the next depth is pressed
/// where it ended. Throws on a refused pose or a failed solve.
std::vector<Hold> hold_at_every_depth(const SurfaceModel& organ, const ToolGeometry& tip, int spot,
                                      const HoldTrace& trace = {}, bool slide = false);

}  // namespace palpate::testing
