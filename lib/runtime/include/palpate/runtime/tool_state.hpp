#pragma once
/// @file
/// What goes into the contact engine for a tool and what comes out: its
/// pose, its output after a tick, its states, the events between them and
/// why a pose is refused. The vocabulary the engine, the wire module, the
/// clients and the recordings share (docs/tools.md). Numbers match
/// idl/palpate.idl.

#include <Eigen/Geometry>
#include <array>
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
  kEnded,  ///< the client ended the tool's session (ToolContactEngine::end)
};
/// The last ToolEventKind: the kinds are 0 to it.
inline constexpr ToolEventKind kLastToolEventKind = ToolEventKind::kEnded;
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
  kUnknownModel,    ///< the pose names a model palpated does not serve
  kUnknownTool,     ///< the pose names a tool palpated does not have
};
const char* pose_problem_name(PoseProblem problem);

/// A pose as the device sends it.
struct ToolPoseInput {
  std::uint64_t sequence = 0;
  std::int64_t send_time_ns = 0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();             ///< hinge, model frame
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< tool → model
  double jaw_angle_rad = 0;
};

/// The contact wrench of a tool linearized about the pose it answers, for
/// rendering at the device's rate between two answers (docs/tools.md, "The
/// local model"). For a pose (x, R) near the answered one (x₀, R₀),
///
///     (F, τ) ≈ (F₀, τ₀) + K (x − x₀, θ),   θ: the rotation vector of R R₀ᵀ,
///
/// with τ about the hinge and everything in the model frame. K is exact for
/// the contact set of the tick (its points, kinds and normals frozen): it
/// comes from the factorization of the tick's reduced system, with no solve
/// of the problem again.
struct LocalContactModel {
  bool valid = false;  ///< false: no model (an engine that has not solved yet)
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();             ///< x₀, the hinge
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< R₀, tool → model
  /// F₀, τ₀: the contact wrench on the tool at x₀, before the device's force
  /// and slew limits (the renderer applies them), N and N·m.
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();
  /// K = ∂(F, τ)/∂(x, θ), 6 × 6: N/m and N/rad in its first three rows,
  /// N·m/m and N·m/rad in the last three. Zero when free.
  Eigen::Matrix<double, 6, 6> stiffness = Eigen::Matrix<double, 6, 6>::Zero();
  /// The jaws hold tissue: the wrench may pull the tool. A touching tool's
  /// contacts only push (a renderer keeps F from pointing against F₀).
  bool holding = false;
};

/// What a tool feels after a tick.
struct ToolOutput {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();    ///< on the tool, limited
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();  ///< about the hinge
  double grip_n = 0;                                    ///< per jaw
  int contacts = 0;                                     ///< vertices this tool constrains
  int held = 0;                                         ///< of which held by the jaws
  ToolState state = ToolState::kFree;
  bool force_limited = false;  ///< clamped or rate limited this tick
  bool watchdog = false;       ///< ramping out
  std::uint64_t sequence = 0;  ///< of the pose it answers
  std::int64_t send_time_ns = 0;
  std::array<ToolEventKind, 4> events{};  ///< state changes of this tick, in order
  int event_count = 0;
  /// The tick's contact wrench linearized about the pose it answers; the
  /// last successful solve's when this tick's failed.
  LocalContactModel local;
};

}  // namespace palpate
