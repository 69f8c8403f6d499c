#include "palpate/runtime/tool_state.hpp"

namespace palpate {

const char* tool_state_name(ToolState state) {
  switch (state) {
    case ToolState::kFree:
      return "free";
    case ToolState::kTouching:
      return "touching";
    case ToolState::kGrasping:
      return "grasping";
  }
  return "unknown";
}

const char* tool_event_name(ToolEventKind kind) {
  switch (kind) {
    case ToolEventKind::kTouch:
      return "touch";
    case ToolEventKind::kLeave:
      return "leave";
    case ToolEventKind::kGrasp:
      return "grasp";
    case ToolEventKind::kRelease:
      return "release";
    case ToolEventKind::kWatchdog:
      return "watchdog";
    case ToolEventKind::kResumed:
      return "resumed";
    case ToolEventKind::kEnded:
      return "ended";
  }
  return "unknown";
}

const char* pose_problem_name(PoseProblem problem) {
  switch (problem) {
    case PoseProblem::kNone:
      return "none";
    case PoseProblem::kNonFinite:
      return "non_finite";
    case PoseProblem::kBadQuaternion:
      return "bad_quaternion";
    case PoseProblem::kBadJawAngle:
      return "bad_jaw_angle";
    case PoseProblem::kOutOfWorkspace:
      return "out_of_workspace";
    case PoseProblem::kStale:
      return "stale";
    case PoseProblem::kUnknownModel:
      return "unknown_model";
    case PoseProblem::kUnknownTool:
      return "unknown_tool";
  }
  return "unknown";
}

}  // namespace palpate
