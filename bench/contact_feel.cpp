// What the trainee feels, measured (docs/tools.md, "How the contact feels"):
// scripted gestures played through ToolContactEngine at 1 kHz of simulated
// time, with the measures of issue 17 computed from outside the engine (its
// own closest-point code is not used here):
//
//   glide   a capsule (r = --radius-mm, 15 mm long, friction --friction,
//           default 0) pressed --depth-mm below the rest surface at the
//           auto anchor and glided 36 mm along it at 20 mm/s, played at
//           --rate-hz (default 1000): ticks with zero force while the tip
//           is more than 1 mm into the rest surface ("free inside"), their
//           longest stretch, the deepest penetration of the tip into the
//           deformed triangles after each tick's solve (% of r), the
//           largest tick-to-tick force change (% of the mean force, the
//           middle 80 % of the glide) and the mean force against the
//           motion there (friction).
//   press   palpated's default grasper (capsule r = 4 mm, friction 0.3)
//           tilted 20°, pressed 8 mm at --press-vertex (or the auto anchor),
//           held 1 s, moved 10 mm sideways at 5 mm/s, held 1 s: touch and
//           leave events after the first touch.
//   curve   a frictionless 5 mm sphere pressed along the normal of the
//           point --curve-point (or the auto anchor) to 1..5 mm: the force
//           along the press at each depth, for comparing resolutions.
//   wide    a frictionless 15 mm sphere pressed 8 mm and glided 10 mm with
//           up to 64 contacts: contacts per tick and the tick's time.
//
// The force is the engine's before the device limits (force limit and slew
// set out of reach). Each scenario also reports the time of a tick
// (update(): detection, solve, feedback), p50 and p99 in µs.
//
// It uses only ToolContactEngine's public interface, so it builds against
// the tree before surface contacts too (the same-run baseline of
// docs/benchmarks-history.md, "Contact with the surface").
//
// palpated runs OpenBLAS on one thread (set_blas_threads(1)); run this the
// same way: OPENBLAS_NUM_THREADS=1.
//
// Usage: palpate_contact_feel MODEL.h5 [--radius-mm 2] [--depth-mm 2] [--friction 0]
//            [--rate-hz 1000]
//            [--press-vertex ID] [--curve-point X,Y,Z,NX,NY,NZ (m)] [--json FILE]

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "palpate/core/rotation.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/drawn_surface.hpp"
#include "palpate/runtime/gesture.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace {

using Eigen::Vector3d;
using palpate::SurfaceModel;
using palpate::ToolContactEngine;
using palpate::ToolGeometry;

// ---- independent geometry: closest point on a triangle, distance to a segment

Vector3d closest_point_on_triangle(const Vector3d& x, const Vector3d& a, const Vector3d& b,
                                   const Vector3d& c) {
  const Vector3d n = (b - a).cross(c - a);
  const double area2 = n.squaredNorm();
  if (area2 > 0) {
    const Vector3d p = x - n * (n.dot(x - a) / area2);  // projection on the plane
    const double wa = (c - b).cross(p - b).dot(n), wb = (a - c).cross(p - c).dot(n),
                 wc = (b - a).cross(p - a).dot(n);
    if (wa >= 0 && wb >= 0 && wc >= 0) return p;
  }
  Vector3d best = a;
  for (const auto& [p, q] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
    const Vector3d e = q - p;
    const double t =
        e.squaredNorm() > 0 ? std::clamp((x - p).dot(e) / e.squaredNorm(), 0.0, 1.0) : 0.0;
    const Vector3d y = p + t * e;
    if ((y - x).squaredNorm() < (best - x).squaredNorm()) best = y;
  }
  return best;
}

/// Distance from the segment s0 + t·axis, t ∈ [0, length], to the triangle:
/// convex in t, minimized by ternary search to 1e-12 of the length.
double segment_triangle_distance(const Vector3d& s0, const Vector3d& axis, double length,
                                 const Vector3d& a, const Vector3d& b, const Vector3d& c) {
  auto at = [&](double t) {
    const Vector3d x = s0 + t * axis;
    return (closest_point_on_triangle(x, a, b, c) - x).norm();
  };
  double lo = 0, hi = length;
  for (int i = 0; i < 80 && hi - lo > 1e-12 * std::max(length, 1e-3); ++i) {
    const double m1 = lo + (hi - lo) / 3, m2 = hi - (hi - lo) / 3;
    if (at(m1) < at(m2))
      hi = m2;
    else
      lo = m1;
  }
  return at(0.5 * (lo + hi));
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(
      static_cast<double>(v.size() - 1), std::floor(p * static_cast<double>(v.size()))))];
}

struct Scene {
  const SurfaceModel& model;
  int compliance = 0;
  std::vector<Vector3d> rest;  // per drawn vertex
  std::vector<Vector3d> centroid;
  explicit Scene(const SurfaceModel& m) : model(m), compliance(m.compliance_vertex_count()) {
    for (int v = 0; v < m.surface.vertex_count(); ++v) rest.push_back(m.surface.rest_position(v));
    for (int t = 0; t < m.surface.triangle_count(); ++t) {
      const auto* tri = &m.surface.triangles[3 * static_cast<std::size_t>(t)];
      centroid.push_back((rest[tri[0]] + rest[tri[1]] + rest[tri[2]]) / 3);
    }
  }
  /// The deepest penetration (m) of a capsule into the surface triangles near
  /// it, at rest (engine null) or deformed by the engine's contact loads.
  double penetration(const Vector3d& s0, const Vector3d& axis, double length, double r,
                     const ToolContactEngine* engine) const {
    const auto idx = engine ? engine->contact_indices() : std::span<const int>{};
    const auto f = engine ? engine->contact_forces() : std::span<const double>{};
    auto position = [&](int v) {
      Vector3d x = rest[static_cast<std::size_t>(v)];
      if (v < compliance)
        for (std::size_t l = 0; l < idx.size(); ++l)
          x += model.G_block(v, idx[l]) * Eigen::Map<const Vector3d>(&f[3 * l]);
      return x;
    };
    double deepest = -1;
    const double reach = length + r + 0.02;
    for (std::size_t t = 0; t < centroid.size(); ++t) {
      const Vector3d& x = centroid[t];
      const double along = std::clamp((x - s0).dot(axis), 0.0, length);
      if ((x - s0 - along * axis).norm() > reach) continue;
      const auto* tri = &model.surface.triangles[3 * t];
      const double d = segment_triangle_distance(s0, axis, length, position(tri[0]),
                                                 position(tri[1]), position(tri[2]));
      deepest = std::max(deepest, r - d);
    }
    return deepest;
  }
};

ToolGeometry capsule(double r, double length, double friction) {
  ToolGeometry g;
  g.id = "tool";
  g.tip = length > 0 ? palpate::TipShape::kCapsule : palpate::TipShape::kSphere;
  g.tip_radius_m = r;
  g.tip_length_m = length;
  g.friction = friction;
  g.jaw_length_m = 0;
  g.force_limit_n = 1e6;
  g.max_force_rate_n_per_s = 1e12;
  return g;
}

struct TickLog {
  std::vector<double> time_s, force_n, rest_depth_m, deformed_depth_m, tick_us;
  std::vector<Vector3d> force;
  std::vector<int> contacts;
  int touches = 0, leaves = 0;
};

using PoseAt = std::function<palpate::GesturePose(double)>;

/// Plays poses from @p pose_at for @p duration_s with tool @p g on the model
/// at 1 kHz; measures penetrations when @p measure is set.
TickLog play(const Scene& scene, const PoseAt& pose_at, double duration_s, const ToolGeometry& g,
             bool measure, int max_contacts = 24, double rate_hz = 1000) {
  palpate::ContactSettings settings;
  settings.max_contacts_per_tool = max_contacts;
  palpate::SolverLimits limits;
  limits.max_constraints = std::max(64, max_contacts);
  ToolContactEngine engine(scene.model, {g}, settings, limits);
  TickLog log;
  const int ticks = static_cast<int>(std::ceil(duration_s * rate_hz)) + 1;
  for (int i = 0; i < ticks; ++i) {
    const double t = i / rate_hz;
    const palpate::GesturePose p = pose_at(t);
    palpate::ToolPoseInput pose;
    pose.sequence = static_cast<std::uint64_t>(i + 1);
    pose.position_m = p.hinge_m;
    pose.orientation = p.orientation;
    pose.jaw_angle_rad = p.jaw_angle_rad;
    if (engine.check(0, pose) != palpate::PoseProblem::kNone) {
      std::fprintf(stderr, "contact_feel: pose refused: %s\n", engine.problem_message());
      std::exit(1);
    }
    const auto start = std::chrono::steady_clock::now();
    engine.update(0, pose, t);
    const auto stop = std::chrono::steady_clock::now();
    const palpate::ToolOutput& out = engine.output(0);
    log.tick_us.push_back(std::chrono::duration<double, std::micro>(stop - start).count());
    log.time_s.push_back(t);
    log.force.push_back(out.force_n);
    log.force_n.push_back(out.force_n.norm());
    log.contacts.push_back(out.contacts);
    for (int e = 0; e < out.event_count; ++e) {
      log.touches += out.events[static_cast<std::size_t>(e)] == palpate::ToolEventKind::kTouch;
      log.leaves += out.events[static_cast<std::size_t>(e)] == palpate::ToolEventKind::kLeave;
    }
    if (measure) {
      const Vector3d axis = pose.orientation.toRotationMatrix().col(2);
      const double length = g.tip == palpate::TipShape::kCapsule ? g.tip_length_m : 0.0;
      log.rest_depth_m.push_back(
          scene.penetration(pose.position_m, axis, length, g.tip_radius_m, nullptr));
      log.deformed_depth_m.push_back(
          scene.penetration(pose.position_m, axis, length, g.tip_radius_m, &engine));
    }
  }
  return log;
}

/// Plays gesture TOML text (its first tool).
TickLog play_gesture(const Scene& scene, const std::string& gesture_toml, const ToolGeometry& g,
                     bool measure, int max_contacts = 24) {
  const palpate::Gesture gesture = palpate::parse_gesture(gesture_toml, "contact_feel");
  const palpate::GesturePlayer player(gesture,
                                      palpate::place_gesture(gesture, scene.model.surface));
  return play(
      scene, [&](double t) { return player.sample(0, t); }, player.duration_s(), g, measure,
      max_contacts);
}

std::string anchor_line(long long vertex) {
  return vertex >= 0 ? "anchor = " + std::to_string(vertex) + "\n" : "anchor = \"auto\"\n";
}

}  // namespace

int main(int argc, char** argv) {
  std::string model_path, json_path;
  double radius_mm = 2, depth_mm = 2, friction = 0, rate_hz = 1000;
  long long press_vertex = -1;
  std::vector<double> curve_point;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    auto next = [&]() -> std::string {
      if (a + 1 >= argc) {
        std::fprintf(stderr, "contact_feel: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++a];
    };
    if (arg == "--radius-mm")
      radius_mm = std::stod(next());
    else if (arg == "--depth-mm")
      depth_mm = std::stod(next());
    else if (arg == "--friction")
      friction = std::stod(next());
    else if (arg == "--rate-hz")
      rate_hz = std::stod(next());
    else if (arg == "--press-vertex")
      press_vertex = std::stoll(next());
    else if (arg == "--json")
      json_path = next();
    else if (arg == "--curve-point") {
      std::string s = next();
      for (char& c : s)
        if (c == ',') c = ' ';
      char* p = s.data();
      for (int i = 0; i < 6; ++i) curve_point.push_back(std::strtod(p, &p));
    } else if (arg[0] != '-')
      model_path = arg;
    else {
      std::fprintf(stderr, "contact_feel: unknown option %s\n", arg.c_str());
      return 2;
    }
  }
  if (model_path.empty()) {
    std::fprintf(stderr, "usage: palpate_contact_feel MODEL.h5 [options]\n");
    return 2;
  }
  const SurfaceModel model = palpate::load_surface_model("organ", model_path);
  const Scene scene(model);
  std::string json = "{\n  \"model\": \"" + model_path + "\",\n";

  // ---- glide: along the surface, the tip point `depth` below the rest
  // surface's nearest point (normals interpolated across triangles), 36 mm
  // along the auto anchor's x tangent at 20 mm/s.
  const double r = radius_mm * 1e-3, length = 0.015, depth = depth_mm * 1e-3;
  const palpate::AnchorFrame anchor = palpate::auto_anchor(model.surface);
  const Eigen::MatrixX3d normals = palpate::vertex_normals(model.surface);
  auto on_surface = [&](const Vector3d& x, Vector3d& normal) {
    Vector3d best = x;
    double best_d = INFINITY;
    for (int t = 0; t < model.surface.triangle_count(); ++t) {
      const auto* tri = &model.surface.triangles[3 * static_cast<std::size_t>(t)];
      const Vector3d &a = scene.rest[tri[0]], &b = scene.rest[tri[1]], &c = scene.rest[tri[2]];
      const Vector3d y = closest_point_on_triangle(x, a, b, c);
      if (const double d = (y - x).norm(); d < best_d) {
        best_d = d;
        best = y;
        // Barycentric weights of y, for a smooth normal.
        const Vector3d n = (b - a).cross(c - a);
        const double area2 = n.squaredNorm();
        const double wa = (c - b).cross(y - b).dot(n) / area2,
                     wb = (a - c).cross(y - c).dot(n) / area2;
        normal = (wa * normals.row(tri[0]) + wb * normals.row(tri[1]) +
                  (1 - wa - wb) * normals.row(tri[2]))
                     .transpose()
                     .normalized();
      }
    }
    return best;
  };
  const double reach = length + r;
  auto glide_pose = [&](double t) {
    // s along the tangent (mm): -18 until 0.6 s, to +18 at 2.4 s; the tip
    // point from 10 mm above to `depth` below in 0.4 s, back up after 2.6 s.
    const double s = -0.018 + 0.036 * std::clamp((t - 0.6) / 1.8, 0.0, 1.0);
    const double below = t < 0.4   ? -0.010 + (0.010 + depth) * t / 0.4
                         : t < 2.6 ? depth
                                   : depth - (0.010 + depth) * std::min(1.0, (t - 2.6) / 0.4);
    Vector3d n;
    const Vector3d c = on_surface(anchor.origin_m + s * anchor.x, n);
    palpate::GesturePose pose;
    pose.tip_m = c - below * n;
    pose.hinge_m = pose.tip_m + reach * n;
    pose.orientation = palpate::rotation_taking(Vector3d::UnitZ(), -n);
    return pose;
  };
  const TickLog g = play(scene, glide_pose, 3.0, capsule(r, length, friction), true, 24, rate_hz);
  int free_inside = 0, stretch = 0, longest = 0, glide_ticks = 0;
  double mean = 0, worst_change = 0, worst_pen = 0, against = 0;
  std::vector<double> middle;
  for (std::size_t i = 0; i < g.time_s.size(); ++i) {
    const double t = g.time_s[i];
    if (t < 0.6 || t > 2.4) continue;
    ++glide_ticks;
    const bool inside = g.rest_depth_m[i] > 1e-3;
    if (inside && g.force_n[i] == 0) {
      ++free_inside;
      longest = std::max(longest, ++stretch);
    } else {
      stretch = 0;
    }
    worst_pen = std::max(worst_pen, g.deformed_depth_m[i]);
    if (t >= 0.6 + 0.18 && t <= 2.4 - 0.18) {
      middle.push_back(g.force_n[i]);
      against -= g.force[i].dot(anchor.x);  // the tool moves along x: friction pulls it back
    }
  }
  against /= std::max<std::size_t>(1, middle.size());
  for (double f : middle) mean += f;
  mean /= std::max<std::size_t>(1, middle.size());
  for (std::size_t i = 0; i < g.time_s.size(); ++i) {
    const double t = g.time_s[i];
    if (i == 0 || t < 0.6 + 0.18 || t > 2.4 - 0.18) continue;
    worst_change = std::max(worst_change, (g.force[i] - g.force[i - 1]).norm());
  }
  std::printf(
      "glide (capsule r %.3g mm, friction %.3g, %.3g mm deep, 36 mm at 20 mm/s, %.0f Hz, %d "
      "ticks):\n",
      radius_mm, friction, depth_mm, rate_hz, glide_ticks);
  std::printf("  free inside the rest surface (>1 mm): %d ticks, longest %d ms\n", free_inside,
              longest);
  std::printf("  deepest penetration into the deformed triangles: %.3f mm (%.1f %% of r)\n",
              worst_pen * 1e3, 100 * worst_pen / r);
  std::printf("  mean force (middle 80 %%) %.4f N; largest tick-to-tick change %.4f N (%.1f %%)\n",
              mean, worst_change, 100 * worst_change / std::max(mean, 1e-300));
  std::printf("  mean force against the motion (middle 80 %%) %.4f N\n", against);
  std::printf("  tick p50 %.1f µs, p99 %.1f µs, mean contacts %.2f\n", percentile(g.tick_us, 0.5),
              percentile(g.tick_us, 0.99), [&] {
                double s = 0;
                for (int c : g.contacts) s += c;
                return s / static_cast<double>(g.contacts.size());
              }());
  char buffer[1024];
  std::snprintf(buffer, sizeof buffer,
                "  \"glide\": {\"radius_mm\": %g, \"friction\": %g, \"rate_hz\": %g, "
                "\"depth_mm\": %g, \"ticks\": %d, "
                "\"free_inside_ticks\": %d, \"longest_free_ms\": %d, \"max_penetration_mm\": %.6g, "
                "\"max_penetration_pct_r\": %.4g, \"mean_force_n\": %.6g, \"max_change_n\": %.6g, "
                "\"max_change_pct\": %.4g, \"against_motion_n\": %.6g, \"tick_p50_us\": %.4g, "
                "\"tick_p99_us\": %.4g},\n",
                radius_mm, friction, rate_hz, depth_mm, glide_ticks, free_inside, longest,
                worst_pen * 1e3, 100 * worst_pen / r, mean, worst_change,
                100 * worst_change / std::max(mean, 1e-300), against, percentile(g.tick_us, 0.5),
                percentile(g.tick_us, 0.99));
  json += buffer;

  // ---- tilted steady press, then a slow sideways move
  const std::string press = "name = \"feel-press\"\n" + anchor_line(press_vertex) +
                            "[[tool]]\nid = \"tool\"\n"
                            "[[tool.keyframe]]\nt = 0.0\nposition = [0, 0, 10]\ntilt = [20, 0]\n"
                            "[[tool.keyframe]]\nt = 0.5\nposition = [0, 0, -8]\ntilt = [20, 0]\n"
                            "[[tool.keyframe]]\nt = 1.5\nposition = [0, 0, -8]\ntilt = [20, 0]\n"
                            "[[tool.keyframe]]\nt = 3.5\nposition = [10, 0, -8]\ntilt = [20, 0]\n"
                            "[[tool.keyframe]]\nt = 4.5\nposition = [10, 0, -8]\ntilt = [20, 0]\n";
  ToolGeometry grasper;  // palpated's default tool, no device limits
  grasper.id = "tool";
  grasper.force_limit_n = 1e6;
  grasper.max_force_rate_n_per_s = 1e12;
  const TickLog p = play_gesture(scene, press, grasper, false);
  std::printf("press (default grasper, tilted 20°, 8 mm, held, 10 mm sideways, held):\n");
  std::printf("  touch events %d, leave events %d (a steady press: 1 and 0)\n", p.touches,
              p.leaves);
  std::printf("  force at the end %.4f N; tick p50 %.1f µs, p99 %.1f µs\n", p.force_n.back(),
              percentile(p.tick_us, 0.5), percentile(p.tick_us, 0.99));
  std::snprintf(buffer, sizeof buffer,
                "  \"press\": {\"touches\": %d, \"leaves\": %d, \"final_force_n\": %.6g, "
                "\"tick_p50_us\": %.4g, \"tick_p99_us\": %.4g},\n",
                p.touches, p.leaves, p.force_n.back(), percentile(p.tick_us, 0.5),
                percentile(p.tick_us, 0.99));
  json += buffer;

  // ---- a press between vertices: a frictionless 2 mm sphere 3 mm deep
  // along the normal at the centroid of the surface triangle nearest the
  // auto anchor (not at its vertex), held 2 s: ticks without force.
  {
    std::size_t nearest = 0;
    for (std::size_t t = 0; t < scene.centroid.size(); ++t)
      if ((scene.centroid[t] - anchor.origin_m).norm() <
          (scene.centroid[nearest] - anchor.origin_m).norm())
        nearest = t;
    const auto* tri = &model.surface.triangles[3 * nearest];
    const Vector3d n = (scene.rest[tri[1]] - scene.rest[tri[0]])
                           .cross(scene.rest[tri[2]] - scene.rest[tri[0]])
                           .normalized();
    const Vector3d at = scene.centroid[nearest];
    const double rb = 0.002;
    auto between = [&](double t) {
      const double d = 0.003 * std::clamp(t / 0.3, 0.0, 1.0);
      palpate::GesturePose pose;
      pose.hinge_m = at + (rb - d) * n;
      pose.orientation = palpate::rotation_taking(Vector3d::UnitZ(), -n);
      return pose;
    };
    const TickLog b = play(scene, between, 2.3, capsule(rb, 0, 0), false);
    int zero = 0;
    for (std::size_t i = 300; i < b.force_n.size(); ++i) zero += b.force_n[i] == 0 ? 1 : 0;
    std::printf(
        "between vertices (2 mm sphere, 3 mm at a triangle's centroid, held 2 s): %d of "
        "%zu ticks without force; force at the end %.4f N\n",
        zero, b.force_n.size() - 300, b.force_n.back());
    std::snprintf(buffer, sizeof buffer,
                  "  \"between\": {\"zero_force_ticks\": %d, \"held_ticks\": %zu, "
                  "\"final_force_n\": %.6g},\n",
                  zero, b.force_n.size() - 300, b.force_n.back());
    json += buffer;
  }

  // ---- force-depth curve of a 5 mm sphere along one normal
  Vector3d point, normal;
  if (curve_point.size() == 6) {
    // The given point, moved onto this mesh's rest surface (meshes of the
    // same organ differ by their faceting), pressed along the given normal.
    Vector3d ignored;
    point = on_surface(Vector3d(curve_point[0], curve_point[1], curve_point[2]), ignored);
    normal = Vector3d(curve_point[3], curve_point[4], curve_point[5]).normalized();
  } else {
    const palpate::AnchorFrame a = palpate::auto_anchor(model.surface);
    point = a.origin_m;
    normal = a.normal;
  }
  {
    const double rs = 0.005;
    palpate::ContactSettings settings;
    ToolContactEngine engine(model, {capsule(rs, 0, 0)}, settings, {});
    const Eigen::Quaterniond q = palpate::rotation_taking(Vector3d::UnitZ(), -normal);
    std::printf(
        "curve (5 mm frictionless sphere along -n at (%.5f, %.5f, %.5f) m, "
        "n = (%.5f, %.5f, %.5f)):\n",
        point.x(), point.y(), point.z(), normal.x(), normal.y(), normal.z());
    json += "  \"curve\": {\"point_m\": [" + std::to_string(point.x()) + ", " +
            std::to_string(point.y()) + ", " + std::to_string(point.z()) + "], \"depth_mm\": [";
    std::string forces = "], \"force_n\": [";
    std::uint64_t sequence = 0;
    double t = 0;
    for (int mm = 0; mm <= 5; ++mm) {
      // 1 mm in 200 ticks, then 300 ticks held; the force is the mean of
      // the last 100 (with their spread: the contact set may alternate).
      double sum_f = 0, lo = INFINITY, hi = -INFINITY;
      for (int i = 1; i <= 500; ++i) {
        const double depth_m = 1e-3 * (mm - 1 + std::min(1.0, i / 200.0));
        palpate::ToolPoseInput pose;
        pose.sequence = ++sequence;
        pose.position_m = point + normal * (rs - std::max(depth_m, -0.002));
        pose.orientation = q;
        engine.update(0, pose, t);
        t += 1e-3;
        if (i > 400) {
          const double f = engine.output(0).force_n.dot(normal);
          sum_f += f;
          lo = std::min(lo, f);
          hi = std::max(hi, f);
        }
      }
      if (mm == 0) continue;
      std::printf(
          "  depth %d mm: force along the press %.5f N (last 100 ticks %.5f to %.5f), "
          "contacts %d\n",
          mm, sum_f / 100, lo, hi, engine.output(0).contacts);
      // Appended piece by piece: GCC 12 warns (-Wrestrict, a false
      // positive) on const char* + std::string here.
      if (mm > 1) {
        json += ", ";
        forces += ", ";
      }
      json += std::to_string(mm);
      forces += std::to_string(sum_f / 100);
    }
    json += forces + "]},\n";
  }

  // ---- a retractor: a capsule r = 10 mm, 60 mm long, laid along the
  // surface (its axis along the anchor's x tangent), pressed 6 mm and moved
  // 10 mm sideways: many contacts on one tool (up to 64).
  const double rr = 0.010, rl = 0.060;
  auto retractor = [&](double t) {
    const double d = 0.006 * std::clamp(t / 0.5, 0.0, 1.0);
    const double side = 0.010 * std::clamp((t - 0.5) / 0.5, 0.0, 1.0);
    palpate::GesturePose pose;
    pose.hinge_m =
        anchor.origin_m + (rr - d) * anchor.normal - 0.5 * rl * anchor.x + side * anchor.y;
    pose.orientation = palpate::rotation_taking(Vector3d::UnitZ(), anchor.x);
    return pose;
  };
  const TickLog w = play(scene, retractor, 1.2, capsule(rr, rl, 0), false, 64);
  int most = 0;
  double sum = 0;
  for (int c : w.contacts) most = std::max(most, c), sum += c;
  std::printf(
      "retractor (capsule r 10 mm, 60 mm, laid on the surface, 6 mm, up to 64 contacts): "
      "mean contacts %.1f, most %d;"
      " tick p50 %.1f µs, p99 %.1f µs, max %.1f µs\n",
      sum / static_cast<double>(w.contacts.size()), most, percentile(w.tick_us, 0.5),
      percentile(w.tick_us, 0.99), percentile(w.tick_us, 1.0));
  std::snprintf(
      buffer, sizeof buffer,
      "  \"retractor\": {\"mean_contacts\": %.4g, \"most_contacts\": %d, \"tick_p50_us\": %.4g, "
      "\"tick_p99_us\": %.4g}\n}\n",
      sum / static_cast<double>(w.contacts.size()), most, percentile(w.tick_us, 0.5),
      percentile(w.tick_us, 0.99));
  json += buffer;

#ifdef PALPATE_HAS_SURFACE_POINTS
  // ---- the solve of a contact set that changed: k points on the k surface
  // triangles nearest the anchor (at their centroids, normal-only rows, the
  // rest surface pushed 1 mm in), each solve with new weights so that no
  // factorization is reused: P = H G Hᵀ assembled, Bᵀ P B factored, solved.
  {
    std::vector<std::pair<double, int>> by_distance;
    for (std::size_t t = 0; t < scene.centroid.size(); ++t) {
      const auto* tri = &model.surface.triangles[3 * t];
      bool free = true;
      for (int c = 0; c < 3; ++c) free &= static_cast<int>(tri[c]) < scene.compliance;
      if (free)
        by_distance.push_back({(scene.centroid[t] - anchor.origin_m).norm(), static_cast<int>(t)});
    }
    std::sort(by_distance.begin(), by_distance.end());
    json.back() = ' ';
    json.pop_back();
    json.pop_back();
    json += ",\n  \"solve\": [";
    for (const int k : {8, 16, 32, 64}) {
      palpate::SolverLimits limits;
      limits.max_constraints = 64;
      limits.cache_slots = 1;
      palpate::ConstraintSolver solver(model, limits);
      std::vector<double> us;
      for (int round = 0; round < 2000; ++round) {
        const double jitter = 1e-3 * (round % 97);
        const auto start = std::chrono::steady_clock::now();
        solver.begin(static_cast<std::size_t>(k));
        for (int c = 0; c < k; ++c) {
          const auto* tri =
              &model.surface.triangles[3 * static_cast<std::size_t>(by_distance[c].second)];
          const int index[3] = {static_cast<int>(tri[0]), static_cast<int>(tri[1]),
                                static_cast<int>(tri[2])};
          const double weights[3] = {1.0 / 3 + jitter, 1.0 / 3 - jitter, 1.0 / 3};
          const Vector3d n = -Vector3d(normals.row(tri[0])).normalized();
          const double value[3] = {1e-3, 0, 0};
          solver.add_surface_point(index, weights, 3, palpate::ConstraintKind::kNormalDisplacement,
                                   value, n.data());
        }
        const auto status = solver.solve();
        const auto stop = std::chrono::steady_clock::now();
        if (status != palpate::RequestStatus::kOk) {
          std::fprintf(stderr, "contact_feel: solve of %d points: %s\n", k, solver.message());
          break;
        }
        us.push_back(std::chrono::duration<double, std::micro>(stop - start).count());
      }
      std::printf("solve of %d new points (assembly, factor, solve): p50 %.1f µs, p99 %.1f µs\n", k,
                  percentile(us, 0.5), percentile(us, 0.99));
      json += (k > 8 ? ", " : "") + std::string("{\"points\": ") + std::to_string(k) +
              ", \"p50_us\": " + std::to_string(percentile(us, 0.5)) +
              ", \"p99_us\": " + std::to_string(percentile(us, 0.99)) + "}";
    }
    json += "]\n}\n";
  }
#endif
  if (!json_path.empty()) std::ofstream(json_path) << json;
  return 0;
}
