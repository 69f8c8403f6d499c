#pragma once
/// @file
/// A played trace against its reference, with the tolerance of the feel's
/// regression test (docs/tools.md, "The feel under regression tests").

#include <string>
#include <vector>

#include "feel/feel_trace.hpp"

namespace palpate::feel {

/// What may differ between a reference trace and a new one.
///
/// A sample matches when its force, torque and grip are each within
/// abs + rel·|reference| of the reference's (vector difference, Euclidean
/// norm), and its state, contact count and held count are equal. The
/// relative part (0.5 %) sits between round-off and physics: a different
/// BLAS kernel or compiler moves the compliance file's G by ~1e-12
/// relative, and a force solved from it by as much, while a 2 % stiffer
/// organ changes a pressed force by 2 % and a friction 0.3 → 0.31 a gliding
/// one's tangential part by 3 %. The absolute parts (1 mN, 20 µN·m, 1 mN)
/// are far below what a device renders or a hand perceives, and keep a
/// force near zero (the first tick of a touch) from failing on its
/// relative part alone.
///
/// Round-off can still flip a discrete decision of the engine whose margin
/// is at round-off (a triangle exactly at the 5 % band, a contact exactly on
/// its friction cone) and change one or two ticks, which the slew limit
/// then spreads over a few more. allowed_mismatches samples per tool may
/// therefore fail the sample test; a change of the physics fails
/// hundreds.
struct FeelTolerance {
  double force_abs_n = 1e-3;
  double force_rel = 5e-3;
  double torque_abs_nm = 2e-5;
  double torque_rel = 5e-3;
  double grip_abs_n = 1e-3;
  double grip_rel = 5e-3;
  int allowed_mismatches = 5;  ///< per tool and trace
};

/// What compare() found.
struct FeelComparison {
  bool same_shape = true;  ///< same tools and number of ticks
  int compared = 0;        ///< reference samples compared
  int mismatches = 0;      ///< samples outside the tolerance, all tools
  int worst_tool_mismatches = 0;
  double max_force_diff_n = 0;  ///< max |ΔF| over the compared samples
  double max_force_diff_time_s = 0;
  std::string first_mismatch;  ///< the first one, in words
  /// Per tool: the tick of its (allowed_mismatches + 1)-th mismatch, where
  /// it fails; the trace's ticks when it does not.
  std::vector<int> failing_tick;
  int not_compared = 0;  ///< reference samples beyond their tool's horizon
  bool passed() const;
  /// One line: mismatches, max |ΔF|, the first mismatch.
  std::string summary() const;
  FeelTolerance tolerance;
};

/// Compares @p actual (every tick, as play() returns it) with @p reference
/// (as read_csv() returns it: the ticks it kept) at the reference's samples.
/// A transition of @p actual (a change of state, contact or held count) at a
/// tick the reference did not keep is a mismatch too: the reference keeps
/// the tick before and the tick of each of its own transitions. Ticks at or
/// beyond a tool's horizon in @p reference are not compared.
FeelComparison compare(const FeelTrace& reference, const FeelTrace& actual,
                       const FeelTolerance& tolerance = {});

/// How find_horizon() probes round-off.
struct HorizonProbe {
  int seeds = 4;            ///< perturbed plays, seeds 1 to seeds
  double relative = 1e-12;  ///< perturb_compliance(): above what a BLAS kernel leaves
  int margin_ticks = 20;    ///< the horizon this many ticks before the first failure
};

/// Sets @p trace's horizon (played on @p model, every tick): @p probe.seeds
/// plays with G perturbed at round-off; for each tool, the earliest tick
/// where one of them fails compare() against @p trace, less the margin;
/// the whole trace where none fails. With the current engine a friction
/// contact's stick/slide switches and a deep press's lost contact (docs/tools.md,
/// "Limits of the model") can turn on a decision whose margin is round-off:
/// beyond such a tick no trace is reproducible on another machine.
void find_horizon(FeelTrace& trace, const SurfaceModel& model, const Gesture& gesture,
                  const FeelSetup& setup, const HorizonProbe& probe = {},
                  const FeelTolerance& tolerance = {});

}  // namespace palpate::feel
