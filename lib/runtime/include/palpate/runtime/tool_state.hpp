#pragma once
/// @file
/// A haptic tool's states, the events between them and why a pose is
/// refused: the vocabulary the contact engine, the wire module, the clients
/// and the recordings share (docs/tools.md). Numbers match idl/palpate.idl.

#include <cstdint>

namespace palpate {

/// What a tool does to the organ.
enum class ToolState : std::int32_t { kFree = 0, kTouching = 1, kGrasping = 2 };
enum class ToolEventKind : std::int32_t {
  kTouch = 0,
  kLeave,
  kGrasp,
  kRelease,
  kWatchdog,
  kResumed,
};
const char* tool_state_name(ToolState state);
const char* tool_event_name(ToolEventKind kind);

/// Why a pose was refused.
enum class PoseProblem : std::int8_t {
  kNone,
  kNonFinite,       ///< NaN or infinity
  kBadQuaternion,   ///< norm not within 1 ± 0.1
  kBadJawAngle,     ///< outside [0, max_jaw_angle]
  kOutOfWorkspace,  ///< farther than workspace_margin from the organ
  kStale,           ///< sequence not above the last one taken
};
const char* pose_problem_name(PoseProblem problem);

}  // namespace palpate
