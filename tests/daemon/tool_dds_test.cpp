// Haptic tools end to end: the real palpated, real Cyclone DDS on loopback
// (CTest runs this binary in a private network namespace), poses sent by a
// ToolClient at the haptic rate, feedback checked against the direct solves
// of docs/model/requests.md on G read from the compliance file. The fixture:
// tools_over_dds.hpp.

#include "tools_over_dds.hpp"

namespace palpate {
namespace {

using namespace std::chrono_literals;
using Eigen::Vector3d;
using testing::kPointingDown;
using testing::kRelativeTolerance;
using testing::kTimeout;
using testing::ToolsOverDdsTest;

TEST_F(ToolsOverDdsTest, PressingGivesTheDirectSolveAndWithdrawingGivesNothing) {
  const int v = top_vertex(75, 25);
  const double r = 0.002;
  Hand probe("probe", rest(v) + Vector3d(0, 0, r + 0.002));
  client_->take_events();
  double previous = 0;
  for (const double d : {0.001, 0.002, 0.003}) {
    probe.move(rest(v) + Vector3d(0, 0, r - d), 0);
    probe.hold(5);
    ASSERT_TRUE(probe.last) << daemon_->log();
    EXPECT_GT(probe.force().norm(), previous * 1.2) << "depth " << d;
    previous = probe.force().norm();
    // docs/model/requests.md: at the vertex alone, G_vv f = u_v with u_v = −d e_z and
    // the probe feels −f. The tip also meets the triangles that the dip
    // around v tilts towards it (docs/tools.md, "Tip contacts"): a few
    // per cent more, never less (the exact joint solve is checked in
    // process, tests/runtime/contact/tool_contact_test.cpp).
    const Vector3d f = G_->block<3, 3>(3 * v, 3 * v).ldlt().solve(Vector3d(0, 0, -d));
    EXPECT_LT((probe.force() + f).norm(), 0.1 * f.norm()) << "depth " << d;
    EXPECT_GE(probe.force().z(), -f.z() * (1 - 1e-9)) << "depth " << d;
    EXPECT_EQ(probe.last->state, ToolState::kTouching);
    EXPECT_GE(probe.last->contacts, 1u);
    EXPECT_EQ(probe.last->sequence, probe.sequence) << "echoed";
    EXPECT_GT(probe.last->compute_ns, 0u);
  }
  probe.move(rest(v) + Vector3d(0, 0, r + 0.002), 0);
  probe.hold(5);
  EXPECT_EQ(probe.force().norm(), 0.0);
  EXPECT_EQ(probe.last->state, ToolState::kFree);
  std::this_thread::sleep_for(100ms);
  const auto events = client_->take_events();
  EXPECT_TRUE(saw_event(events, "probe", ToolEventKind::kTouch));
  EXPECT_TRUE(saw_event(events, "probe", ToolEventKind::kLeave));
  EXPECT_GT(probe.answered, 100);
}

TEST_F(ToolsOverDdsTest, TheSurfaceStreamCarriesTheContactPointsOnTheDeformedTriangles) {
  // A top triangle of free vertices: the probe presses its centroid, a
  // point between vertices.
  const DrawnSurface& surface = info_->surface;
  Vector3d centroid = Vector3d::Zero();
  for (int t = 0; t < surface.triangle_count() && centroid.isZero(); ++t) {
    Vector3d sum = Vector3d::Zero();
    bool top = true;
    for (int i = 0; i < 3; ++i) {
      const auto v = static_cast<int>(surface.triangles[3 * static_cast<std::size_t>(t) + i]);
      top &= v < surface.compliance_vertex_count && std::abs(rest(v).z() - 0.040) < 1e-9;
      sum += rest(v);
    }
    if (top && std::abs(sum.x() / 3 - 0.060) < 0.008 && std::abs(sum.y() / 3 - 0.025) < 0.008)
      centroid = sum / 3;
  }
  ASSERT_FALSE(centroid.isZero());
  const double r = 0.002;
  Hand probe("probe", centroid + Vector3d(0, 0, r + 0.002));
  probe.move(centroid + Vector3d(0, 0, r - 0.002), 0);
  probe.hold(5);
  const auto [sample, feedback] = shown_tick(probe);
  ASSERT_FALSE(sample.contact_points.empty()) << daemon_->log();
  EXPECT_EQ(sample.source_client_id, "tool:probe");
  EXPECT_EQ(sample.contact_points.size(), feedback.contacts) << "the tool's points, all of them";
  const auto tools = check_contact_points(sample);
  EXPECT_EQ(tools.size(), 1u) << "the probe's points only";
  const Vector3d total = tools.count("probe") ? tools.at("probe").force : Vector3d::Zero();
  bool inside_a_triangle = false;
  for (const auto& c : sample.contact_points) {
    EXPECT_FALSE(c.held);
    inside_a_triangle |= c.vertices[2] != SurfaceContactSample::kNoVertex;
    // Friction holds every point (friction = 1e9): each is put back onto
    // the sphere exactly, to the solve's rounding (1e-9 of r).
    const double from_centre = (Vector3d(c.position_m.data()) - probe.at).norm();
    EXPECT_NEAR(from_centre, r, 1e-9 * r) << "a point of the tip's surface";
  }
  EXPECT_TRUE(inside_a_triangle) << "the centroid is pressed between vertices";
  // The feedback is minus the points' sum (under the 100 N limit, the slew
  // limit 1e6 N/s caught up), and the vertex loads f_S = Hᵀ f_C the same sum
  // (no point touches a fixed vertex): both to rounding, 1e-9 relative.
  EXPECT_FALSE(feedback.force_limited);
  EXPECT_LT((total + Vector3d(feedback.force_n.data())).norm(), 1e-9 * total.norm());
  Vector3d loads = Vector3d::Zero();
  for (std::size_t i = 0; i < sample.constrained_forces_n.size(); ++i)
    loads[static_cast<Eigen::Index>(i % 3)] += sample.constrained_forces_n[i];
  EXPECT_LT((loads - total).norm(), 1e-9 * total.norm());
  EXPECT_LT((Vector3d(sample.total_force_n.data()) - total).norm(), 1e-9 * total.norm());

  // Withdrawn: the tool's state shows no contact point.
  probe.move(centroid + Vector3d(0, 0, r + 0.002), 0);
  const auto [after, withdrawn] = shown_tick(probe);
  EXPECT_EQ(withdrawn.state, ToolState::kFree);
  EXPECT_TRUE(after.contact_points.empty());
  EXPECT_TRUE(after.constrained_vertices.empty());
}

TEST_F(ToolsOverDdsTest, GraspPullAndReleaseArriveInOrderAndReleaseRestoresTheOrgan) {
  const int v = top_vertex(75, 25);
  const double reach = 0.015 + 0.004;  // default capsule: 15 mm long, radius 4 mm
  const Vector3d above = rest(v) + Vector3d(0, 0, reach + 0.002);
  const Vector3d in = rest(v) + Vector3d(0, 0, reach - 0.003);
  Hand left("left", above, degrees(40));
  client_->take_events();
  left.move(in, degrees(40));
  left.move(in, 0);
  ASSERT_TRUE(left.last);
  EXPECT_EQ(left.last->state, ToolState::kGrasping) << daemon_->log();
  left.move(in + Vector3d(0, 0, 0.008), 0);  // pull up
  left.hold(10);
  EXPECT_LT(left.force().z(), -0.05) << "the organ holds the pliers back";
  {
    // The held points reach the surface stream as held contact points,
    // each on its deformed triangle, their forces what the jaws feel. The
    // slew limit (500 N/s) has caught up after the hold: the feedback is
    // minus their sum, to rounding (1e-12 N on ~0.1 N).
    const auto [sample, feedback] = shown_tick(left);
    EXPECT_EQ(sample.source_client_id, "tool:left");
    int held = 0;
    for (const auto& c : sample.contact_points) held += c.held;
    EXPECT_GT(held, 0);
    EXPECT_EQ(sample.contact_points.size(), feedback.contacts);
    const auto tools = check_contact_points(sample);
    EXPECT_EQ(tools.size(), 1u) << "the left tool's points only";
    const Vector3d total = tools.count("left") ? tools.at("left").force : Vector3d::Zero();
    EXPECT_FALSE(feedback.force_limited);
    EXPECT_LT((total + Vector3d(feedback.force_n.data())).norm(), 1e-12 + 1e-9 * total.norm());
  }
  left.move(in + Vector3d(0, 0, 0.008), degrees(40));  // open
  left.move(above, degrees(40));
  left.hold(10);
  EXPECT_EQ(left.force().norm(), 0.0);
  EXPECT_EQ(left.last->state, ToolState::kFree);
  EXPECT_EQ(left.last->contacts, 0u);

  // Grasp and release come reliably, in this order.
  std::this_thread::sleep_for(100ms);
  const auto events = client_->take_events();
  int grasp = -1, release = -1;
  for (int i = 0; i < static_cast<int>(events.size()); ++i) {
    if (events[static_cast<std::size_t>(i)].tool_id != "left") continue;
    if (events[static_cast<std::size_t>(i)].kind == ToolEventKind::kGrasp && grasp < 0) grasp = i;
    if (events[static_cast<std::size_t>(i)].kind == ToolEventKind::kRelease) release = i;
  }
  ASSERT_GE(grasp, 0);
  ASSERT_GT(release, grasp);
  EXPECT_GT(events[static_cast<std::size_t>(grasp)].held_vertices, 0u);
}

TEST_F(ToolsOverDdsTest, TwoToolsPressingTogetherFeelEachOther) {
  const int a = top_vertex(75, 12.5), b = top_vertex(75, 37.5);
  const double reach = 0.015 + 0.004;
  Hand left("left", rest(a) + Vector3d(0, 0, reach + 0.001));
  Hand right("right", rest(b) + Vector3d(0, 0, reach + 0.001));
  left.move(rest(a) + Vector3d(0, 0, reach - 0.003), 0, &right);  // left alone
  left.hold(10);
  const Vector3d alone = left.force();
  ASSERT_GT(alone.z(), 0.05);
  for (int i = 0; i < 120; ++i) {  // right presses too (b has dipped under the left press)
    right.at.z() -= 5e-5;
    left.send();
    right.send();
    left.receive();
    right.receive();
  }
  left.hold(10, &right);
  ASSERT_TRUE(right.last);
  EXPECT_GT(right.last->contacts, 0u);
  EXPECT_GT(right.force().z(), 0.05);
  EXPECT_GT((left.force() - alone).norm(), 0.005 * alone.norm())
      << "coupled through G: the right tool changes what the left one feels";
  // Withdraw both.
  for (int i = 0; i < 200; ++i) {
    left.at.z() += 5e-5;
    right.at.z() += 5e-5;
    left.send();
    right.send();
    left.receive();
    right.receive();
  }
  EXPECT_EQ(left.force().norm() + right.force().norm(), 0.0);
}

TEST_F(ToolsOverDdsTest, BothToolsContactPointsReachTheStreamEachNamedByItsTool) {
  const int a = top_vertex(25, 12.5), b = top_vertex(25, 37.5);
  const double reach = 0.015 + 0.004;
  Hand left("left", rest(a) + Vector3d(0, 0, reach + 0.001));
  Hand right("right", rest(b) + Vector3d(0, 0, reach + 0.001));
  for (int i = 0; i < 80; ++i) {  // both down 4 mm, 3 mm into the organ
    left.at.z() -= 5e-5;
    right.at.z() -= 5e-5;
    left.send();
    right.send();
    left.receive();
    right.receive();
  }
  left.hold(20, &right);
  ASSERT_TRUE(left.last && right.last);
  ASSERT_GT(left.last->contacts, 0u);
  ASSERT_GT(right.last->contacts, 0u);
  // The shown state of one of the right tool's ticks: every tool's points,
  // each named by its tool, as many as each tool's feedback counts. Per
  // tool, their forces are minus its feedback; the left's feedback is of
  // the tick before (the same still poses, solved again): 1e-6 relative
  // bounds the difference.
  std::optional<SurfaceSample> sample;
  for (int attempt = 0; attempt < 200 && !sample; ++attempt) {
    left.send();
    right.send();
    left.receive();
    right.receive();
    sample = viewer_->wait_surface("box", 0, right.sequence, 20ms);
  }
  ASSERT_TRUE(sample) << daemon_->log();
  const auto tools = check_contact_points(*sample);
  ASSERT_EQ(tools.size(), 2u);
  for (const Hand* hand : {&left, &right}) {
    const ToolPoints& points = tools.at(hand->tool);
    EXPECT_EQ(points.count, hand->last->contacts) << hand->tool;
    EXPECT_FALSE(hand->last->force_limited) << hand->tool;
    EXPECT_LT((points.force + hand->force()).norm(), 1e-6 * points.force.norm()) << hand->tool;
  }
  for (int i = 0; i < 100; ++i) {  // withdraw both
    left.at.z() += 5e-5;
    right.at.z() += 5e-5;
    left.send();
    right.send();
    left.receive();
    right.receive();
  }
  EXPECT_EQ(left.force().norm() + right.force().norm(), 0.0);
}

TEST_F(ToolsOverDdsTest, BadPosesAreIgnoredWithAWarningAndServingGoesOn) {
  const Vector3d above = rest(top_vertex(50, 25)) + Vector3d(0, 0, 0.05);
  auto no_feedback = [&](const std::string& tool, std::uint64_t sequence) {
    return !client_->wait_feedback(tool, sequence, std::chrono::steady_clock::now() + 300ms);
  };
  const std::uint64_t s = next_sequence_ += 100000;
  client_->send_pose("probe", "box", s + 1, {std::nan(""), above.y(), above.z()}, kPointingDown, 0);
  EXPECT_TRUE(no_feedback("probe", s + 1));
  client_->send_pose("probe", "box", s + 2, {above.x(), above.y(), above.z()}, {2, 0, 0, 0}, 0);
  EXPECT_TRUE(no_feedback("probe", s + 2));
  client_->send_pose("probe", "box", s + 3, {above.x(), above.y(), 1e6}, kPointingDown, 0);
  EXPECT_TRUE(no_feedback("probe", s + 3));
  client_->send_pose("left", "box", s + 4, {above.x(), above.y(), above.z()}, kPointingDown, 7.0);
  EXPECT_TRUE(no_feedback("left", s + 4));
  client_->send_pose("nobody", "box", s + 5, {above.x(), above.y(), above.z()}, kPointingDown, 0);
  EXPECT_TRUE(no_feedback("nobody", s + 5));
  client_->send_pose("probe", "liver", s + 6, {above.x(), above.y(), above.z()}, kPointingDown, 0);
  EXPECT_TRUE(no_feedback("probe", s + 6));

  client_->send_pose("probe", "box", s + 7, {above.x(), above.y(), above.z()}, kPointingDown, 0);
  const auto good =
      client_->wait_feedback("probe", s + 7, std::chrono::steady_clock::now() + kTimeout);
  ASSERT_TRUE(good) << daemon_->log();
  EXPECT_EQ(good->sequence, s + 7);
  const std::string log = daemon_->log();
  for (const char* reason :
       {"reason=non_finite", "reason=bad_quaternion", "reason=out_of_workspace",
        "reason=bad_jaw_angle", "reason=unknown_tool", "reason=unknown_model"})
    EXPECT_NE(log.find(reason), std::string::npos) << reason << "\n" << log;

  // Each refusal reached the client too, with its reason in one line.
  std::vector<ToolNoticeSample> notices;
  const auto until = std::chrono::steady_clock::now() + kTimeout;
  while (notices.size() < 6 && std::chrono::steady_clock::now() < until) {
    for (auto& n : client_->take_notices()) notices.push_back(std::move(n));
    std::this_thread::sleep_for(5ms);
  }
  auto notice_of = [&](std::uint64_t sequence) -> const ToolNoticeSample* {
    for (const auto& n : notices)
      if (n.pose_sequence == sequence) return &n;
    return nullptr;
  };
  const struct {
    std::uint64_t sequence;
    PoseProblem reason;
    const char* says;
  } expected[] = {
      {s + 1, PoseProblem::kNonFinite, "non-finite"},
      {s + 2, PoseProblem::kBadQuaternion, "quaternion of norm 2"},
      {s + 3, PoseProblem::kOutOfWorkspace, "outside the organ's box"},
      {s + 4, PoseProblem::kBadJawAngle,
       "jaw angle 401.1° of tool 'left' is over its limit; "
       "accepted: 0° to 75°"},
      {s + 5, PoseProblem::kUnknownTool,
       "tool 'nobody' is not one of palpated's tools on model "
       "'box': probe, left, right"},
      {s + 6, PoseProblem::kUnknownModel, "model 'liver' is not served by palpated; served: box"},
  };
  for (const auto& e : expected) {
    const ToolNoticeSample* n = notice_of(e.sequence);
    ASSERT_NE(n, nullptr) << pose_problem_name(e.reason);
    EXPECT_EQ(n->reason, e.reason);
    EXPECT_NE(n->message.find(e.says), std::string::npos) << n->message;
  }
}

TEST_F(ToolsOverDdsTest, AClientThatEndsItsSessionIsLetGoAtOnceWithoutTheWatchdog) {
  const int v = top_vertex(25, 25);
  const double r = 0.002;
  Hand probe("probe", rest(v) + Vector3d(0, 0, r + 0.002));
  probe.move(rest(v) + Vector3d(0, 0, r - 0.002), 0);
  probe.hold(5);
  ASSERT_GT(probe.force().norm(), 0.05);
  client_->take_events();

  ASSERT_TRUE(client_->end_session("probe", "box", kTimeout));
  std::vector<ToolEventSample> events;
  const auto until = std::chrono::steady_clock::now() + 300ms;  // past the 50 ms watchdog
  while (std::chrono::steady_clock::now() < until) {
    for (auto& e : client_->take_events()) events.push_back(std::move(e));
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_TRUE(saw_event(events, "probe", ToolEventKind::kEnded));
  EXPECT_FALSE(saw_event(events, "probe", ToolEventKind::kWatchdog));
  // Its last feedback: nothing to feel, no contact, not a watchdog ramp.
  const auto last =
      client_->wait_feedback("probe", probe.sequence, std::chrono::steady_clock::now() + 100ms);
  ASSERT_TRUE(last);
  EXPECT_EQ(Vector3d(last->force_n.data()).norm(), 0.0);
  EXPECT_EQ(last->contacts, 0u);
  EXPECT_FALSE(last->watchdog);

  // A new session counts from 1 again: served, and not "resumed".
  Hand again("probe", rest(v) + Vector3d(0, 0, r + 0.002));
  again.sequence = 0;
  again.hold(5);
  EXPECT_EQ(again.answered, 5);
  std::this_thread::sleep_for(50ms);
  EXPECT_FALSE(saw_event(client_->take_events(), "probe", ToolEventKind::kResumed));
}

TEST_F(ToolsOverDdsTest, WhenPosesStopTheWatchdogRampsTheForceToZero) {
  // A plain reader of the feedback topic sees the watchdog's samples, which
  // come on their own. Made first: waiting for its discovery after the
  // press would be a silence the watchdog acts on (50 ms).
  const auto domain = dds::acquire_domain(0, dds::resolve_domain_config(""));
  dds::Entity participant(dds::check(dds_create_participant(0, nullptr, nullptr), "participant"));
  const dds_entity_t topic =
      dds::check(dds_create_topic(participant.get(), &palpate_ToolFeedback_desc,
                                  dds::kToolFeedbackTopic, nullptr, nullptr),
                 "topic");
  const dds_entity_t reader = dds::check(
      dds_create_reader(participant.get(), topic, dds::tool_stream_qos().get(), nullptr), "reader");
  std::this_thread::sleep_for(200ms);  // discovery

  const int v = top_vertex(50, 25);
  const double reach = 0.015 + 0.004;
  Hand right("right", rest(v) + Vector3d(0, 0, reach + 0.001));
  right.move(rest(v) + Vector3d(0, 0, reach - 0.004), 0);
  right.hold(10);  // the last poses: from here, silence
  const double pressed = right.force().norm();
  ASSERT_GT(pressed, 0.05);
  client_->take_events();
  // Samples taken so far are the feedback of the poses, not the watchdog's.
  {
    palpate_ToolFeedback sample{};
    void* pointer = &sample;
    dds_sample_info_t info;
    while (dds_take(reader, &pointer, &info, 1, 1) == 1) {
    }
  }
  std::vector<double> magnitudes;
  const auto until = std::chrono::steady_clock::now() + 1s;
  while (std::chrono::steady_clock::now() < until) {
    palpate_ToolFeedback sample{};
    void* pointer = &sample;
    dds_sample_info_t info;
    if (dds_take(reader, &pointer, &info, 1, 1) == 1 && info.valid_data &&
        std::string(sample.tool_id) == "right" &&
        (sample.watchdog || sample.state == palpate_TOOL_FREE))
      magnitudes.push_back(Vector3d(sample.force[0], sample.force[1], sample.force[2]).norm());
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_GE(magnitudes.size(), 3u) << daemon_->log();
  EXPECT_LT(magnitudes.front(), pressed * 1.01);
  EXPECT_EQ(magnitudes.back(), 0.0);
  EXPECT_TRUE(saw_event(client_->take_events(), "right", ToolEventKind::kWatchdog));
}

}  // namespace
}  // namespace palpate
