#pragma once
/// @file
/// What palpated and its clients say to each other, as C++ values: the
/// domain side of every message on palpate's topics (docs/dds.md). wire.hpp
/// converts them from and to the IDL types; Client and ToolClient hand them
/// to applications.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "palpate/runtime/drawn_surface.hpp"
#include "palpate/runtime/request_status.hpp"
#include "palpate/runtime/tool_state.hpp"

namespace palpate {

/// A model as ModelDescription gives it.
struct ModelInfo {
  std::string model_id, units, material_summary, input_hash;
  DrawnSurface surface;  ///< vertex_ids, rest_positions, triangles, compliance_vertex_count
  /// What a request may give on this model; larger is refused. 0 from a
  /// palpated older than these fields (unknown).
  double max_displacement_m = 0, max_force_n = 0;
  /// "linear", or "warped" (large rotations, docs/model/warped.md); "linear" from
  /// a palpated older than the field.
  std::string mechanics = "linear";
  /// The compliance file's cuttable region as its job chose it, when
  /// palpated simulates it (the surface samples then carry its surface);
  /// empty otherwise and from a palpated older than the field.
  std::string cut_region;
};

/// One constraint of a request (see ConstraintKind).
struct ConstraintSpec {
  std::uint32_t vertex = 0;  ///< mesh vertex id
  ConstraintKind kind = ConstraintKind::kForce;
  std::array<double, 3> value{};   ///< N or m
  std::array<double, 3> normal{};  ///< kNormalDisplacement only

  static ConstraintSpec force(std::uint32_t vertex, std::array<double, 3> force_n) {
    return {vertex, ConstraintKind::kForce, force_n, {}};
  }
  static ConstraintSpec displacement(std::uint32_t vertex, std::array<double, 3> displacement_m) {
    return {vertex, ConstraintKind::kDisplacement, displacement_m, {}};
  }
  static ConstraintSpec normal_displacement(std::uint32_t vertex, std::array<double, 3> normal,
                                            double depth_m) {
    return {vertex, ConstraintKind::kNormalDisplacement, {depth_m, 0, 0}, normal};
  }
};

struct VertexResult {
  std::uint32_t vertex = 0;
  std::array<double, 3> force_n{};
  std::array<double, 3> displacement_m{};
};

struct Reply {
  std::uint64_t request_id = 0;
  std::string model_id;
  RequestStatus status = RequestStatus::kInternalError;
  std::string message;
  double condition_estimate = 0;
  std::array<double, 3> total_force_n{};
  std::uint64_t solve_ns = 0;
  std::vector<VertexResult> results;
  std::vector<double> surface_displacement_m;  ///< 3 per compliance vertex when asked
};

/// One point where a tool touches the organ, as the surface stream carries
/// it (SurfaceContact): on the deformed surface of the sample it came with.
struct SurfaceContactSample {
  static constexpr std::uint32_t kNoVertex = 0xffffffffu;  ///< an unused slot of vertices
  std::string tool_id;
  bool held = false;  ///< held by the jaws (one vertex), else a tip contact
  /// Mesh vertex ids of the corners with a non-zero weight; kNoVertex beyond them.
  std::array<std::uint32_t, 3> vertices{kNoVertex, kNoVertex, kNoVertex};
  std::array<double, 3> weights{};     ///< barycentric, summing to 1
  std::array<double, 3> position_m{};  ///< on the deformed surface
  std::array<double, 3> force_n{};     ///< the tool on the organ
};

struct SurfaceSample {
  std::string model_id;
  std::uint64_t sequence_number = 0;
  std::string source_client_id;
  std::uint64_t source_request_id = 0;
  std::array<double, 3> total_force_n{};
  std::vector<double> displacement_m;               ///< 3 per compliance vertex
  std::vector<std::uint32_t> constrained_vertices;  ///< mesh vertex ids; empty at rest
  std::vector<double> constrained_forces_n;         ///< 3 per constrained vertex
  /// The tools' contact points; empty at rest, for a request's state and
  /// from a palpated older than the field.
  std::vector<SurfaceContactSample> contact_points;
  /// The served cut region (ModelInfo::cut_region), all empty and version 0
  /// without one or from a palpated older than the fields. displacement_m
  /// then includes the region's push on the rest.
  std::uint64_t topology_version = 0;      ///< 0: no region; changes with its surface (a cut)
  std::vector<double> region_positions_m;  ///< 3 per region vertex, deformed
  std::vector<std::uint32_t>
      region_triangles;  ///< 3 per visible triangle, region vertices, outward
  /// Triangles of the model's drawn surface (index into
  /// DrawnSurface::triangles / 3) the region covers: not to be drawn.
  std::vector<std::uint32_t> hidden_triangles;
};

struct LatencySummary {
  double p50_us = 0, p99_us = 0, p999_us = 0, max_us = 0;
};

struct StatusSample {
  std::string daemon_id;
  std::uint64_t uptime_ns = 0, requests_served = 0, error_replies = 0;
  double request_rate_hz = 0, surface_rate_hz = 0;
  LatencySummary solve, request_to_reply;
  std::uint32_t models = 0, clients = 0;
  std::uint64_t tool_poses = 0, tool_poses_refused = 0;  ///< since start
  LatencySummary tool_compute;                           ///< pose taken to feedback written
};

/// One ToolFeedback sample as this client took it.
struct ToolFeedbackSample {
  std::uint64_t sequence = 0;         ///< of the pose it answers
  std::int64_t send_time_ns = 0;      ///< that pose's send_pose() time, steady clock
  std::int64_t receive_time_ns = 0;   ///< when this client took it from DDS, steady clock
  std::array<double, 3> force_n{};    ///< the organ on the tool, model frame (render this)
  std::array<double, 3> torque_nm{};  ///< about the hinge, model frame
  double grip_n = 0;                  ///< squeeze per jaw (0 unless grasping)
  std::uint32_t contacts = 0;         ///< vertices the tool constrains
  ToolState state = ToolState::kFree;
  bool force_limited = false;    ///< clamped or rate limited this tick
  bool watchdog = false;         ///< poses stopped: the force ramps to zero
  std::uint64_t compute_ns = 0;  ///< palpated's time from taking the pose to writing this
  /// From palpate_tool_response (docs/tools.md, "The local model"): the pose
  /// it answers (local.position_m, local.orientation, and the jaw angle),
  /// the contact wrench there before the device's limits and its stiffness;
  /// local.valid is false from palpate_tool_feedback (no model). The
  /// device's limits palpated applies to the tool, N and N/s (0: not told).
  LocalContactModel local;
  double jaw_angle_rad = 0;
  double force_limit_n = 0, max_force_rate_n_per_s = 0;

  /// Round trip on this client's clock, ns.
  std::int64_t round_trip_ns() const { return receive_time_ns - send_time_ns; }
};

/// One ToolEvent sample.
struct ToolEventSample {
  std::string tool_id, model_id;
  ToolEventKind kind = ToolEventKind::kTouch;
  std::uint64_t pose_sequence = 0;   ///< the pose that caused it (the last one for the watchdog)
  std::uint32_t held_vertices = 0;   ///< surface points held by the jaws (grasp)
  std::int64_t daemon_time_ns = 0;   ///< palpated's UTC clock
  std::int64_t receive_time_ns = 0;  ///< when this client took it, steady clock
};

/// One ToolNotice sample: why palpated did not take a pose of a tool.
struct ToolNoticeSample {
  std::string tool_id, model_id;
  PoseProblem reason = PoseProblem::kNone;
  std::uint64_t pose_sequence = 0;   ///< the refused pose
  std::string message;               ///< one line: what, and what is accepted
  std::int64_t receive_time_ns = 0;  ///< when this client took it, steady clock
};

}  // namespace palpate
