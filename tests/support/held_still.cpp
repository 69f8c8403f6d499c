#include "support/held_still.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "palpate/runtime/drawn_surface.hpp"

namespace palpate::testing {

namespace {

using Eigen::Vector3d;

constexpr double kTick = 0.001;  // s
constexpr int kSettle = 50, kHold = 300;
constexpr int kSlide = 1000;  // ticks: 1 mm at 1 mm/s

double p99(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(0.99 * static_cast<double>(v.size() - 1))];
}

Hold measure(const std::vector<ToolOutput>& log, std::size_t from) {
  Hold h;
  h.least_count = 1 << 20;
  h.most_count = -1;
  std::vector<double> steps, seconds;
  for (std::size_t i = from; i < log.size(); ++i) {
    h.mean_force_n += log[i].force_n.norm() / static_cast<double>(log.size() - from);
    h.least_count = std::min(h.least_count, log[i].contacts);
    h.most_count = std::max(h.most_count, log[i].contacts);
    if (i > from) steps.push_back((log[i].force_n - log[i - 1].force_n).norm());
    if (i > from + 1)
      seconds.push_back((log[i].force_n - 2 * log[i - 1].force_n + log[i - 2].force_n).norm());
  }
  h.step_p99_n = p99(steps);
  h.second_p99_n = p99(seconds);
  return h;
}

}  // namespace

std::vector<int> flattest_spots(const SurfaceModel& organ, int count) {
  const DrawnSurface& s = organ.surface;
  const Eigen::MatrixX3d normals = vertex_normals(s);
  const int n = organ.compliance_vertex_count();
  std::vector<std::pair<double, int>> flat;
  for (int v = 0; v < n; ++v) {
    const Vector3d x = s.rest_position(v), nv = normals.row(v);
    double spread = 0;
    bool near_fixed = false;
    for (int w = 0; w < s.vertex_count(); ++w) {
      if ((s.rest_position(w) - x).norm() > 0.02) continue;
      near_fixed |= w >= n;
      spread = std::max(spread, 1 - nv.dot(normals.row(w).transpose()));
    }
    if (!near_fixed) flat.emplace_back(spread, v);
  }
  std::sort(flat.begin(), flat.end());
  std::vector<int> spots;
  for (const auto& [spread, v] : flat) {
    bool apart = true;
    for (const int w : spots) apart &= (s.rest_position(w) - s.rest_position(v)).norm() > 0.03;
    if (apart) spots.push_back(v);
    if (static_cast<int>(spots.size()) == count) break;
  }
  return spots;
}

ToolGeometry held_tip(bool capsule, double radius_m, double friction) {
  ToolGeometry g;
  g.id = capsule ? "capsule" : "sphere";
  g.tip_radius_m = radius_m;
  g.friction = friction;
  g.jaw_length_m = 0;
  if (!capsule) {
    g.tip = TipShape::kSphere;
    g.tip_length_m = 0;
  }
  g.force_limit_n = 3;
  g.max_force_rate_n_per_s = 100;
  return g;
}

std::vector<Hold> hold_at_every_depth(const SurfaceModel& organ, const ToolGeometry& g, int spot,
                                      const HoldTrace& trace, bool slide) {
  const Vector3d normal = vertex_normals(organ.surface).row(spot);
  const Vector3d at = organ.surface.rest_position(spot) + 0.0013 * normal.unitOrthogonal();
  const double reach =
      g.tip == TipShape::kCapsule ? g.tip_length_m + g.tip_radius_m : g.tip_radius_m;
  ToolContactEngine engine(organ, {g}, {}, {});
  ToolPoseInput pose;
  pose.position_m = at + (reach + 0.001) * normal;
  pose.orientation = Eigen::Quaterniond::FromTwoVectors(Vector3d::UnitZ(), -normal);
  double now = 0;
  std::vector<ToolOutput> log;
  int target_mm = 1;
  const auto tick = [&] {
    ++pose.sequence;
    ToolPoseInput checked = pose;
    if (engine.check(0, checked) != PoseProblem::kNone)
      throw std::runtime_error(std::string("pose refused: ") + engine.problem_message());
    if (engine.update(0, checked, now) != RequestStatus::kOk)
      throw std::runtime_error(std::string("solve failed: ") + engine.solver_message());
    log.push_back(engine.output(0));
    now += kTick;
    if (trace) trace(engine, target_mm);
  };
  std::vector<Hold> holds;
  double depth_mm = 0;
  for (; target_mm <= 20; ++target_mm) {
    while (depth_mm < target_mm - 1e-9) {
      depth_mm += 0.02;
      pose.position_m -= 2e-5 * normal;
      tick();
    }
    for (int i = 0; i < kSettle + kHold; ++i) tick();
    Hold h = measure(log, log.size() - kHold);
    h.spot = spot;
    h.depth_mm = target_mm;
    if (slide)
      for (int i = 0; i < kSlide; ++i) {
        pose.position_m += 1e-6 * normal.unitOrthogonal();  // 1 mm/s at 1 kHz
        tick();
        const ToolOutput& now_out = log.back();
        const ToolOutput& before = log[log.size() - 2];
        const double bound = 0.01 * now_out.force_n.norm() + 1e-3;
        const double ratio = (now_out.force_n - before.force_n).norm() / bound;
        h.slide_ratio = std::max(h.slide_ratio, ratio);
        if (ratio > 1) ++h.slide_over;
      }
    holds.push_back(h);
    if (log.back().force_limited) break;  // deeper holds the limit
  }
  return holds;
}

}  // namespace palpate::testing
