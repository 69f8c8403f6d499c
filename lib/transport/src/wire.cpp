#include "palpate/transport/wire.hpp"

#include <algorithm>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "palpate/runtime/warped_solver.hpp"

namespace palpate::wire {

// The wire enums and the library's agree number for number.
static_assert(static_cast<int>(RequestStatus::kOk) == palpate_STATUS_OK);
static_assert(static_cast<int>(RequestStatus::kUnknownModel) == palpate_STATUS_UNKNOWN_MODEL);
static_assert(static_cast<int>(RequestStatus::kIllConditioned) == palpate_STATUS_ILL_CONDITIONED);
static_assert(static_cast<int>(RequestStatus::kInternalError) == palpate_STATUS_INTERNAL_ERROR);
static_assert(static_cast<int>(RequestStatus::kDisplacementTooLarge) ==
              palpate_STATUS_DISPLACEMENT_TOO_LARGE);
static_assert(static_cast<int>(RequestStatus::kForceTooLarge) == palpate_STATUS_FORCE_TOO_LARGE);
static_assert(static_cast<int>(ConstraintKind::kForce) == palpate_CONSTRAINT_FORCE);
static_assert(static_cast<int>(ConstraintKind::kNormalDisplacement) ==
              palpate_CONSTRAINT_NORMAL_DISPLACEMENT);
static_assert(static_cast<int>(ToolState::kFree) == palpate_TOOL_FREE);
static_assert(static_cast<int>(ToolState::kGrasping) == palpate_TOOL_GRASPING);
static_assert(static_cast<int>(ToolEventKind::kTouch) == palpate_TOOL_EVENT_TOUCH);
static_assert(static_cast<int>(ToolEventKind::kResumed) == palpate_TOOL_EVENT_RESUMED);
static_assert(static_cast<int>(ToolEventKind::kEnded) == palpate_TOOL_EVENT_ENDED);

namespace {

template <typename T, std::size_t N>
std::array<T, N> to_array(const T (&values)[N]) {
  std::array<T, N> a;
  std::copy_n(values, N, a.begin());
  return a;
}

/// An enum field of a received sample as the number it holds. A sender may
/// put any 32-bit value there (palpated validates it); loading it as the C
/// enum type would be undefined behaviour for a value outside its range.
template <typename Enum>
std::int32_t received(const Enum& field) {
  static_assert(sizeof(Enum) == sizeof(std::int32_t));
  std::int32_t value;
  std::memcpy(&value, &field, sizeof value);
  return value;
}

template <typename Sequence>
auto to_vector(const Sequence& sequence) {
  return std::vector(sequence._buffer, sequence._buffer + sequence._length);
}

}  // namespace

palpate_ModelDescription describe(const SurfaceModel& model, double max_displacement_m,
                                  double max_force_n, bool warped, bool region_served) {
  palpate_ModelDescription d{};
  copy_bounded(d.model_id, model.id);
  copy_bounded(d.units, "m, N (SI)");
  copy_bounded(d.material_summary, model.material_summary);
  copy_bounded(d.input_hash, model.input_hash);
  d.compliance_vertex_count = static_cast<std::uint32_t>(model.compliance_vertex_count());
  view(d.vertex_ids, std::span(model.surface.vertex_ids));
  view(d.rest_positions, std::span(model.surface.rest_positions_m));
  view(d.triangles, std::span(model.surface.triangles));
  d.max_displacement = max_displacement_m;
  d.max_force = max_force_n;
  copy_bounded(d.mechanics, warped ? "warped" : "linear");
  if (region_served) copy_bounded(d.cut_region, model.cut_region_spec);
  return d;
}

ModelInfo from_idl(const palpate_ModelDescription& d) {
  ModelInfo info;
  info.model_id = bounded(d.model_id);
  info.units = bounded(d.units);
  info.material_summary = bounded(d.material_summary);
  info.input_hash = bounded(d.input_hash);
  info.surface.compliance_vertex_count = static_cast<int>(d.compliance_vertex_count);
  info.surface.vertex_ids = to_vector(d.vertex_ids);
  info.surface.rest_positions_m = to_vector(d.rest_positions);
  info.surface.triangles = to_vector(d.triangles);
  info.max_displacement_m = d.max_displacement;
  info.max_force_n = d.max_force;
  info.mechanics = bounded(d.mechanics);
  if (info.mechanics.empty()) info.mechanics = "linear";
  info.cut_region = bounded(d.cut_region);
  return info;
}

void to_idl(std::string_view client_id, std::string_view model_id, std::uint64_t request_id,
            std::span<const ConstraintSpec> constraints, bool want_surface, bool update_state,
            std::vector<palpate_Constraint>& storage, palpate_ConstraintRequest& out) {
  storage.resize(constraints.size());
  for (std::size_t j = 0; j < constraints.size(); ++j) {
    const ConstraintSpec& s = constraints[j];
    palpate_Constraint& c = storage[j];
    c.vertex = s.vertex;
    c.kind = static_cast<palpate_ConstraintKind>(s.kind);
    std::copy(s.value.begin(), s.value.end(), c.value);
    std::copy(s.normal.begin(), s.normal.end(), c.normal);
  }
  std::memset(out.client_id, 0, sizeof out.client_id);
  std::memset(out.model_id, 0, sizeof out.model_id);
  copy_bounded(out.client_id, client_id);
  copy_bounded(out.model_id, model_id);
  out.request_id = request_id;
  out.want_surface = want_surface;
  out.update_state = update_state;
  view(out.constraints, std::span(storage));
}

namespace {

// The same for the linear and the warped solver (their interfaces agree).
template <typename Solver>
RequestStatus load_into(const palpate_ConstraintRequest& request, Solver& solver) {
  const std::uint32_t k = request.constraints._length;
  RequestStatus status = solver.begin(k);
  for (std::uint32_t j = 0; j < k && status == RequestStatus::kOk; ++j) {
    const palpate_Constraint& c = request.constraints._buffer[j];
    status = solver.add(c.vertex, received(c.kind), c.value, c.normal);
  }
  return status;
}

template <typename Solver>
void results_of(const palpate_ConstraintRequest& request, const Solver& solver,
                palpate_ConstraintReply& reply) {
  const auto forces = solver.forces();
  const auto displacements = solver.displacements();
  const auto k = static_cast<std::uint32_t>(solver.size());
  reply.results._length = k;
  for (std::uint32_t j = 0; j < k; ++j) {
    palpate_ConstraintResult& result = reply.results._buffer[j];
    result.vertex = request.constraints._buffer[j].vertex;
    for (std::uint32_t d = 0; d < 3; ++d) {
      result.force[d] = forces[3 * j + d];
      result.displacement[d] = displacements[3 * j + d];
    }
  }
  const Eigen::Vector3d total = solver.total_force();
  for (int d = 0; d < 3; ++d) reply.total_force[d] = total[d];
}

}  // namespace

RequestStatus load_constraints(const palpate_ConstraintRequest& request, ConstraintSolver& solver) {
  return load_into(request, solver);
}
RequestStatus load_constraints(const palpate_ConstraintRequest& request, WarpedSolver& solver) {
  return load_into(request, solver);
}
void write_results(const palpate_ConstraintRequest& request, const ConstraintSolver& solver,
                   palpate_ConstraintReply& reply) {
  results_of(request, solver, reply);
}
void write_results(const palpate_ConstraintRequest& request, const WarpedSolver& solver,
                   palpate_ConstraintReply& reply) {
  results_of(request, solver, reply);
}

void use_buffers(std::span<palpate_ConstraintResult> results, std::span<double> surface_m,
                 palpate_ConstraintReply& reply) {
  view(reply.results, results);
  view(reply.surface_displacement, surface_m);
  reply.results._length = 0;
  reply.surface_displacement._length = 0;
}

void start_reply(const palpate_ConstraintRequest& request, palpate_ConstraintReply& reply) {
  copy_bounded(reply.client_id, bounded(request.client_id));
  copy_bounded(reply.model_id, bounded(request.model_id));
  reply.request_id = request.request_id;
  reply.message[0] = '\0';
  reply.condition_estimate = 1;
  reply.total_force[0] = reply.total_force[1] = reply.total_force[2] = 0;
  reply.results._length = 0;
  reply.surface_displacement._length = 0;
}

namespace {

// The same for the linear and the warped solver.
template <typename Solver>
void answer_of(const palpate_ConstraintRequest& request, RequestStatus status, const Solver& solver,
               std::size_t compliance_rows, palpate_ConstraintReply& reply) {
  // Meaningful when the system was solved, or refused for its condition;
  // every other error reply carries 1 (docs/dds.md, "Status codes").
  if (status == RequestStatus::kOk || status == RequestStatus::kIllConditioned)
    reply.condition_estimate = solver.condition_estimate();
  if (status != RequestStatus::kOk) {
    write_message(solver.message(), reply);
    return;
  }
  results_of(request, solver, reply);
  if (request.want_surface) {
    const auto n = static_cast<Eigen::Index>(compliance_rows);
    solver.surface_displacement(Eigen::Map<Eigen::VectorXd>(reply.surface_displacement._buffer, n));
    reply.surface_displacement._length = static_cast<std::uint32_t>(n);
  }
}

}  // namespace

void write_answer(const palpate_ConstraintRequest& request, RequestStatus status,
                  const ConstraintSolver& solver, std::size_t compliance_rows,
                  palpate_ConstraintReply& reply) {
  answer_of(request, status, solver, compliance_rows, reply);
}
void write_answer(const palpate_ConstraintRequest& request, RequestStatus status,
                  const WarpedSolver& solver, std::size_t compliance_rows,
                  palpate_ConstraintReply& reply) {
  answer_of(request, status, solver, compliance_rows, reply);
}

void write_message(std::string_view message, palpate_ConstraintReply& reply) {
  copy_bounded(reply.message, message);
}

void write_status(RequestStatus status, palpate_ConstraintReply& reply) {
  reply.status = static_cast<palpate_ReplyStatus>(status);
  if (status != RequestStatus::kOk) {
    reply.results._length = 0;
    reply.surface_displacement._length = 0;
  }
}

Reply from_idl(const palpate_ConstraintReply& r) {
  Reply out;
  out.request_id = r.request_id;
  out.model_id = bounded(r.model_id);
  out.status = static_cast<RequestStatus>(received(r.status));
  out.message = bounded(r.message);
  out.condition_estimate = r.condition_estimate;
  out.total_force_n = to_array(r.total_force);
  out.solve_ns = r.solve_ns;
  out.results.resize(r.results._length);
  for (std::uint32_t j = 0; j < r.results._length; ++j) {
    const palpate_ConstraintResult& in = r.results._buffer[j];
    out.results[j] = {in.vertex, to_array(in.force), to_array(in.displacement)};
  }
  out.surface_displacement_m = to_vector(r.surface_displacement);
  return out;
}

void to_idl(const ContactPoint& point, std::string_view tool_id,
            std::span<const std::uint32_t> vertex_ids, palpate_SurfaceContact& out) {
  copy_bounded(out.tool_id, tool_id);
  out.held = point.held;
  const int n = std::clamp(point.vertex_count, 0, 3);
  for (int i = 0; i < 3; ++i) {
    const auto slot = static_cast<std::size_t>(i);
    const int v = point.vertices[slot];
    const bool used = i < n && v >= 0 && static_cast<std::size_t>(v) < vertex_ids.size();
    out.vertices[i] =
        used ? vertex_ids[static_cast<std::size_t>(v)] : SurfaceContactSample::kNoVertex;
    out.weights[i] = used ? point.weights[slot] : 0.0;
    out.position[i] = point.position_m[i];
    out.force[i] = point.force_n[i];
  }
}

void to_idl(std::string_view model_id, std::uint64_t sequence_number,
            std::string_view source_client_id, std::uint64_t source_request_id,
            const double (&total_force_n)[3], std::span<const double> displacement_m,
            palpate_SurfaceDisplacement& out) {
  copy_bounded(out.model_id, model_id);
  out.sequence_number = sequence_number;
  copy_bounded(out.source_client_id, source_client_id);
  out.source_request_id = source_request_id;
  std::copy_n(total_force_n, 3, out.total_force);
  view(out.displacement, displacement_m);
}

void view_loads(std::span<const int> indices, std::span<const double> forces_n,
                std::span<const std::uint32_t> vertex_ids, std::span<std::uint32_t> vertex_storage,
                palpate_SurfaceDisplacement& out) {
  for (std::size_t c = 0; c < indices.size(); ++c)
    vertex_storage[c] = vertex_ids[static_cast<std::size_t>(indices[c])];
  view(out.constrained_vertices, vertex_storage.first(indices.size()));
  view(out.constrained_forces, forces_n);
}

void view_contacts(std::span<const ContactPoint> points, std::span<const std::string> tool_ids,
                   std::span<const std::uint32_t> vertex_ids,
                   std::span<palpate_SurfaceContact> storage, palpate_SurfaceDisplacement& out) {
  for (std::size_t c = 0; c < points.size(); ++c) {
    const auto tool = static_cast<std::size_t>(points[c].tool);
    to_idl(points[c], tool < tool_ids.size() ? std::string_view(tool_ids[tool]) : "", vertex_ids,
           storage[c]);
  }
  view(out.contact_points, storage.first(points.size()));
}

SurfaceContactSample from_idl(const palpate_SurfaceContact& c) {
  SurfaceContactSample out;
  out.tool_id = bounded(c.tool_id);
  out.held = c.held;
  out.vertices = to_array(c.vertices);
  out.weights = to_array(c.weights);
  out.position_m = to_array(c.position);
  out.force_n = to_array(c.force);
  return out;
}

SurfaceSample from_idl(const palpate_SurfaceDisplacement& s) {
  SurfaceSample out;
  out.model_id = bounded(s.model_id);
  out.sequence_number = s.sequence_number;
  out.source_client_id = bounded(s.source_client_id);
  out.source_request_id = s.source_request_id;
  out.total_force_n = to_array(s.total_force);
  out.displacement_m = to_vector(s.displacement);
  out.constrained_vertices = to_vector(s.constrained_vertices);
  out.constrained_forces_n = to_vector(s.constrained_forces);
  out.contact_points.reserve(s.contact_points._length);
  for (std::uint32_t c = 0; c < s.contact_points._length; ++c)
    out.contact_points.push_back(from_idl(s.contact_points._buffer[c]));
  out.topology_version = s.topology_version;
  out.region_positions_m = to_vector(s.region_positions);
  out.region_triangles = to_vector(s.region_triangles);
  out.hidden_triangles = to_vector(s.hidden_triangles);
  return out;
}

void view_region(std::uint64_t topology_version, std::span<const double> positions_m,
                 std::span<const std::uint32_t> triangles,
                 std::span<const std::uint32_t> hidden_triangles,
                 palpate_SurfaceDisplacement& out) {
  out.topology_version = topology_version;
  view(out.region_positions, positions_m);
  view(out.region_triangles, triangles);
  view(out.hidden_triangles, hidden_triangles);
}

LatencySummary from_idl(const palpate_Latency& l) {
  return {l.p50_us, l.p99_us, l.p999_us, l.max_us};
}

palpate_Latency to_idl(const LatencySummary& l) {
  return {l.p50_us, l.p99_us, l.p999_us, l.max_us};
}

void to_idl(const StatusSample& s, palpate_DaemonStatus& out) {
  copy_bounded(out.daemon_id, s.daemon_id);
  out.uptime_ns = s.uptime_ns;
  out.requests_served = s.requests_served;
  out.error_replies = s.error_replies;
  out.request_rate_hz = s.request_rate_hz;
  out.surface_rate_hz = s.surface_rate_hz;
  out.solve = to_idl(s.solve);
  out.request_to_reply = to_idl(s.request_to_reply);
  out.models = s.models;
  out.clients = s.clients;
  out.tool_poses = s.tool_poses;
  out.tool_poses_refused = s.tool_poses_refused;
  out.tool_compute = to_idl(s.tool_compute);
}

StatusSample from_idl(const palpate_DaemonStatus& s) {
  StatusSample out;
  out.daemon_id = bounded(s.daemon_id);
  out.uptime_ns = s.uptime_ns;
  out.requests_served = s.requests_served;
  out.error_replies = s.error_replies;
  out.request_rate_hz = s.request_rate_hz;
  out.surface_rate_hz = s.surface_rate_hz;
  out.solve = from_idl(s.solve);
  out.request_to_reply = from_idl(s.request_to_reply);
  out.models = s.models;
  out.clients = s.clients;
  out.tool_poses = s.tool_poses;
  out.tool_poses_refused = s.tool_poses_refused;
  out.tool_compute = from_idl(s.tool_compute);
  return out;
}

void to_idl(std::string_view tool_id, std::string_view model_id, std::uint64_t sequence,
            const std::array<double, 3>& position_m, const std::array<double, 4>& orientation_wxyz,
            double jaw_angle_rad, palpate_ToolPose& out) {
  std::memset(out.tool_id, 0, sizeof out.tool_id);
  std::memset(out.model_id, 0, sizeof out.model_id);
  copy_bounded(out.tool_id, tool_id);
  copy_bounded(out.model_id, model_id);
  out.pose_sequence = sequence;
  std::copy(position_m.begin(), position_m.end(), out.position);
  std::copy(orientation_wxyz.begin(), orientation_wxyz.end(), out.orientation);
  out.jaw_angle = jaw_angle_rad;
}

ToolPoseInput from_idl(const palpate_ToolPose& pose) {
  ToolPoseInput input;
  input.sequence = pose.pose_sequence;
  input.send_time_ns = pose.send_time_ns;
  input.position_m = Eigen::Vector3d(pose.position[0], pose.position[1], pose.position[2]);
  input.orientation = Eigen::Quaterniond(pose.orientation[0], pose.orientation[1],
                                         pose.orientation[2], pose.orientation[3]);
  input.jaw_angle_rad = pose.jaw_angle;
  return input;
}

namespace {

/// The fields ToolFeedback and ToolResponse share, written from a tick's output.
template <typename Sample>
void write_feedback(const ToolOutput& out, std::string_view tool_id, std::string_view model_id,
                    std::uint64_t compute_ns, Sample& sample) {
  copy_bounded(sample.tool_id, tool_id);
  copy_bounded(sample.model_id, model_id);
  sample.pose_sequence = out.sequence;
  sample.send_time_ns = out.send_time_ns;
  for (int d = 0; d < 3; ++d) {
    sample.force[d] = out.force_n[d];
    sample.torque[d] = out.torque_nm[d];
  }
  sample.grip_force = out.grip_n;
  sample.contacts = static_cast<std::uint32_t>(out.contacts);
  sample.state = static_cast<palpate_ToolState>(out.state);
  sample.force_limited = out.force_limited;
  sample.watchdog = out.watchdog;
  sample.compute_ns = compute_ns;
}

/// The same fields as a client's sample, taken at @p receive_time_ns.
template <typename Sample>
ToolFeedbackSample read_feedback(const Sample& f, std::int64_t receive_time_ns) {
  ToolFeedbackSample s;
  s.sequence = f.pose_sequence;
  s.send_time_ns = f.send_time_ns;
  s.receive_time_ns = receive_time_ns;
  s.force_n = to_array(f.force);
  s.torque_nm = to_array(f.torque);
  s.grip_n = f.grip_force;
  s.contacts = f.contacts;
  s.state = static_cast<ToolState>(received(f.state));
  s.force_limited = f.force_limited;
  s.watchdog = f.watchdog;
  s.compute_ns = f.compute_ns;
  return s;
}

}  // namespace

void to_idl(const ToolOutput& out, std::string_view tool_id, std::string_view model_id,
            std::uint64_t compute_ns, palpate_ToolFeedback& feedback) {
  write_feedback(out, tool_id, model_id, compute_ns, feedback);
}

ToolFeedbackSample from_idl(const palpate_ToolFeedback& f, std::int64_t receive_time_ns) {
  return read_feedback(f, receive_time_ns);
}

void to_idl(const ToolOutput& out, const ToolPoseInput& pose, const ToolGeometry& tool,
            std::string_view model_id, std::uint64_t compute_ns, palpate_ToolResponse& response) {
  write_feedback(out, tool.id, model_id, compute_ns, response);
  const LocalContactModel& local = out.local;
  for (int d = 0; d < 3; ++d) {
    response.position[d] = pose.position_m[d];
    response.contact_force[d] = local.force_n[d];
    response.contact_torque[d] = local.torque_nm[d];
  }
  response.orientation[0] = pose.orientation.w();
  response.orientation[1] = pose.orientation.x();
  response.orientation[2] = pose.orientation.y();
  response.orientation[3] = pose.orientation.z();
  response.jaw_angle = pose.jaw_angle_rad;
  // The model answers the pose it was made at; a failed tick's is the last
  // one's, whose pose is not this one: no model then.
  response.model_valid = local.valid && local.position_m == pose.position_m &&
                         local.orientation.coeffs() == pose.orientation.coeffs();
  response.holding = local.holding;
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(response.stiffness) = local.stiffness;
  response.force_limit = tool.force_limit_n;
  response.max_force_rate = tool.max_force_rate_n_per_s;
}

ToolFeedbackSample from_idl(const palpate_ToolResponse& r, std::int64_t receive_time_ns) {
  ToolFeedbackSample s = read_feedback(r, receive_time_ns);
  LocalContactModel& local = s.local;
  local.position_m = Eigen::Vector3d(r.position[0], r.position[1], r.position[2]);
  local.orientation =
      Eigen::Quaterniond(r.orientation[0], r.orientation[1], r.orientation[2], r.orientation[3]);
  local.force_n = Eigen::Vector3d(r.contact_force[0], r.contact_force[1], r.contact_force[2]);
  local.torque_nm = Eigen::Vector3d(r.contact_torque[0], r.contact_torque[1], r.contact_torque[2]);
  local.stiffness = Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(r.stiffness);
  local.holding = r.holding;
  // Only a model of finite numbers with a unit quaternion is one.
  const double norm = local.orientation.norm();
  local.valid = r.model_valid && local.position_m.allFinite() && local.force_n.allFinite() &&
                local.torque_nm.allFinite() && local.stiffness.allFinite() && norm > 0.9 &&
                norm < 1.1;
  if (local.valid) local.orientation.normalize();
  s.jaw_angle_rad = r.jaw_angle;
  s.force_limit_n = r.force_limit;
  s.max_force_rate_n_per_s = r.max_force_rate;
  return s;
}

void to_idl(std::string_view tool_id, std::string_view model_id, std::uint64_t pose_sequence,
            std::span<const RenderedRecord> steps, std::span<palpate_RenderedStep> storage,
            palpate_ToolRendered& out) {
  copy_bounded(out.tool_id, tool_id);
  copy_bounded(out.model_id, model_id);
  out.pose_sequence = pose_sequence;
  const std::size_t n = std::min({steps.size(), storage.size(), std::size_t{32}});
  const std::size_t first = steps.size() - n;  // the newest n
  for (std::size_t i = 0; i < n; ++i) {
    const RenderedRecord& r = steps[first + i];
    palpate_RenderedStep& s = storage[i];
    s.time_ns = r.time_ns;
    s.answer_sequence = r.answer_sequence;
    std::copy_n(r.position_m, 3, s.position);
    std::copy_n(r.force_n, 3, s.force);
    s.damping = r.damping;
  }
  view(out.steps, storage.first(n));
}

std::size_t from_idl(const palpate_ToolRendered& rendered, std::int32_t tool,
                     std::span<RenderedRecord> out) {
  const std::size_t n = std::min<std::size_t>(rendered.steps._length, out.size());
  for (std::size_t i = 0; i < n; ++i) {
    const palpate_RenderedStep& s = rendered.steps._buffer[i];
    RenderedRecord& r = out[i];
    r.tool = tool;
    r.time_ns = s.time_ns;
    r.answer_sequence = s.answer_sequence;
    std::copy_n(s.position, 3, r.position_m);
    std::copy_n(s.force, 3, r.force_n);
    r.damping = s.damping;
  }
  return n;
}

void to_idl(ToolEventKind kind, const ToolOutput& output, std::string_view tool_id,
            std::string_view model_id, std::int64_t daemon_time_ns, palpate_ToolEvent& out) {
  copy_bounded(out.tool_id, tool_id);
  copy_bounded(out.model_id, model_id);
  out.kind = static_cast<palpate_ToolEventKind>(kind);
  out.pose_sequence = output.sequence;
  out.held_vertices = static_cast<std::uint32_t>(output.held);
  out.daemon_time_ns = daemon_time_ns;
}

ToolEventSample from_idl(const palpate_ToolEvent& e, std::int64_t receive_time_ns) {
  ToolEventSample s;
  s.tool_id = bounded(e.tool_id);
  s.model_id = bounded(e.model_id);
  s.kind = static_cast<ToolEventKind>(received(e.kind));
  s.pose_sequence = e.pose_sequence;
  s.held_vertices = e.held_vertices;
  s.daemon_time_ns = e.daemon_time_ns;
  s.receive_time_ns = receive_time_ns;
  return s;
}

void to_idl_end(std::string_view tool_id, std::string_view model_id, std::uint64_t last_sequence,
                palpate_ToolCommand& out) {
  copy_bounded(out.tool_id, tool_id);
  copy_bounded(out.model_id, model_id);
  out.kind = palpate_TOOL_COMMAND_END;
  out.pose_sequence = last_sequence;
}

std::int32_t received_kind(const palpate_ToolCommand& command) { return received(command.kind); }

void to_idl(PoseProblem reason, std::uint64_t pose_sequence, std::string_view message,
            std::string_view tool_id, std::string_view model_id, palpate_ToolNotice& out) {
  copy_bounded(out.tool_id, tool_id);
  copy_bounded(out.model_id, model_id);
  copy_bounded(out.message, message);
  out.kind = palpate_TOOL_NOTICE_POSE_REFUSED;
  out.pose_sequence = pose_sequence;
  out.reason = static_cast<std::int32_t>(reason);
}

ToolNoticeSample from_idl(const palpate_ToolNotice& n, std::int64_t receive_time_ns) {
  ToolNoticeSample s;
  s.tool_id = bounded(n.tool_id);
  s.model_id = bounded(n.model_id);
  // A reason this build does not know reads as kNone; the message still says.
  const bool known =
      n.reason > 0 && n.reason <= static_cast<std::int32_t>(PoseProblem::kUnknownTool);
  s.reason = known ? static_cast<PoseProblem>(n.reason) : PoseProblem::kNone;
  s.pose_sequence = n.pose_sequence;
  s.message = bounded(n.message);
  s.receive_time_ns = receive_time_ns;
  return s;
}

}  // namespace palpate::wire
