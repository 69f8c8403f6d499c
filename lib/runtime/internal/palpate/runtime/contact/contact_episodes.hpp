#pragma once
/// @file
/// A tool's touch and leave events as contact episodes (internal to the
/// runtime; docs/tools.md, "One tick", step 5): a tool that loses its last
/// contact and touches again within kLeaveAfter_s was never away. Its state
/// in each feedback stays the tick's own; only the events are debounced.

#include <optional>

#include "palpate/runtime/tool_state.hpp"

namespace palpate::detail {

/// The state events of one tool, tick by tick:
///
/// - `touch` when it touches (it was free, or its last `leave` was sent);
/// - `leave` once it has had no contact for kLeaveAfter_s, at the first
///   tick that is that long after its last contact (or at once when the
///   tool's session ends): a tip hopping between triangles, a hook cutting
///   through what it touches, a tick lost to the active set, is one
///   episode, not a touch and a leave per millisecond;
/// - a grasp's own events (grasp, release) are the grasp state machine's:
///   a tool that grasps is shown grasping at once, and one that lets go
///   straight into free air sends no `leave` (it sent `release`).
///
/// Allocates nothing.
class ContactEpisodes {
 public:
  /// How long a tool is free before its `leave` is sent, s: 10 ticks at
  /// 1 kHz. The gaps it closes are 1–3 ticks (a hook cutting: contact on
  /// every other tick); a lift-off is told 10 ms late.
  static constexpr double kLeaveAfter_s = 0.010;

  /// What this tick's state @p state at @p now_s tells: kTouch, kLeave or
  /// nothing. @p ending: the tool's session ends (a pending leave is sent).
  std::optional<ToolEventKind> step(ToolState state, double now_s, bool ending = false) {
    if (state == ToolState::kFree && shown_ == ToolState::kTouching) {
      if (!free_since_s_) free_since_s_ = now_s;
      if (!ending && now_s - *free_since_s_ < kLeaveAfter_s - kTimeSlack_s) return std::nullopt;
      shown_ = ToolState::kFree;
      free_since_s_.reset();
      return ToolEventKind::kLeave;
    }
    free_since_s_.reset();
    const bool touch = state == ToolState::kTouching && shown_ == ToolState::kFree;
    shown_ = state;
    if (touch) return ToolEventKind::kTouch;
    return std::nullopt;
  }

  /// The state the events have told so far.
  ToolState shown() const { return shown_; }

 private:
  /// Ticks are whole milliseconds apart up to round-off of their clock.
  static constexpr double kTimeSlack_s = 1e-6;
  ToolState shown_ = ToolState::kFree;
  std::optional<double> free_since_s_;  // the first free tick since the last contact
};

}  // namespace palpate::detail
