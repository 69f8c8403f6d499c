// The wire conversions (wire.hpp) on the C structs of "palpate.h", no DDS
// participant: every from_idl / to_idl pair carries its fields, bounded
// strings are kept, truncated and read as the IDL bounds them, the model's
// description views its arrays, a request loaded into a ConstraintSolver
// gives the solver's (and the dense algebra's) forces and displacements,
// and the request and tool paths allocate nothing.

#include "palpate/transport/wire.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "support/allocation_counter.hpp"
#include "support/box_job.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using wire::bounded;
using wire::copy_bounded;

/// True when every byte of @p text after its terminator is zero.
template <std::size_t N>
bool zero_padded(const char (&text)[N]) {
  const std::size_t n = strnlen(text, N);
  for (std::size_t i = n; i < N; ++i)
    if (text[i] != '\0') return false;
  return true;
}

// ---- bounded strings -------------------------------------------------------------

TEST(Wire, BoundedStringsKeepTruncateAndReadAsTheIdlBoundsThem) {
  char id[64];
  std::memset(id, 'z', sizeof id);
  const std::string longest(63, 'a');  // string<63>: the longest that fits
  copy_bounded(id, longest);
  EXPECT_EQ(id[63], '\0');
  EXPECT_EQ(bounded(id), longest);

  std::string too_long = std::string(63, 'b') + "cdef";
  copy_bounded(id, too_long);
  EXPECT_EQ(id[63], '\0') << "truncated and terminated";
  EXPECT_EQ(bounded(id), std::string(63, 'b'));

  copy_bounded(id, "");
  EXPECT_EQ(id[0], '\0');
  EXPECT_EQ(bounded(id).size(), 0u);

  // Received without a terminator (a foreign writer): read as 64 characters,
  // never past the array.
  struct {
    char text[64];
    char after[8];
  } unterminated;
  std::memset(unterminated.text, 'x', sizeof unterminated.text);
  std::memset(unterminated.after, 'y', sizeof unterminated.after);
  EXPECT_EQ(bounded(unterminated.text), std::string(64, 'x'));

  char with_nul[16] = "abc\0def";
  EXPECT_EQ(bounded(with_nul), "abc");
}

// ---- palpate_model -----------------------------------------------------------------

SurfaceModel hand_made_model() {
  SurfaceModel m;
  m.id = "liver";
  m.material_summary = "organ: E = 85000 Pa, nu = 0.45";
  m.input_hash = "sha256:" + std::string(64, 'd');
  m.G = Eigen::MatrixXd::Identity(6, 6);  // two compliance vertices
  m.surface.compliance_vertex_count = 2;
  m.surface.vertex_ids = {4, 9, 1};
  m.surface.rest_positions_m = {0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09};
  m.surface.triangles = {0, 1, 2, 2, 1, 0};
  return m;
}

TEST(Wire, TheModelDescriptionViewsTheModelsArrays) {
  const SurfaceModel model = hand_made_model();
  const palpate_ModelDescription d = wire::describe(model, 0.03, 50);
  EXPECT_EQ(bounded(d.model_id), "liver");
  EXPECT_EQ(bounded(d.units), "m, N (SI)");
  EXPECT_EQ(bounded(d.material_summary), model.material_summary);
  EXPECT_EQ(bounded(d.input_hash), model.input_hash);
  EXPECT_EQ(d.compliance_vertex_count, 2u);
  // Views, not copies: Cyclone must not free them.
  EXPECT_EQ(d.vertex_ids._buffer, model.surface.vertex_ids.data());
  EXPECT_EQ(d.rest_positions._buffer, model.surface.rest_positions_m.data());
  EXPECT_EQ(d.triangles._buffer, model.surface.triangles.data());
  EXPECT_EQ(d.vertex_ids._length, 3u);
  EXPECT_EQ(d.vertex_ids._maximum, 3u);
  EXPECT_EQ(d.rest_positions._length, 9u);
  EXPECT_EQ(d.triangles._length, 6u);
  EXPECT_FALSE(d.vertex_ids._release);
  EXPECT_FALSE(d.rest_positions._release);
  EXPECT_FALSE(d.triangles._release);

  // And back, as a client gets it: copies of every field.
  const ModelInfo info = wire::from_idl(d);
  EXPECT_EQ(info.model_id, "liver");
  EXPECT_EQ(info.units, "m, N (SI)");
  EXPECT_EQ(info.material_summary, model.material_summary);
  EXPECT_EQ(info.input_hash, model.input_hash);
  EXPECT_EQ(info.surface.compliance_vertex_count, 2);
  EXPECT_EQ(info.surface.vertex_ids, model.surface.vertex_ids);
  EXPECT_EQ(info.surface.rest_positions_m, model.surface.rest_positions_m);
  EXPECT_EQ(info.surface.triangles, model.surface.triangles);
  EXPECT_NE(info.surface.vertex_ids.data(), model.surface.vertex_ids.data());

  // A float32 model counts its compliance vertices from G32; a long id is cut to 63.
  SurfaceModel single = hand_made_model();
  single.G.resize(0, 0);
  single.G32 = Eigen::MatrixXf::Identity(6, 6);
  single.id = std::string(70, 'q');
  const palpate_ModelDescription d32 = wire::describe(single, 0.03, 50);
  EXPECT_EQ(d32.compliance_vertex_count, 2u);
  EXPECT_EQ(bounded(d32.model_id), std::string(63, 'q'));
}

// ---- palpate_request, palpate_reply ----------------------------------------------------

TEST(Wire, ARequestCarriesEveryKindOfConstraint) {
  const std::vector<ConstraintSpec> constraints{
      ConstraintSpec::force(12, {0.1, -0.2, 0.3}),
      ConstraintSpec::displacement(7, {-1e-3, 2e-3, 0}),
      ConstraintSpec::normal_displacement(30, {0, 0.6, 0.8}, -2.5e-3)};
  std::vector<palpate_Constraint> storage;
  palpate_ConstraintRequest request;
  std::memset(&request, 0x5a, sizeof request);  // whatever was there before
  wire::to_idl("simulator-1", "liver", 42, constraints, true, false, storage, request);
  EXPECT_EQ(bounded(request.client_id), "simulator-1");
  EXPECT_EQ(bounded(request.model_id), "liver");
  EXPECT_TRUE(zero_padded(request.client_id)) << "no stale bytes on the wire";
  EXPECT_TRUE(zero_padded(request.model_id));
  EXPECT_EQ(request.request_id, 42u);
  EXPECT_TRUE(request.want_surface);
  EXPECT_FALSE(request.update_state);
  ASSERT_EQ(request.constraints._length, 3u);
  EXPECT_EQ(request.constraints._maximum, 3u);
  EXPECT_EQ(request.constraints._buffer, storage.data());
  EXPECT_FALSE(request.constraints._release);
  for (std::size_t j = 0; j < constraints.size(); ++j) {
    const palpate_Constraint& c = request.constraints._buffer[j];
    EXPECT_EQ(c.vertex, constraints[j].vertex);
    EXPECT_EQ(static_cast<int>(c.kind), static_cast<int>(constraints[j].kind));
    for (int d = 0; d < 3; ++d) {
      EXPECT_EQ(c.value[d], constraints[j].value[static_cast<std::size_t>(d)]);
      EXPECT_EQ(c.normal[d], constraints[j].normal[static_cast<std::size_t>(d)]);
    }
  }
  EXPECT_EQ(request.constraints._buffer[0].kind, palpate_CONSTRAINT_FORCE);
  EXPECT_EQ(request.constraints._buffer[1].kind, palpate_CONSTRAINT_DISPLACEMENT);
  EXPECT_EQ(request.constraints._buffer[2].kind, palpate_CONSTRAINT_NORMAL_DISPLACEMENT);
  EXPECT_EQ(request.constraints._buffer[2].value[0], -2.5e-3);

  // An empty request (the rest state), long ids truncated.
  wire::to_idl(std::string(80, 'c'), "liver", 43, {}, false, true, storage, request);
  EXPECT_EQ(request.constraints._length, 0u);
  EXPECT_EQ(bounded(request.client_id), std::string(63, 'c'));
  EXPECT_TRUE(request.update_state);
}

TEST(Wire, AReplyCarriesItsResultsAndSurface) {
  std::array<palpate_ConstraintResult, 2> results{};
  results[0] = {12, {0.1, 0.2, 0.3}, {1e-3, 2e-3, 3e-3}};
  results[1] = {7, {-0.4, -0.5, -0.6}, {-4e-3, -5e-3, -6e-3}};
  std::vector<double> surface{1e-4, 2e-4, 3e-4, 4e-4, 5e-4, 6e-4};
  palpate_ConstraintReply reply{};
  copy_bounded(reply.client_id, "simulator-1");
  copy_bounded(reply.model_id, "liver");
  copy_bounded(reply.message, "constraint 1: vertex 7 of model 'liver' is fixed (attached)");
  reply.request_id = 99;
  reply.status = palpate_STATUS_VERTEX_FIXED;
  reply.condition_estimate = 12.5;
  reply.total_force[0] = -0.3;
  reply.total_force[1] = -0.3;
  reply.total_force[2] = -0.3;
  reply.solve_ns = 123456;
  wire::view(reply.results, std::span<palpate_ConstraintResult>(results));
  wire::view(reply.surface_displacement, std::span(surface));

  const Reply r = wire::from_idl(reply);
  EXPECT_EQ(r.request_id, 99u);
  EXPECT_EQ(r.model_id, "liver");
  EXPECT_EQ(r.status, RequestStatus::kVertexFixed);
  EXPECT_EQ(r.message, "constraint 1: vertex 7 of model 'liver' is fixed (attached)");
  EXPECT_EQ(r.condition_estimate, 12.5);
  EXPECT_EQ(r.total_force_n, (std::array<double, 3>{-0.3, -0.3, -0.3}));
  EXPECT_EQ(r.solve_ns, 123456u);
  ASSERT_EQ(r.results.size(), 2u);
  EXPECT_EQ(r.results[0].vertex, 12u);
  EXPECT_EQ(r.results[0].force_n, (std::array<double, 3>{0.1, 0.2, 0.3}));
  EXPECT_EQ(r.results[0].displacement_m, (std::array<double, 3>{1e-3, 2e-3, 3e-3}));
  EXPECT_EQ(r.results[1].vertex, 7u);
  EXPECT_EQ(r.results[1].force_n, (std::array<double, 3>{-0.4, -0.5, -0.6}));
  EXPECT_EQ(r.results[1].displacement_m, (std::array<double, 3>{-4e-3, -5e-3, -6e-3}));
  EXPECT_EQ(r.surface_displacement_m, surface);

  // Each status number maps to its RequestStatus.
  for (int s = palpate_STATUS_OK; s <= palpate_STATUS_INTERNAL_ERROR; ++s) {
    reply.status = static_cast<palpate_ReplyStatus>(s);
    EXPECT_EQ(static_cast<int>(wire::from_idl(reply).status), s);
  }
  // A 255-character message is whole; an unterminated one is read to the bound.
  std::memset(reply.message, 'm', sizeof reply.message);
  EXPECT_EQ(wire::from_idl(reply).message, std::string(256, 'm'));
}

// ---- palpate_surface, palpate_status ------------------------------------------------------

TEST(Wire, ASurfaceSampleCarriesItsState) {
  std::vector<double> displacement{1, 2, 3, 4, 5, 6, 7, 8, 9};
  std::vector<std::uint32_t> vertices{5, 11};
  std::vector<double> forces{0.5, 0, -1, 0, 0.25, 0};
  palpate_SurfaceDisplacement s{};
  copy_bounded(s.model_id, "kidney");
  copy_bounded(s.source_client_id, "viewer");
  s.sequence_number = 17;
  s.source_request_id = 4;
  s.total_force[0] = 0.5;
  s.total_force[1] = 0.25;
  s.total_force[2] = -1;
  wire::view(s.displacement, std::span(displacement));
  wire::view(s.constrained_vertices, std::span(vertices));
  wire::view(s.constrained_forces, std::span(forces));
  const SurfaceSample sample = wire::from_idl(s);
  EXPECT_EQ(sample.model_id, "kidney");
  EXPECT_EQ(sample.source_client_id, "viewer");
  EXPECT_EQ(sample.sequence_number, 17u);
  EXPECT_EQ(sample.source_request_id, 4u);
  EXPECT_EQ(sample.total_force_n, (std::array<double, 3>{0.5, 0.25, -1}));
  EXPECT_EQ(sample.displacement_m, displacement);
  EXPECT_EQ(sample.constrained_vertices, vertices);
  EXPECT_EQ(sample.constrained_forces_n, forces);

  // At rest: empty sequences give empty vectors.
  palpate_SurfaceDisplacement rest{};
  const SurfaceSample empty = wire::from_idl(rest);
  EXPECT_TRUE(empty.displacement_m.empty());
  EXPECT_TRUE(empty.constrained_vertices.empty());
}

TEST(Wire, AContactPointCarriesItsToolVerticesWeightsPositionAndForce) {
  // Drawn vertices 0..5 are mesh vertices 100..105.
  const std::vector<std::uint32_t> vertex_ids{100, 101, 102, 103, 104, 105};
  ContactPoint tip;
  tip.tool = 1;
  tip.triangle = 4;
  tip.vertex_count = 2;  // on an edge
  tip.vertices = {5, 2, 0};
  tip.weights = {0.75, 0.25, 0};
  tip.position_m = {0.01, -0.02, 0.03};
  tip.force_n = {0.5, 0, -1.5};
  palpate_SurfaceContact c{};
  wire::to_idl(tip, "right", vertex_ids, c);
  const SurfaceContactSample s = wire::from_idl(c);
  EXPECT_EQ(s.tool_id, "right");
  EXPECT_FALSE(s.held);
  EXPECT_EQ(s.vertices, (std::array<std::uint32_t, 3>{105, 102, SurfaceContactSample::kNoVertex}));
  EXPECT_EQ(s.weights, (std::array<double, 3>{0.75, 0.25, 0}));
  EXPECT_EQ(s.position_m, (std::array<double, 3>{0.01, -0.02, 0.03}));
  EXPECT_EQ(s.force_n, (std::array<double, 3>{0.5, 0, -1.5}));

  // A held vertex: one vertex, weight 1; a vertex the map does not know is
  // left out rather than read past the map.
  ContactPoint held;
  held.held = true;
  held.vertices = {3, 0, 0};
  held.weights = {1, 0, 0};
  wire::to_idl(held, "left", vertex_ids, c);
  EXPECT_TRUE(wire::from_idl(c).held);
  EXPECT_EQ(wire::from_idl(c).vertices,
            (std::array<std::uint32_t, 3>{103, SurfaceContactSample::kNoVertex,
                                          SurfaceContactSample::kNoVertex}));
  held.vertices = {6, 0, 0};
  wire::to_idl(held, "left", vertex_ids, c);
  EXPECT_EQ(wire::from_idl(c).vertices[0], SurfaceContactSample::kNoVertex);
  EXPECT_EQ(wire::from_idl(c).weights[0], 0.0);

  // In a surface sample, in order; none in a sample without them.
  std::vector<palpate_SurfaceContact> contacts(2);
  wire::to_idl(tip, "right", vertex_ids, contacts[0]);
  wire::to_idl(held, "left", vertex_ids, contacts[1]);
  palpate_SurfaceDisplacement sample{};
  wire::view(sample.contact_points, std::span(contacts));
  const SurfaceSample read = wire::from_idl(sample);
  ASSERT_EQ(read.contact_points.size(), 2u);
  EXPECT_EQ(read.contact_points[0].tool_id, "right");
  EXPECT_EQ(read.contact_points[1].tool_id, "left");
  EXPECT_TRUE(wire::from_idl(palpate_SurfaceDisplacement{}).contact_points.empty());
}

TEST(Wire, AStatusCarriesItsCountersAndLatencies) {
  const LatencySummary solve{10.5, 20.25, 30.125, 40.0625};
  const palpate_Latency l = wire::to_idl(solve);
  EXPECT_EQ(l.p50_us, 10.5);
  EXPECT_EQ(l.p99_us, 20.25);
  EXPECT_EQ(l.p999_us, 30.125);
  EXPECT_EQ(l.max_us, 40.0625);
  palpate_DaemonStatus s{};
  copy_bounded(s.daemon_id, "palpated@host");
  s.uptime_ns = 1'000'000'007;
  s.requests_served = 1001;
  s.error_replies = 3;
  s.request_rate_hz = 999.5;
  s.surface_rate_hz = 60.25;
  s.solve = l;
  s.request_to_reply = wire::to_idl(LatencySummary{1, 2, 3, 4});
  s.models = 2;
  s.clients = 5;
  s.tool_poses = 123456789012ULL;
  s.tool_poses_refused = 7;
  s.tool_compute = wire::to_idl(LatencySummary{5, 6, 7, 8});
  const StatusSample st = wire::from_idl(s);
  EXPECT_EQ(st.daemon_id, "palpated@host");
  EXPECT_EQ(st.uptime_ns, 1'000'000'007u);
  EXPECT_EQ(st.requests_served, 1001u);
  EXPECT_EQ(st.error_replies, 3u);
  EXPECT_EQ(st.request_rate_hz, 999.5);
  EXPECT_EQ(st.surface_rate_hz, 60.25);
  auto same = [](const LatencySummary& a, const LatencySummary& b) {
    return a.p50_us == b.p50_us && a.p99_us == b.p99_us && a.p999_us == b.p999_us &&
           a.max_us == b.max_us;
  };
  EXPECT_TRUE(same(st.solve, solve));
  EXPECT_TRUE(same(st.request_to_reply, LatencySummary{1, 2, 3, 4}));
  EXPECT_TRUE(same(st.tool_compute, LatencySummary{5, 6, 7, 8}));
  EXPECT_EQ(st.models, 2u);
  EXPECT_EQ(st.clients, 5u);
  EXPECT_EQ(st.tool_poses, 123456789012ULL);
  EXPECT_EQ(st.tool_poses_refused, 7u);

  // palpated's side: the values back into the heartbeat, field for field;
  // a daemon id longer than string<63> is cut to it.
  palpate_DaemonStatus again{};
  wire::to_idl(st, again);
  EXPECT_EQ(std::memcmp(&again, &s, sizeof s), 0);
  StatusSample long_id = st;
  long_id.daemon_id = std::string(70, 'd');
  wire::to_idl(long_id, again);
  EXPECT_EQ(bounded(again.daemon_id), std::string(63, 'd'));
}

TEST(Wire, ASurfaceSampleIsWrittenFromTheShownStateAndReadBack) {
  // Compliance vertices 0..3 are mesh vertices 40..43; the loads are on 3 and 1.
  const std::vector<std::uint32_t> vertex_ids{40, 41, 42, 43};
  const std::vector<double> displacement{1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  const std::vector<int> indices{3, 1};
  const std::vector<double> forces{0.5, 0, -1, 0, 0.25, 0};
  std::vector<ContactPoint> points(2);
  points[0].tool = 1;
  points[0].vertex_count = 1;
  points[0].vertices = {2, 0, 0};
  points[0].weights = {1, 0, 0};
  points[1].tool = 5;  // no such tool: no id
  const std::vector<std::string> tool_ids{"left", "right"};
  const double total[3] = {0.5, 0.25, -1};
  std::vector<std::uint32_t> vertex_storage(4, 0xdead);
  std::vector<palpate_SurfaceContact> contact_storage(3);

  palpate_SurfaceDisplacement s{};
  wire::to_idl("kidney", 17, "tool:left", 4, total, displacement, s);
  wire::view_loads(indices, forces, vertex_ids, vertex_storage, s);
  wire::view_contacts(points, tool_ids, vertex_ids, contact_storage, s);
  EXPECT_EQ(s.displacement._buffer, displacement.data()) << "a view, not a copy";
  EXPECT_EQ(s.constrained_vertices._buffer, vertex_storage.data());
  EXPECT_EQ(s.constrained_forces._buffer, forces.data());
  EXPECT_EQ(s.contact_points._buffer, contact_storage.data());
  EXPECT_FALSE(s.displacement._release || s.constrained_vertices._release ||
               s.constrained_forces._release || s.contact_points._release);

  const SurfaceSample sample = wire::from_idl(s);
  EXPECT_EQ(sample.model_id, "kidney");
  EXPECT_EQ(sample.sequence_number, 17u);
  EXPECT_EQ(sample.source_client_id, "tool:left");
  EXPECT_EQ(sample.source_request_id, 4u);
  EXPECT_EQ(sample.total_force_n, (std::array<double, 3>{0.5, 0.25, -1}));
  EXPECT_EQ(sample.displacement_m, displacement);
  EXPECT_EQ(sample.constrained_vertices, (std::vector<std::uint32_t>{43, 41}));
  EXPECT_EQ(sample.constrained_forces_n, forces);
  ASSERT_EQ(sample.contact_points.size(), 2u);
  EXPECT_EQ(sample.contact_points[0].tool_id, "right");
  EXPECT_EQ(sample.contact_points[0].vertices[0], 42u);
  EXPECT_EQ(sample.contact_points[1].tool_id, "");
}

// ---- palpate_tool_pose, palpate_tool_feedback, palpate_tool_event -----------------------

TEST(Wire, AToolPoseBecomesTheEnginesInput) {
  palpate_ToolPose pose;
  std::memset(&pose, 0x5a, sizeof pose);
  pose.send_time_ns = 987654321;  // stamped by the caller, left alone
  wire::to_idl("grasper-left", "liver", 31, {0.01, -0.02, 0.03}, {0.5, 0.5, -0.5, 0.5}, 0.25, pose);
  EXPECT_EQ(bounded(pose.tool_id), "grasper-left");
  EXPECT_EQ(bounded(pose.model_id), "liver");
  EXPECT_TRUE(zero_padded(pose.tool_id));
  EXPECT_TRUE(zero_padded(pose.model_id));
  EXPECT_EQ(pose.pose_sequence, 31u);
  EXPECT_EQ(pose.send_time_ns, 987654321);
  EXPECT_EQ(pose.orientation[0], 0.5) << "w first";
  EXPECT_EQ(pose.orientation[3], 0.5);

  const ToolPoseInput input = wire::from_idl(pose);
  EXPECT_EQ(input.sequence, 31u);
  EXPECT_EQ(input.send_time_ns, 987654321);
  EXPECT_EQ(input.position_m, Eigen::Vector3d(0.01, -0.02, 0.03));
  EXPECT_EQ(input.orientation.w(), 0.5);
  EXPECT_EQ(input.orientation.x(), 0.5);
  EXPECT_EQ(input.orientation.y(), -0.5);
  EXPECT_EQ(input.orientation.z(), 0.5);
  EXPECT_EQ(input.jaw_angle_rad, 0.25);
}

ToolOutput an_output() {
  ToolOutput out;
  out.force_n = {0.5, -1.5, 2.25};
  out.torque_nm = {-0.01, 0.02, 0.0};
  out.grip_n = 1.75;
  out.contacts = 6;
  out.held = 4;
  out.state = ToolState::kGrasping;
  out.force_limited = true;
  out.watchdog = false;
  out.sequence = 1234;
  out.send_time_ns = 5'000'000;
  return out;
}

TEST(Wire, ToolOutputBecomesFeedbackAndFeedbackTheClientsSample) {
  const ToolOutput out = an_output();
  palpate_ToolFeedback feedback{};
  wire::to_idl(out, "grasper-left", "liver", 87'000, feedback);
  EXPECT_EQ(bounded(feedback.tool_id), "grasper-left");
  EXPECT_EQ(bounded(feedback.model_id), "liver");
  EXPECT_EQ(feedback.pose_sequence, 1234u);
  EXPECT_EQ(feedback.send_time_ns, 5'000'000);
  EXPECT_EQ(feedback.state, palpate_TOOL_GRASPING);
  EXPECT_EQ(feedback.compute_ns, 87'000u);

  const ToolFeedbackSample s = wire::from_idl(feedback, 5'900'000);
  EXPECT_EQ(s.sequence, 1234u);
  EXPECT_EQ(s.send_time_ns, 5'000'000);
  EXPECT_EQ(s.receive_time_ns, 5'900'000);
  EXPECT_EQ(s.round_trip_ns(), 900'000);
  EXPECT_EQ(s.force_n, (std::array<double, 3>{0.5, -1.5, 2.25}));
  EXPECT_EQ(s.torque_nm, (std::array<double, 3>{-0.01, 0.02, 0.0}));
  EXPECT_EQ(s.grip_n, 1.75);
  EXPECT_EQ(s.contacts, 6u);
  EXPECT_EQ(s.state, ToolState::kGrasping);
  EXPECT_TRUE(s.force_limited);
  EXPECT_FALSE(s.watchdog);
  EXPECT_EQ(s.compute_ns, 87'000u);

  // Every state, and the watchdog flag.
  ToolOutput other = out;
  other.watchdog = true;
  other.force_limited = false;
  for (const ToolState state : {ToolState::kFree, ToolState::kTouching, ToolState::kGrasping}) {
    other.state = state;
    wire::to_idl(other, "t", "m", 0, feedback);
    const ToolFeedbackSample back = wire::from_idl(feedback, 0);
    EXPECT_EQ(back.state, state);
    EXPECT_TRUE(back.watchdog);
    EXPECT_FALSE(back.force_limited);
  }
}

TEST(Wire, AResponseCarriesTheFeedbackThePoseAndTheLocalModel) {
  ToolOutput out = an_output();
  ToolPoseInput pose;
  pose.position_m = Eigen::Vector3d(0.01, -0.02, 0.03);
  pose.orientation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 1, 0).normalized()));
  pose.jaw_angle_rad = 0.2;
  out.local.valid = true;
  out.local.position_m = pose.position_m;
  out.local.orientation = pose.orientation;
  out.local.force_n = Eigen::Vector3d(0.6, -1.7, 2.5);
  out.local.torque_nm = Eigen::Vector3d(0.001, 0.002, 0.003);
  out.local.holding = true;
  for (int i = 0; i < 36; ++i) out.local.stiffness(i / 6, i % 6) = 0.5 * i - 7;  // row-major order
  ToolGeometry tool;
  tool.id = "grasper-left";
  tool.force_limit_n = 6;
  tool.max_force_rate_n_per_s = 400;
  palpate_ToolResponse response{};
  wire::to_idl(out, pose, tool, "liver", 87'000, response);
  EXPECT_EQ(bounded(response.tool_id), "grasper-left");
  EXPECT_EQ(bounded(response.model_id), "liver");
  EXPECT_EQ(response.pose_sequence, 1234u);
  EXPECT_EQ(response.stiffness[7], 0.5 * 7 - 7) << "row 1, column 1";
  EXPECT_EQ(response.stiffness[6], 0.5 * 6 - 7) << "row 1, column 0: row-major";
  EXPECT_TRUE(response.model_valid);
  EXPECT_EQ(response.force_limit, 6);
  EXPECT_EQ(response.max_force_rate, 400);

  const ToolFeedbackSample s = wire::from_idl(response, 5'900'000);
  EXPECT_EQ(s.sequence, 1234u);
  EXPECT_EQ(s.round_trip_ns(), 900'000);
  EXPECT_EQ(s.force_n, (std::array<double, 3>{0.5, -1.5, 2.25})) << "the fed-back force";
  EXPECT_EQ(s.grip_n, 1.75);
  EXPECT_EQ(s.contacts, 6u);
  EXPECT_EQ(s.state, ToolState::kGrasping);
  EXPECT_EQ(s.compute_ns, 87'000u);
  EXPECT_TRUE(s.local.valid);
  EXPECT_TRUE(s.local.holding);
  EXPECT_EQ(s.local.position_m, pose.position_m);
  EXPECT_LE(s.local.orientation.angularDistance(pose.orientation), 1e-15);
  EXPECT_EQ(s.jaw_angle_rad, 0.2);
  EXPECT_EQ(s.local.force_n, out.local.force_n);
  EXPECT_EQ(s.local.torque_nm, out.local.torque_nm);
  EXPECT_EQ(s.local.stiffness, out.local.stiffness);
  EXPECT_EQ(s.force_limit_n, 6);
  EXPECT_EQ(s.max_force_rate_n_per_s, 400);

  // A failed tick keeps the last model, which answers another pose: none
  // is sent then.
  ToolPoseInput moved = pose;
  moved.position_m.x() += 1e-4;
  wire::to_idl(out, moved, tool, "liver", 0, response);
  EXPECT_FALSE(response.model_valid);
  EXPECT_FALSE(wire::from_idl(response, 0).local.valid);
}

TEST(Wire, AResponseWithAbsurdNumbersHasNoModel) {
  ToolOutput out = an_output();
  ToolPoseInput pose;
  out.local.valid = true;
  ToolGeometry tool;
  tool.id = "t";
  palpate_ToolResponse response{};
  wire::to_idl(out, pose, tool, "m", 0, response);
  ASSERT_TRUE(wire::from_idl(response, 0).local.valid);
  palpate_ToolResponse bad = response;
  bad.stiffness[20] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(wire::from_idl(bad, 0).local.valid);
  bad = response;
  bad.contact_force[1] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(wire::from_idl(bad, 0).local.valid);
  bad = response;
  bad.orientation[0] = 3;  // not a unit quaternion
  EXPECT_FALSE(wire::from_idl(bad, 0).local.valid);
}

TEST(Wire, ToolEventsCarryTheirKindAndTheTick) {
  const ToolOutput out = an_output();
  for (int k = 0; k <= static_cast<int>(kLastToolEventKind); ++k) {
    const auto kind = static_cast<ToolEventKind>(k);
    palpate_ToolEvent event{};
    wire::to_idl(kind, out, "grasper-left", "liver", 1'700'000'000'000'000'000LL, event);
    EXPECT_EQ(static_cast<int>(event.kind), k);
    const ToolEventSample s = wire::from_idl(event, 42);
    EXPECT_EQ(s.tool_id, "grasper-left");
    EXPECT_EQ(s.model_id, "liver");
    EXPECT_EQ(s.kind, kind);
    EXPECT_EQ(s.pose_sequence, 1234u);
    EXPECT_EQ(s.held_vertices, 4u);
    EXPECT_EQ(s.daemon_time_ns, 1'700'000'000'000'000'000LL);
    EXPECT_EQ(s.receive_time_ns, 42);
  }
}

TEST(Wire, EndCommandsNameTheToolAndTheLastPose) {
  palpate_ToolCommand command{};
  wire::to_idl_end("right", "liver", 77, command);
  EXPECT_STREQ(command.tool_id, "right");
  EXPECT_STREQ(command.model_id, "liver");
  EXPECT_EQ(command.kind, palpate_TOOL_COMMAND_END);
  EXPECT_EQ(command.pose_sequence, 77u);
  EXPECT_EQ(wire::received_kind(command), palpate_TOOL_COMMAND_END);
  // As a sender may write it: 32 bits that no enumerator of the IDL names.
  const std::int32_t unknown_kind = 12345;
  std::memcpy(&command.kind, &unknown_kind, sizeof unknown_kind);
  EXPECT_EQ(wire::received_kind(command), unknown_kind);
}

TEST(Wire, NoticesCarryTheReasonAndItsMessage) {
  palpate_ToolNotice notice{};
  wire::to_idl(PoseProblem::kBadJawAngle, 12, "jaw angle 90° is over", "right", "liver", notice);
  EXPECT_EQ(notice.reason, 3);  // the number docs/dds.md gives
  const ToolNoticeSample s = wire::from_idl(notice, 5);
  EXPECT_EQ(s.tool_id, "right");
  EXPECT_EQ(s.model_id, "liver");
  EXPECT_EQ(s.reason, PoseProblem::kBadJawAngle);
  EXPECT_EQ(s.pose_sequence, 12u);
  EXPECT_EQ(s.message, "jaw angle 90° is over");
  EXPECT_EQ(s.receive_time_ns, 5);
}

TEST(Wire, ALongNoticeMessageIsCutToItsField) {
  palpate_ToolNotice notice{};
  const std::string long_message(400, 'x');
  wire::to_idl(PoseProblem::kOutOfWorkspace, 1, long_message, "t", "m", notice);
  EXPECT_EQ(wire::from_idl(notice, 0).message, std::string(255, 'x'));
}

TEST(Wire, ANoticeReasonThisBuildDoesNotKnowReadsAsNone) {
  palpate_ToolNotice notice{};
  wire::to_idl(PoseProblem::kStale, 1, "m", "t", "m", notice);
  notice.reason = 99;
  EXPECT_EQ(wire::from_idl(notice, 0).reason, PoseProblem::kNone);
  notice.reason = -1;
  EXPECT_EQ(wire::from_idl(notice, 0).reason, PoseProblem::kNone);
}

// ---- requests through a solver on a real model -------------------------------------------

class WireSolverTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    model_ =
        new SurfaceModel(load_surface_model("box", testing::write_box_compliance(dir_->path())));
  }
  static void TearDownTestSuite() {
    delete model_;
    delete dir_;
  }
  static const SurfaceModel& model() { return *model_; }
  /// Mesh id of compliance vertex i.
  static std::uint32_t vertex(int i) {
    return model_->surface.vertex_ids[static_cast<std::size_t>(i)];
  }
  inline static testing::TempDir* dir_ = nullptr;
  inline static SurfaceModel* model_ = nullptr;
};

// The systems solved are made of a few 3 × 3 blocks of G, condition ≤ 1e4
// on this box (constraint_solver_test): the solver's results meet their
// definitions to ~κ·ε ≈ 1e-12 relative; 1e-9 (as in constraint_solver_test)
// leaves a wide margin and still catches a wrong vertex or component
// (errors of order 1).
constexpr double kRelativeTolerance = 1e-9;

TEST_F(WireSolverTest, ALoadedRequestGivesTheSolversAndTheDenseForces) {
  ASSERT_GT(model().compliance_vertex_count(), 12);
  const std::vector<ConstraintSpec> constraints{
      ConstraintSpec::force(vertex(2), {0.1, -0.2, 0.3}),
      ConstraintSpec::displacement(vertex(5), {0, 0, -1e-3}),
      ConstraintSpec::normal_displacement(vertex(11), {0, 0, 2}, -5e-4)};
  std::vector<palpate_Constraint> storage;
  palpate_ConstraintRequest request{};
  wire::to_idl("c", "box", 1, constraints, false, false, storage, request);

  ConstraintSolver solver(model(), {});
  ASSERT_EQ(wire::load_constraints(request, solver), RequestStatus::kOk);
  ASSERT_EQ(solver.solve(), RequestStatus::kOk) << solver.message();
  std::vector<palpate_ConstraintResult> results(3);
  palpate_ConstraintReply reply{};
  wire::view(reply.results, std::span(results));
  reply.results._length = 0;
  wire::write_results(request, solver, reply);
  ASSERT_EQ(reply.results._length, 3u);

  // The same constraints added by hand to another solver: the same bits.
  ConstraintSolver direct(model(), {});
  ASSERT_EQ(direct.begin(3), RequestStatus::kOk);
  for (const auto& c : constraints)
    ASSERT_EQ(
        direct.add(c.vertex, static_cast<std::int32_t>(c.kind), c.value.data(), c.normal.data()),
        RequestStatus::kOk);
  ASSERT_EQ(direct.solve(), RequestStatus::kOk);
  for (int j = 0; j < 3; ++j) {
    EXPECT_EQ(results[static_cast<std::size_t>(j)].vertex,
              constraints[static_cast<std::size_t>(j)].vertex);
    for (int d = 0; d < 3; ++d) {
      EXPECT_EQ(results[static_cast<std::size_t>(j)].force[d], direct.forces()(3 * j + d));
      EXPECT_EQ(results[static_cast<std::size_t>(j)].displacement[d],
                direct.displacements()(3 * j + d));
    }
  }
  const Eigen::Vector3d total = direct.total_force();
  for (int d = 0; d < 3; ++d) EXPECT_EQ(reply.total_force[d], total[d]);

  // Independently, the definitions: u_C = G_CC f_C; the force is the one
  // given, the displacement the one imposed, and the normal one along the
  // (unit) normal with no tangential force.
  Eigen::VectorXd f(9), u(9);
  for (int j = 0; j < 9; ++j) {
    f[j] = results[static_cast<std::size_t>(j / 3)].force[j % 3];
    u[j] = results[static_cast<std::size_t>(j / 3)].displacement[j % 3];
  }
  const int idx[3] = {2, 5, 11};
  Eigen::MatrixXd G_CC(9, 9);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) G_CC.block<3, 3>(3 * a, 3 * b) = model().G_block(idx[a], idx[b]);
  EXPECT_LT((G_CC * f - u).norm(), kRelativeTolerance * u.norm());
  EXPECT_EQ(f.segment<3>(0), Eigen::Vector3d(0.1, -0.2, 0.3));  // a given force is copied: exact
  EXPECT_LT((u.segment<3>(3) - Eigen::Vector3d(0, 0, -1e-3)).norm(), kRelativeTolerance * 1e-3);
  EXPECT_NEAR(u[8], -5e-4, kRelativeTolerance * 5e-4);
  EXPECT_LT(f.segment<2>(6).norm(), kRelativeTolerance * std::abs(f[8]));

  // Forces only: the displacements are G_CC f, the forces those given.
  const std::vector<ConstraintSpec> pushes{ConstraintSpec::force(vertex(0), {0, 0, -1}),
                                           ConstraintSpec::force(vertex(7), {0.5, 0, 0})};
  wire::to_idl("c", "box", 2, pushes, false, false, storage, request);
  ASSERT_EQ(wire::load_constraints(request, solver), RequestStatus::kOk);
  ASSERT_EQ(solver.solve(), RequestStatus::kOk);
  wire::write_results(request, solver, reply);
  ASSERT_EQ(reply.results._length, 2u);
  const Eigen::Vector3d f0(0, 0, -1), f7(0.5, 0, 0);
  const Eigen::Vector3d u0 = model().G_block(0, 0) * f0 + model().G_block(0, 7) * f7;
  const Eigen::Vector3d u7 = model().G_block(7, 0) * f0 + model().G_block(7, 7) * f7;
  EXPECT_EQ(Eigen::Vector3d(results[0].force[0], results[0].force[1], results[0].force[2]), f0);
  EXPECT_LT((Eigen::Vector3d(results[0].displacement[0], results[0].displacement[1],
                             results[0].displacement[2]) -
             u0)
                .norm(),
            kRelativeTolerance * u0.norm());
  EXPECT_LT((Eigen::Vector3d(results[1].displacement[0], results[1].displacement[1],
                             results[1].displacement[2]) -
             u7)
                .norm(),
            kRelativeTolerance * u7.norm());
  // Sums of one non-zero term per axis: exact.
  EXPECT_EQ(reply.total_force[0], 0.5);
  EXPECT_EQ(reply.total_force[2], -1.0);
}

TEST_F(WireSolverTest, AReplyIsStartedAnsweredAndEndedAsPalpatedWritesIt) {
  std::vector<palpate_ConstraintResult> results(4);
  std::vector<double> surface(static_cast<std::size_t>(model().compliance_rows()) + 6, -1.0);
  palpate_ConstraintReply reply{};
  wire::use_buffers(results, surface, reply);
  EXPECT_EQ(reply.results._buffer, results.data());
  EXPECT_EQ(reply.results._maximum, 4u);
  EXPECT_EQ(reply.surface_displacement._buffer, surface.data());
  EXPECT_EQ(reply.surface_displacement._maximum, surface.size());
  EXPECT_EQ(reply.results._length + reply.surface_displacement._length, 0u);
  EXPECT_FALSE(reply.results._release || reply.surface_displacement._release);

  // What an earlier reply left is reset; the ids come from the request.
  copy_bounded(reply.message, "an earlier failure");
  reply.condition_estimate = 7;
  reply.total_force[1] = 3;
  reply.results._length = 2;
  reply.surface_displacement._length = 5;
  const std::vector<ConstraintSpec> constraints{
      ConstraintSpec::force(vertex(2), {0.1, -0.2, 0.3}),
      ConstraintSpec::displacement(vertex(5), {0, 0, -1e-3})};
  std::vector<palpate_Constraint> storage;
  palpate_ConstraintRequest request{};
  wire::to_idl("sim", "box", 31, constraints, true, false, storage, request);
  wire::start_reply(request, reply);
  EXPECT_STREQ(reply.client_id, "sim");
  EXPECT_STREQ(reply.model_id, "box");
  EXPECT_EQ(reply.request_id, 31u);
  EXPECT_EQ(reply.message[0], '\0');
  EXPECT_EQ(reply.condition_estimate, 1.0);
  EXPECT_EQ(reply.total_force[1], 0.0);
  EXPECT_EQ(reply.results._length + reply.surface_displacement._length, 0u);

  // Solved, the surface wanted: the results, the condition and u_S.
  ConstraintSolver solver(model(), {});
  const auto rows = static_cast<std::size_t>(model().compliance_rows());
  RequestStatus status = wire::load_constraints(request, solver);
  if (status == RequestStatus::kOk) status = solver.solve();
  ASSERT_EQ(status, RequestStatus::kOk) << solver.message();
  wire::write_answer(request, status, solver, rows, reply);
  wire::write_status(status, reply);
  EXPECT_EQ(reply.status, palpate_STATUS_OK);
  EXPECT_EQ(reply.message[0], '\0');
  EXPECT_EQ(reply.condition_estimate, solver.condition_estimate());
  ASSERT_EQ(reply.results._length, 2u);
  EXPECT_EQ(results[1].vertex, vertex(5));
  ASSERT_EQ(reply.surface_displacement._length, rows);
  Eigen::VectorXd u(model().compliance_rows());
  solver.surface_displacement(u);
  for (std::size_t i = 0; i < rows; ++i) EXPECT_EQ(surface[i], u[static_cast<Eigen::Index>(i)]);
  EXPECT_EQ(surface[rows], -1.0) << "nothing beyond the model's rows";

  // Refused: the solver's message, condition 1, no results, no surface.
  const std::vector<ConstraintSpec> refused{ConstraintSpec::force(vertex(6), {0, 0, std::nan("")})};
  wire::to_idl("sim", "box", 32, refused, true, false, storage, request);
  wire::start_reply(request, reply);
  status = wire::load_constraints(request, solver);
  if (status == RequestStatus::kOk) status = solver.solve();
  ASSERT_NE(status, RequestStatus::kOk);
  ASSERT_NE(status, RequestStatus::kIllConditioned);
  wire::write_answer(request, status, solver, rows, reply);
  wire::write_status(status, reply);
  EXPECT_EQ(static_cast<int>(reply.status), static_cast<int>(status));
  EXPECT_STREQ(reply.message, solver.message());
  EXPECT_EQ(reply.condition_estimate, 1.0);
  EXPECT_EQ(reply.results._length + reply.surface_displacement._length, 0u);

  // An error after the results were written (palpated's exceptions): they go.
  reply.results._length = 2;
  reply.surface_displacement._length = 3;
  wire::write_message(std::string(300, 'e'), reply);
  wire::write_status(RequestStatus::kInternalError, reply);
  EXPECT_EQ(reply.status, palpate_STATUS_INTERNAL_ERROR);
  EXPECT_EQ(bounded(reply.message), std::string(255, 'e')) << "cut to string<255>";
  EXPECT_EQ(reply.results._length + reply.surface_displacement._length, 0u);
}

TEST_F(WireSolverTest, LoadingStopsAtTheFirstBadConstraint) {
  const std::vector<ConstraintSpec> constraints{
      ConstraintSpec::force(vertex(1), {0, 0, 1}),
      ConstraintSpec::force(model().mesh_vertex_count() + 5, {0, 0, 1}),  // no such vertex
      ConstraintSpec::force(vertex(1), {0, 0, 1})};  // a duplicate, not reached
  std::vector<palpate_Constraint> storage;
  palpate_ConstraintRequest request{};
  wire::to_idl("c", "box", 1, constraints, false, false, storage, request);
  ConstraintSolver solver(model(), {});
  EXPECT_EQ(wire::load_constraints(request, solver), RequestStatus::kVertexOutOfRange);
  EXPECT_NE(std::string(solver.message()).find("constraint 1"), std::string::npos)
      << solver.message();
  // An unknown kind number from the wire is refused, not cast blindly.
  storage[1] = storage[0];
  storage[1].vertex = vertex(4);
  // As a sender writes it: 32 bits that no enumerator of the IDL names.
  const std::int32_t unknown_kind = 7;
  std::memcpy(&storage[1].kind, &unknown_kind, sizeof unknown_kind);
  EXPECT_EQ(wire::load_constraints(request, solver), RequestStatus::kBadConstraint);
  // Too many for the limits.
  ConstraintSolver small(model(), {.max_constraints = 2});
  EXPECT_EQ(wire::load_constraints(request, small), RequestStatus::kTooManyConstraints);
}

TEST_F(WireSolverTest, TheRequestAndToolPathsAllocateNothing) {
  ConstraintSolver solver(model(), {});
  const std::vector<std::vector<ConstraintSpec>> requests{
      {ConstraintSpec::displacement(vertex(3), {0, 0, -1e-3}),
       ConstraintSpec::force(vertex(9), {0.1, 0, 0})},
      {ConstraintSpec::normal_displacement(vertex(4), {0, 0, 1}, -1e-3)},
      {ConstraintSpec::force(vertex(6), {0, 0, std::nan("")})}};  // refused
  std::vector<palpate_ConstraintRequest> wire_requests(requests.size());
  std::vector<std::vector<palpate_Constraint>> storages(requests.size());
  for (std::size_t i = 0; i < requests.size(); ++i)
    wire::to_idl("c", "box", i, requests[i], false, false, storages[i], wire_requests[i]);
  std::vector<palpate_ConstraintResult> results(8);
  palpate_ConstraintReply reply{};
  wire::view(reply.results, std::span(results));
  std::vector<palpate_ConstraintResult> served_results(8);
  std::vector<double> served_surface(static_cast<std::size_t>(model().compliance_rows()));
  palpate_ConstraintReply served_reply{};
  wire::use_buffers(served_results, served_surface, served_reply);
  const ToolOutput out = an_output();
  palpate_ToolFeedback feedback{};
  palpate_ToolEvent event{};
  ContactPoint point;
  point.vertex_count = 3;
  point.vertices = {0, 1, 2};
  point.weights = {0.5, 0.25, 0.25};
  const std::vector<std::uint32_t> vertex_ids{7, 8, 9};
  palpate_SurfaceContact contact{};
  // The stream's sample (not a real-time path, allocation-free all the same).
  const std::vector<double> displacement(12, 1e-3);
  const std::vector<int> indices{2, 0};
  const std::vector<double> forces(6, 0.5);
  const std::vector<ContactPoint> points(2, point);
  const std::vector<std::string> tool_ids{"grasper-left"};
  const double total[3] = {1, 0, 1};
  std::vector<std::uint32_t> vertex_storage(2);
  std::vector<palpate_SurfaceContact> contact_storage(2);
  palpate_SurfaceDisplacement sample{};
  const StatusSample status = [] {
    StatusSample s;
    s.daemon_id = std::string(60, 'p');  // beyond the small-string buffer
    return s;
  }();
  palpate_DaemonStatus status_sample{};
  auto tick = [&](std::size_t i) {
    wire::to_idl(point, "grasper-left", vertex_ids, contact);
    int ok = 0;
    if (wire::load_constraints(wire_requests[i], solver) == RequestStatus::kOk &&
        solver.solve() == RequestStatus::kOk) {
      wire::write_results(wire_requests[i], solver, reply);
      ++ok;
    }
    // The request server's reply: started, answered (the surface wanted), ended.
    wire_requests[i].want_surface = true;
    wire::start_reply(wire_requests[i], served_reply);
    RequestStatus served = wire::load_constraints(wire_requests[i], solver);
    if (served == RequestStatus::kOk) served = solver.solve();
    wire::write_answer(wire_requests[i], served, solver, served_surface.size(), served_reply);
    wire::write_status(served, served_reply);
    wire::to_idl("box", i, "tool:grasper-left", i, total, displacement, sample);
    wire::view_loads(indices, forces, vertex_ids, vertex_storage, sample);
    wire::view_contacts(points, tool_ids, vertex_ids, contact_storage, sample);
    wire::to_idl(status, status_sample);
    wire::to_idl(out, "grasper-left", "liver", i, feedback);
    wire::to_idl(ToolEventKind::kTouch, out, "grasper-left", "liver", 1, event);
    return ok;
  };
  for (std::size_t i = 0; i < requests.size(); ++i) tick(i);  // warm-up
  const std::uint64_t before = testing::allocations_here();
  int ok = 0;
  for (int i = 0; i < 300; ++i) ok += tick(static_cast<std::size_t>(i) % requests.size());
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  EXPECT_EQ(ok, 200);
  // The counter does count.
  std::string counted(100, 'x');
  EXPECT_EQ(testing::allocations_here() - before, 1u);
  EXPECT_EQ(counted.size(), 100u);
}

}  // namespace
}  // namespace palpate
