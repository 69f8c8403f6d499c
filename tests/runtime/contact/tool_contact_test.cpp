// Tools on an organ (docs/tools.md) against the direct solves of docs/model/requests.md on
// the G of a real compliance file: probing, gliding, grasping, two tools,
// the contact set a tick solves and the bound on its displacements. The
// session (limits, watchdog, refused poses): tool_session_test.cpp; friction
// that drags: tool_friction_test.cpp.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

#include "runtime/contact/tool_contact_fixture.hpp"

namespace palpate::tool_contact_testing {
namespace {

TEST_F(ToolContactTest, ATouchAtAVertexIsTheVertexContactAndDeeperTheJointSolve) {
  // A sticking probe lowered onto vertex v of the flat top face first meets
  // v itself: the deepest point of every triangle around v is v, one point
  // of weight 1, so the force is that of the vertex model, G_vv f = u_v.
  // Pressed on, the face dips around v and the triangles beside it reach the
  // tip too: the force is then the joint solve P f = u of all the points.
  const int v = top_vertex(75, 25);
  const double d = 0.003, r = 0.002;
  ToolContactEngine engine(model(), {probe("probe", kSticks, r)}, {}, {});
  Driver driver(engine, 1);
  start(driver, 0, rest(v) + Vector3d(0, 0, r + 0.0005));
  while (driver.last(0).state != ToolState::kTouching && driver.now < 1) {
    driver.poses[0].position_m.z() -= 5e-5;
    driver.tick_all();
  }
  ASSERT_EQ(engine.contact_points().size(), 1u);
  const ContactPoint& first = engine.contact_points()[0];
  ASSERT_EQ(first.vertex_count, 1);
  EXPECT_EQ(first.vertices[0], v);
  EXPECT_EQ(first.weights[0], 1.0);
  const Vector3d u_v = first.position_m - rest(v);
  EXPECT_LT(u_v.z(), 0.0);
  const Vector3d expected = G_block(v, v).ldlt().solve(u_v);  // on the organ
  EXPECT_LT((driver.last(0).force_n + expected).norm(), kRelativeTolerance * expected.norm());
  EXPECT_TRUE(driver.saw(0, ToolEventKind::kTouch));

  driver.move(0, rest(v) + Vector3d(0, 0, r - d), 0);
  driver.hold(5);
  const auto points = engine.contact_points();
  const auto k = static_cast<Eigen::Index>(points.size());
  Eigen::VectorXd u(3 * k);
  Eigen::MatrixXd P(3 * k, 3 * k);
  for (Eigen::Index c = 0; c < k; ++c) {
    const ContactPoint& p = points[static_cast<std::size_t>(c)];
    u.segment<3>(3 * c) = p.position_m - point_rest(p);
    for (Eigen::Index e = 0; e < k; ++e)
      P.block<3, 3>(3 * c, 3 * e) = point_block(p, points[static_cast<std::size_t>(e)]);
  }
  const Eigen::VectorXd f = P.ldlt().solve(u);
  Vector3d on_organ = Vector3d::Zero();
  for (Eigen::Index c = 0; c < k; ++c) on_organ += f.segment<3>(3 * c);
  EXPECT_LT((driver.last(0).force_n + on_organ).norm(), kRelativeTolerance * f.norm());
  EXPECT_GT(driver.last(0).force_n.z(), 0.1) << "the organ pushes the probe back up";
  EXPECT_EQ(driver.last(0).state, ToolState::kTouching);
}

TEST_F(ToolContactTest, AFrictionlessProbeRestsOnTheSurfaceWithNormalForcesOnly) {
  // Normal-only rows: held still, every contact point settles on the tip's
  // surface (at distance r from its centre c), each force is along its
  // normal and pushes, and the tool feels minus their sum.
  const int v = top_vertex(75, 25);
  const double d = 0.003, r = 0.006;  // the centre stays above the rest surface
  ToolContactEngine engine(model(), {probe("probe", 0.0, r)}, {}, {});
  Driver driver(engine, 1);
  start(driver, 0, rest(v) + Vector3d(0, 0, r + 0.002));
  const Vector3d c = rest(v) + Vector3d(0, 0, r - d);
  driver.move(0, c, 0);
  driver.hold(200);
  const auto points = engine.contact_points();
  ASSERT_GE(points.size(), 1u);
  Vector3d sum = Vector3d::Zero();
  for (const ContactPoint& p : points) {
    EXPECT_NEAR((p.position_m - c).norm(), r, 1e-6 * r) << "on the tip's surface, settled";
    ASSERT_NEAR(p.normal.norm(), 1.0, 1e-12);
    EXPECT_LT((p.force_n - p.force_n.dot(p.normal) * p.normal).norm(), 1e-12 * p.force_n.norm());
    EXPECT_GT(p.force_n.dot(p.normal), 0.0);
    sum += p.force_n;
  }
  EXPECT_LT((driver.last(0).force_n + sum).norm(), kRelativeTolerance * sum.norm());
  EXPECT_GT(driver.last(0).force_n.z(), 0.9 * driver.last(0).force_n.norm());
}

TEST_F(ToolContactTest, ForceGrowsWithDepthAndVanishesWhenWithdrawn) {
  ToolGeometry g;  // the default capsule grasper, pointing down
  g.id = "grasper";
  g.force_limit_n = 100;
  ToolContactEngine engine(model(), {g}, {}, {});
  Driver driver(engine, 1);
  const Vector3d surface = rest(top_vertex(75, 25));
  const Vector3d above = surface + Vector3d(0, 0, g.tip_length_m + g.tip_radius_m + 0.002);
  start(driver, 0, above);
  double previous = 0;
  for (const double depth : {0.002, 0.004, 0.006}) {
    driver.move(0, above - Vector3d(0, 0, 0.002 + depth), 0);
    driver.hold(20);
    const double f = driver.last(0).force_n.norm();
    EXPECT_GT(f, previous * 1.2) << "depth " << depth;
    previous = f;
  }
  driver.move(0, above, 0);
  driver.hold(20);
  EXPECT_EQ(driver.last(0).force_n.norm(), 0.0);
  EXPECT_EQ(driver.last(0).contacts, 0);
  EXPECT_EQ(driver.last(0).state, ToolState::kFree);
  EXPECT_TRUE(engine.contact_indices().empty());
  EXPECT_TRUE(driver.saw(0, ToolEventKind::kLeave));
}

TEST_F(ToolContactTest, GlidingMovesTheContactSetAndKeepsEachForceNormal) {
  ToolContactEngine engine(model(), {probe("probe", 0.0, 0.008)}, {}, {});
  Driver driver(engine, 1);
  const Vector3d a = rest(top_vertex(50, 25));
  start(driver, 0, a + Vector3d(0, 0, 0.010));
  driver.move(0, a + Vector3d(0, 0, 0.008 - 0.004), 0);
  driver.hold(10);
  const std::set<int> before(engine.contact_indices().begin(), engine.contact_indices().end());
  ASSERT_FALSE(before.empty());
  double worst_tangential = 0;
  std::set<int> touched = before;
  for (int i = 1; i <= 500; ++i) {  // 25 mm along x at 0.05 mm per tick
    driver.poses[0].position_m.x() += 5e-5;
    driver.tick_all();
    for (const ContactPoint& point : engine.contact_points()) {
      const Vector3d& fc = point.force_n;
      const Vector3d& nc = point.normal;
      ASSERT_NEAR(nc.norm(), 1.0, 1e-12);
      worst_tangential = std::max(worst_tangential, (fc - fc.dot(nc) * nc).norm() / fc.norm());
      EXPECT_GE(fc.dot(nc), 0.0) << "a contact pulls the tissue (adhesion not released)";
    }
    for (const int v : engine.contact_indices()) touched.insert(v);
    ASSERT_GT(driver.last(0).contacts, 0) << "lost contact at tick " << i;
  }
  const std::set<int> after(engine.contact_indices().begin(), engine.contact_indices().end());
  EXPECT_NE(before, after);
  EXPECT_GT(touched.size(), before.size());
  EXPECT_LT(worst_tangential, 1e-12);
  // On a flat face the net force stays mostly along the face's normal.
  const Vector3d f = driver.last(0).force_n;
  EXPECT_GT(f.z(), 0.8 * f.norm());
}

TEST_F(ToolContactTest, GraspAndPullOpposesThePullAndReleaseReturnsTheOrganToRest) {
  ToolGeometry g;
  g.id = "grasper";
  g.force_limit_n = 100;
  ToolContactEngine engine(model(), {g}, {}, {});
  Driver driver(engine, 1);
  const Vector3d surface = rest(top_vertex(75, 25));
  const double reach = g.tip_length_m + g.tip_radius_m;
  const Vector3d above = surface + Vector3d(0, 0, reach + 0.002);
  start(driver, 0, above, degrees(40));
  const Vector3d in = surface + Vector3d(0, 0, reach - 0.003);
  driver.move(0, in, degrees(40));  // jaws open around the tissue
  driver.move(0, in, 0.0);          // close
  ASSERT_TRUE(driver.saw(0, ToolEventKind::kGrasp));
  ASSERT_EQ(driver.last(0).state, ToolState::kGrasping);
  EXPECT_GT(driver.last(0).held, 0);
  driver.move(0, in + Vector3d(0, 0, 0.008), 0.0);  // pull 8 mm up
  driver.hold(20);
  const Vector3d pulled = driver.last(0).force_n;
  EXPECT_LT(pulled.z(), -0.05) << "the organ holds the tool back";
  // The box is a cantilever: held rigidly, the tissue also pulls sideways.
  EXPECT_GT(-pulled.z(), 0.6 * pulled.norm());
  driver.move(0, in + Vector3d(0, 0, 0.008), degrees(40));  // open
  EXPECT_TRUE(driver.saw(0, ToolEventKind::kRelease));
  driver.move(0, above, degrees(40));
  driver.hold(20);
  EXPECT_TRUE(engine.contact_indices().empty()) << "the organ is back at rest";
  EXPECT_EQ(driver.last(0).force_n.norm(), 0.0);
  EXPECT_EQ(driver.last(0).state, ToolState::kFree);
}

TEST_F(ToolContactTest, TwoToolsAreSolvedTogether) {
  // Two sticking probes 25 mm apart across the box press together: the joint
  // 6 × 6 solve G_CC f_C = u_C, not two separate 3 × 3 ones.
  const int a = top_vertex(75, 12.5), b = top_vertex(75, 37.5);
  ASSERT_NE(a, b);
  const double d = 0.003, r = 0.002;
  ToolContactEngine engine(model(), {probe("left", kSticks, r), probe("right", kSticks, r)}, {},
                           {});
  Driver driver(engine, 2);
  start(driver, 0, rest(a) + Vector3d(0, 0, r + 0.001));
  start(driver, 1, rest(b) + Vector3d(0, 0, r + 0.001));
  for (int i = 0; i < 80; ++i) {  // both down 4 mm, 0.05 mm per tick
    driver.poses[0].position_m.z() -= 5e-5;
    driver.poses[1].position_m.z() -= 5e-5;
    driver.tick_all();
  }
  driver.hold(5);
  // Each contact's imposed displacement as the engine set it (the first
  // press moved b sideways before the second tool reached it), and the
  // joint solve P f = u of every tool's points together.
  const auto points = engine.contact_points();
  const auto k = static_cast<Eigen::Index>(points.size());
  ASSERT_GE(k, 2);
  Eigen::VectorXd u(3 * k);
  Eigen::MatrixXd P(3 * k, 3 * k);
  for (Eigen::Index c = 0; c < k; ++c) {
    u.segment<3>(3 * c) = points[static_cast<std::size_t>(c)].position_m -
                          point_rest(points[static_cast<std::size_t>(c)]);
    for (Eigen::Index e = 0; e < k; ++e)
      P.block<3, 3>(3 * c, 3 * e) =
          point_block(points[static_cast<std::size_t>(c)], points[static_cast<std::size_t>(e)]);
  }
  const Eigen::VectorXd f = P.ldlt().solve(u);
  Vector3d on[2] = {Vector3d::Zero(), Vector3d::Zero()}, alone = Vector3d::Zero();
  std::vector<Eigen::Index> left;
  for (Eigen::Index c = 0; c < k; ++c) {
    on[points[static_cast<std::size_t>(c)].tool] += f.segment<3>(3 * c);
    if (points[static_cast<std::size_t>(c)].tool == 0) left.push_back(c);
  }
  EXPECT_LT((driver.last(0).force_n + on[0]).norm(), kRelativeTolerance * f.norm());
  EXPECT_LT((driver.last(1).force_n + on[1]).norm(), kRelativeTolerance * f.norm());
  EXPECT_GT(driver.last(0).force_n.z(), 0.1);
  EXPECT_GT(driver.last(1).force_n.z(), 0.1);
  // Coupled through G: the left tool's points alone would feel something else.
  const auto kl = static_cast<Eigen::Index>(left.size());
  Eigen::MatrixXd P_left(3 * kl, 3 * kl);
  Eigen::VectorXd u_left(3 * kl);
  for (Eigen::Index c = 0; c < kl; ++c) {
    u_left.segment<3>(3 * c) = u.segment<3>(3 * left[static_cast<std::size_t>(c)]);
    for (Eigen::Index e = 0; e < kl; ++e)
      P_left.block<3, 3>(3 * c, 3 * e) = P.block<3, 3>(3 * left[static_cast<std::size_t>(c)],
                                                       3 * left[static_cast<std::size_t>(e)]);
  }
  const Eigen::VectorXd f_left = P_left.ldlt().solve(u_left);
  for (Eigen::Index c = 0; c < kl; ++c) alone += f_left.segment<3>(3 * c);
  EXPECT_GT((on[0] - alone).norm(), 0.005 * alone.norm());
  (void)d;
}

TEST_F(ToolContactTest, AGlideOverTrianglesIsNeverFreeAndSmoothWithOrWithoutFriction) {
  // A capsule pressed 3 mm and dragged 37.5 mm along the box, across
  // triangles of 12.5 mm: the contact moves from triangle to triangle, the
  // tool is never free in between, no tick's force differs from the
  // previous one by more than 25 % of the mean force, and the tip never
  // sinks into the deformed triangles by more than 10 % of r
  // (docs/tools.md, "How the contact feels"), measured on the engine's force
  // before the slew limit (set out of reach here). With friction 0.3 the
  // glide is as smooth, and the tool feels the friction against its motion
  // (docs/tools.md, "Friction"); frictionless, hardly any.
  for (const double friction : {0.0, 0.3}) {
    ToolGeometry g;
    g.id = "grasper";
    g.tip_radius_m = 0.010;
    g.friction = friction;
    g.force_limit_n = 100;
    g.max_force_rate_n_per_s = 1e6;
    ToolContactEngine engine(model(), {g}, {}, {});
    Driver driver(engine, 1);
    const Vector3d a = rest(top_vertex(37.5, 25));
    const double reach = g.tip_length_m + g.tip_radius_m;
    start(driver, 0, a + Vector3d(0, 0, reach + 0.001));
    driver.move(0, a + Vector3d(0, 0, reach - 0.003), 0);
    driver.hold(10);
    ASSERT_EQ(driver.last(0).state, ToolState::kTouching);
    const std::size_t from = driver.log.size();
    std::set<int> touched;
    double deepest = 0;               // penetration of the tip into the deformed triangles, m
    for (int i = 0; i < 1875; ++i) {  // 37.5 mm at 0.02 mm per tick
      driver.poses[0].position_m.x() += 2e-5;
      driver.tick_all();
      for (const ContactPoint& p : engine.contact_points()) touched.insert(p.triangle);
      if (i % 25 == 0) deepest = std::max(deepest, penetration(engine, g, driver.poses[0]));
    }
    SCOPED_TRACE(::testing::Message() << "friction " << friction);
    EXPECT_LT(deepest, 0.1 * g.tip_radius_m);
    for (std::size_t i = from; i < driver.log.size(); ++i)
      ASSERT_NE(driver.log[i].state, ToolState::kFree) << "free at tick " << i - from;
    EXPECT_GE(touched.size(), 4u) << "the contact moved along";
    double mean = 0, worst = 0;
    Vector3d mean_force = Vector3d::Zero();
    for (std::size_t i = from; i < driver.log.size(); ++i) {
      mean += driver.log[i].force_n.norm();
      mean_force += driver.log[i].force_n;
    }
    mean /= static_cast<double>(driver.log.size() - from);
    mean_force /= static_cast<double>(driver.log.size() - from);
    for (std::size_t i = from + 1; i < driver.log.size(); ++i)
      worst = std::max(worst, (driver.log[i].force_n - driver.log[i - 1].force_n).norm());
    EXPECT_GT(mean, 0.5);
    EXPECT_LT(worst, 0.25 * mean);
    // Along the glide: friction 0.3 holds back by 0.23 of the push
    // (measured); frictionless, 0.05 (the triangles' slopes).
    if (friction > 0)
      EXPECT_LT(mean_force.x(), -0.5 * friction * mean_force.z());
    else
      EXPECT_LT(std::abs(mean_force.x()), 0.1 * mean_force.z());
  }
}

/// What a drag with friction gives: the tool's hinge, its output and its
/// contact points at every tick.

TEST_F(ToolContactTest, APressBetweenVerticesIsFeltEveryTick) {
  // A 2 mm sphere pressed 3 mm at the centroid of a top-face triangle of
  // 12.5 mm, farther than its radius from every vertex: with contacts at
  // vertices it met none. On the triangle it is touching on every tick of a
  // 500-tick hold, with one point inside that triangle and a force that grows
  // with depth.
  const DrawnSurface& s = model().surface;
  const int n = model().compliance_vertex_count();
  int chosen = -1;
  Vector3d centroid = Vector3d::Zero();
  for (int t = 0; t < s.triangle_count() && chosen < 0; ++t) {
    const auto* v = &s.triangles[3 * static_cast<std::size_t>(t)];
    Vector3d c = Vector3d::Zero();
    bool top = true;
    for (int i = 0; i < 3; ++i) {
      top &= static_cast<int>(v[i]) < n && std::abs(rest(static_cast<int>(v[i])).z() - 0.04) < 1e-9;
      c += rest(static_cast<int>(v[i])) / 3;
    }
    if (top && c.x() > 0.06) chosen = t, centroid = c;
  }
  ASSERT_GE(chosen, 0);
  ToolGeometry g = probe("finger", 0.3);
  ToolContactEngine engine(model(), {g}, {}, {});
  Driver driver(engine, 1);
  start(driver, 0, centroid + Vector3d(0, 0, g.tip_radius_m + 0.001));
  driver.move(0, centroid + Vector3d(0, 0, g.tip_radius_m - 0.0015), 0);
  const double half_way = driver.last(0).force_n.z();
  driver.move(0, centroid + Vector3d(0, 0, g.tip_radius_m - 0.003), 0);
  const std::size_t from = driver.log.size();
  driver.hold(500);
  for (std::size_t i = from; i < driver.log.size(); ++i)
    ASSERT_EQ(driver.log[i].state, ToolState::kTouching) << "free at tick " << i - from;
  ASSERT_EQ(engine.contact_points().size(), 1u);
  EXPECT_EQ(engine.contact_points()[0].triangle, chosen);
  EXPECT_EQ(engine.contact_points()[0].vertex_count, 3);
  EXPECT_GT(half_way, 0.01);
  EXPECT_GT(driver.last(0).force_n.z(), 1.5 * half_way) << "deeper presses harder";
}

TEST_F(ToolContactTest, ATiltedPressMovedSidewaysNeverFlickers) {
  // The default grasper tilted 20° from the vertical, pressed 8 mm, held,
  // moved 10 mm sideways at 10 mm/s, held: touch once, never leave, never a
  // free tick (with contacts at vertices it logged touch/leave/touch/leave).
  ToolGeometry g;
  g.id = "grasper";
  g.force_limit_n = 100;
  g.max_force_rate_n_per_s = 1e6;
  ToolContactEngine engine(model(), {g}, {}, {});
  Driver driver(engine, 1);
  const Eigen::Quaterniond tilted =
      Eigen::AngleAxisd(degrees(20), Vector3d::UnitY()) * Eigen::Quaterniond(0, 1, 0, 0);
  const Vector3d axis = tilted.toRotationMatrix().col(2);  // into the organ
  const Vector3d at = rest(top_vertex(62.5, 25)) + Vector3d(0.003, 0.004, 0);
  const double reach = g.tip_length_m + g.tip_radius_m;
  const Vector3d above = at - (reach + 0.002) * axis;
  driver.poses[0] = pose_at(above);
  driver.poses[0].orientation = tilted;
  driver.move(0, above + 0.010 * axis, 0);  // 8 mm into the surface along the shaft
  driver.hold(200);
  ASSERT_EQ(driver.last(0).state, ToolState::kTouching);
  const std::size_t from = driver.log.size();
  driver.move(0, driver.poses[0].position_m + Vector3d(0, 0.010, 0), 0, 1e-5);
  driver.hold(200);
  for (std::size_t i = from; i < driver.log.size(); ++i)
    ASSERT_EQ(driver.log[i].state, ToolState::kTouching) << "free at tick " << i - from;
  int touches = 0, leaves = 0;
  for (const ToolOutput& out : driver.log)
    for (int e = 0; e < out.event_count; ++e) {
      touches += out.events[static_cast<std::size_t>(e)] == ToolEventKind::kTouch;
      leaves += out.events[static_cast<std::size_t>(e)] == ToolEventKind::kLeave;
    }
  EXPECT_EQ(touches, 1);
  EXPECT_EQ(leaves, 0);
}

TEST_F(ToolContactTest, EveryStoredContactIsTheSolutionOfTheSetSolvedLast) {
  // Whatever the iteration limit, the contacts the engine stores and feeds
  // back are those of its last solve: each contact's deformed position is
  // its rest position plus G times every stored force, and the tool feels
  // minus their sum. A contact let go (adhesion) after the last allowed
  // solve must not shift the forces onto other vertices.
  //
  // A frictionless probe rests lightly on v; in one tick a sticking probe
  // (6 mm radius) presses the neighbour w 5 mm in, which drags v down, away
  // from the first probe: to hold v on its surface it would have to pull,
  // so that contact is let go (with one iteration, after the only solve).
  const int v = top_vertex(62.5, 25), w = top_vertex(75, 25);
  for (const int iterations : {1, 2, 4}) {
    ContactSettings settings;
    settings.max_iterations = iterations;
    ToolContactEngine engine(
        model(), {probe("presser", kSticks, 0.006), probe("rester", 0.0, 0.003)}, settings, {});
    Driver driver(engine, 2);
    start(driver, 0, rest(w) + Vector3d(0, 0, 0.008));
    start(driver, 1, rest(v) + Vector3d(0, 0, 0.0035));
    driver.move(1, rest(v) + Vector3d(0, 0, 0.0029), 0);  // 0.1 mm into v
    driver.hold(5);
    ASSERT_EQ(driver.last(1).state, ToolState::kTouching) << iterations << " iterations";
    for (const double depth : {0.005, 0.0055, 0.006}) {
      driver.poses[0].position_m = rest(w) + Vector3d(0, 0, 0.006 - depth);
      driver.tick(0);  // the presser alone: its output is of the contacts now stored
      const auto points = engine.contact_points();
      Vector3d felt = Vector3d::Zero();
      for (std::size_t c = 0; c < points.size(); ++c) {
        Vector3d u = Vector3d::Zero();
        for (std::size_t j = 0; j < points.size(); ++j)
          u += point_block(points[c], points[j]) * points[j].force_n;
        // Positions are u_C = P f_C from the solve: round-off of the
        // small dense products, ~1e-15 m against displacements of mm.
        EXPECT_LT((points[c].position_m - point_rest(points[c]) - u).norm(), 1e-12)
            << "contact " << c << " of " << points.size() << ", depth " << depth << ", "
            << iterations << " iterations";
        if (points[c].tool == 0) felt -= points[c].force_n;
      }
      EXPECT_GT(felt.norm(), 0.1) << "the presser presses";
      EXPECT_LT((driver.last(0).force_n - felt).norm(), 1e-9 * felt.norm())
          << "depth " << depth << ", " << iterations << " iterations";
      driver.now += kTick;
    }
  }
}

// The engine leaves out, before deforming them, the triangles that cannot
// reach the tip: it bounds every vertex's displacement under the loads f by
// |u_v| ≤ √(‖G^vv‖_F fᵀ G f) (Cauchy–Schwarz in G's inner product), which
// holds only if the precomputed G is symmetric positive definite. On a real
// compliance file, random loads: no vertex moves farther than the bound
// (1e-9 relative: round-off, and G's asymmetry of ~1e-15), and the bound is
// reached within a factor 2 somewhere (it is not vacuous).
TEST_F(ToolContactTest, TheLoadsEnergyBoundsEveryVertexsDisplacement) {
  const int n = model().compliance_vertex_count();
  std::mt19937 random(17);
  std::uniform_int_distribution<int> vertex(0, n - 1), loads(1, 12);
  std::uniform_real_distribution<double> component(-5, 5);
  double closest = 0;  // the largest |u_v| / bound met
  for (int trial = 0; trial < 200; ++trial) {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * n);
    for (int l = loads(random); l > 0; --l)
      f.segment<3>(3 * vertex(random)) +=
          Vector3d(component(random), component(random), component(random));
    const Eigen::VectorXd u = model().G * f;
    const double energy = f.dot(u);
    ASSERT_GT(energy, 0) << "G is positive definite";
    for (int v = 0; v < n; ++v) {
      const double bound = std::sqrt(G_block(v, v).norm() * energy);
      const double moved = u.segment<3>(3 * v).norm();
      EXPECT_LE(moved, (1 + 1e-9) * bound) << "vertex " << v << ", trial " << trial;
      closest = std::max(closest, moved / bound);
    }
  }
  EXPECT_GT(closest, 0.5);
}

}  // namespace
}  // namespace palpate::tool_contact_testing
