#pragma once
// The fixture of the contact engine's tests (tool_contact_test.cpp,
// tool_session_test.cpp, tool_friction_test.cpp): a real compliance file
// (the 100 × 50 × 40 mm box clamped on x = 0, 12.5 mm cubes), the tools
// that press it, a driver that moves them tick by tick, and the direct
// computations on its G that the engine's answers are checked against.
// A named namespace, not an anonymous one: the test files share one unity
// build.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "palpate/runtime/contact/contact_geometry.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "support/box_job.hpp"
#include "support/sphere_tool.hpp"
#include "support/test_meshes.hpp"

namespace palpate::tool_contact_testing {

using Eigen::Vector3d;

// Forces come from small SPD solves on G (entries ~1e-4 m/N): they agree
// with the direct dense solves to ~1e-12 relative; 1e-9 leaves margin.
constexpr double kRelativeTolerance = 1e-9;
constexpr double kTick = 0.001;       // s, the haptic rate
constexpr double kSticks = INFINITY;  // friction that never lets a contact slide

class ToolContactTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    // A 100 × 50 × 40 mm box clamped on x = 0, 12.5 mm cubes.
    model_ = new SurfaceModel(
        load_surface_model("box", testing::write_box_compliance(dir_->path(), "box", 8)));
  }
  static void TearDownTestSuite() {
    delete model_;
    delete dir_;
  }
  static const SurfaceModel& model() { return *model_; }

  /// The compliance vertex of the top face (z = 40 mm) nearest (x, y) in mm.
  static int top_vertex(double x_mm, double y_mm) {
    return testing::box_top_vertex(model().surface.rest_positions_m,
                                   model().compliance_vertex_count(), x_mm, y_mm);
  }
  static Vector3d rest(int j) {
    return Eigen::Map<const Vector3d>(
        &model().surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
  }
  static Eigen::Matrix3d G_block(int a, int b) { return model().G.block<3, 3>(3 * a, 3 * b); }
  /// The deepest penetration (m) of tool @p g at @p pose into the surface
  /// triangles deformed by the engine's contact loads (u = G f on every
  /// vertex), through the closest pair of each triangle and the tip's axis.
  static double penetration(const ToolContactEngine& engine, const ToolGeometry& g,
                            const ToolPoseInput& pose) {
    const DrawnSurface& s = model().surface;
    const int n = model().compliance_vertex_count();
    Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * n);
    const auto idx = engine.contact_indices();
    for (std::size_t l = 0; l < idx.size(); ++l)
      f.segment<3>(3 * idx[l]) += Eigen::Map<const Vector3d>(&engine.contact_forces()[3 * l]);
    const Eigen::VectorXd u = model().G * f;
    auto x = [&](int v) { return v < n ? Vector3d(rest(v) + u.segment<3>(3 * v)) : rest(v); };
    const Vector3d axis = pose.orientation.toRotationMatrix().col(2);
    const double length = g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0;
    double deepest = 0;
    for (int t = 0; t < s.triangle_count(); ++t) {
      const auto* v = &s.triangles[3 * static_cast<std::size_t>(t)];
      const auto pair =
          detail::closest_segment_triangle(pose.position_m, axis, length, x(static_cast<int>(v[0])),
                                           x(static_cast<int>(v[1])), x(static_cast<int>(v[2])));
      deepest = std::max(deepest, g.tip_radius_m - pair.distance);
    }
    return deepest;
  }
  /// A contact point at rest, Σ w_i rest_i.
  static Vector3d point_rest(const ContactPoint& p) {
    Vector3d x = Vector3d::Zero();
    for (int i = 0; i < p.vertex_count; ++i) x += p.weights[i] * rest(p.vertices[i]);
    return x;
  }
  /// The points' compliance block Σ_i Σ_j w_pi w_qj G^{a_pi a_qj} (fixed vertices: none).
  static Eigen::Matrix3d point_block(const ContactPoint& p, const ContactPoint& q) {
    const int n = model().compliance_vertex_count();
    Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
    for (int i = 0; i < p.vertex_count; ++i)
      for (int j = 0; j < q.vertex_count; ++j)
        if (p.vertices[i] < n && q.vertices[j] < n)
          P += p.weights[i] * q.weights[j] * G_block(p.vertices[i], q.vertices[j]);
    return P;
  }

  static ToolGeometry probe(const std::string& id, double friction, double radius_m = 0.002) {
    return testing::sphere_tool(id, radius_m, friction);
  }

  /// Pointing down: the tool's +z is the model's −z.
  static ToolPoseInput pose_at(const Vector3d& hinge, double jaw = 0) {
    ToolPoseInput pose;
    pose.position_m = hinge;
    pose.orientation = Eigen::Quaterniond(0, 1, 0, 0);
    pose.jaw_angle_rad = jaw;
    return pose;
  }

  /// Moves tool @p t in straight steps of at most @p step_m from its current
  /// hinge to @p to, one tick per step; returns the last status.
  struct Driver {
    ToolContactEngine& engine;
    std::vector<ToolPoseInput> poses;
    double now = 0;
    std::vector<ToolOutput> log;  // every output of every tick, in order
    std::vector<int> log_tool;

    Driver(ToolContactEngine& e, int tools) : engine(e), poses(static_cast<std::size_t>(tools)) {}

    void tick(int t) {
      ToolPoseInput& p = poses[static_cast<std::size_t>(t)];
      ++p.sequence;
      ToolPoseInput checked = p;
      ASSERT_EQ(engine.check(t, checked), PoseProblem::kNone);
      ASSERT_EQ(engine.update(t, checked, now), RequestStatus::kOk) << engine.solver_message();
      log.push_back(engine.output(t));
      log_tool.push_back(t);
    }
    void tick_all() {
      for (int t = 0; t < static_cast<int>(poses.size()); ++t) tick(t);
      now += kTick;
    }
    void move(int t, const Vector3d& to, double jaw, double step_m = 5e-5,
              double jaw_step = degrees(1)) {
      ToolPoseInput& p = poses[static_cast<std::size_t>(t)];
      const Vector3d from = p.position_m;
      const double jaw_from = p.jaw_angle_rad;
      const int n =
          std::max(1, static_cast<int>(std::ceil(std::max((to - from).norm() / step_m,
                                                          std::abs(jaw - jaw_from) / jaw_step))));
      for (int i = 1; i <= n; ++i) {
        p.position_m = from + (to - from) * (static_cast<double>(i) / n);
        p.jaw_angle_rad = jaw_from + (jaw - jaw_from) * (static_cast<double>(i) / n);
        tick_all();
      }
    }
    void hold(int ticks) {
      for (int i = 0; i < ticks; ++i) tick_all();
    }
    const ToolOutput& last(int t) const { return engine.output(t); }
    bool saw(int t, ToolEventKind kind) const {
      for (std::size_t i = 0; i < log.size(); ++i)
        if (log_tool[i] == t)
          for (int e = 0; e < log[i].event_count; ++e)
            if (log[i].events[static_cast<std::size_t>(e)] == kind) return true;
      return false;
    }
  };

  static void start(Driver& driver, int t, const Vector3d& hinge, double jaw = 0) {
    driver.poses[static_cast<std::size_t>(t)] = pose_at(hinge, jaw);
  }

  inline static testing::TempDir* dir_ = nullptr;
  inline static SurfaceModel* model_ = nullptr;
};

}  // namespace palpate::tool_contact_testing
