// A tool held still, measured (issue 34's protocol; BENCHMARKS.md, "Held
// still"): on the flattest spots of an organ (the normals within 20 mm of a
// compliance vertex all within a few degrees of its own, none of them
// fixed, the spots 30 mm apart), each tip pressed along the spot's normal
// at 20 mm/s, 1 mm at a time, and held 350 ticks at each depth until the
// device's force limit, through the device limits of that issue (3 N,
// 100 N/s). A hold is *still* when, after 50 ticks of settling, the force
// fed back changes by at most 1 mN a tick at p99 and its contact count
// stays the same; |Δ²F| = |F_t − 2F_{t−1} + F_{t−2}| shows a tick-to-tick
// alternation.
//
//   palpate_held_still COMPLIANCE.h5 [--spots N] [--all]
//
// Prints every hold that is not still (--all: every hold), then per tip and
// friction the holds, how many are not still, and their worst p99 |ΔF| and
// |Δ²F|. Counts, not times: what the engine feeds back, from its public
// interface only. Tips: spheres of radius 1, 3, 6 and 12.5 mm (6 mm is the
// issue's 12 mm sphere) and the default capsule (4 mm); friction 0 and 0.3.

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

#include "palpate/runtime/drawn_surface.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace {

using Eigen::Vector3d;
using palpate::ToolGeometry;
using palpate::ToolOutput;

constexpr double kTick = 0.001;  // s
constexpr int kSettle = 50, kHold = 300;

struct Hold {
  double mean_force = 0, step_p99 = 0, second_p99 = 0;
  int least_count = 1 << 20, most_count = -1;
  bool still() const { return step_p99 <= 1e-3 && least_count == most_count; }
};

double p99(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(0.99 * static_cast<double>(v.size() - 1))];
}

Hold measure(const std::vector<ToolOutput>& log, std::size_t from) {
  Hold h;
  std::vector<double> steps, seconds;
  for (std::size_t i = from; i < log.size(); ++i) {
    h.mean_force += log[i].force_n.norm() / static_cast<double>(log.size() - from);
    h.least_count = std::min(h.least_count, log[i].contacts);
    h.most_count = std::max(h.most_count, log[i].contacts);
    if (i > from) steps.push_back((log[i].force_n - log[i - 1].force_n).norm());
    if (i > from + 1)
      seconds.push_back((log[i].force_n - 2 * log[i - 1].force_n + log[i - 2].force_n).norm());
  }
  h.step_p99 = p99(steps);
  h.second_p99 = p99(seconds);
  return h;
}

struct Tip {
  const char* kind;
  double radius_m;
};

ToolGeometry tool_of(const Tip& tip, double friction) {
  ToolGeometry g;
  g.id = tip.kind;
  g.tip_radius_m = tip.radius_m;
  g.friction = friction;
  g.jaw_length_m = 0;
  if (std::string(tip.kind) == "sphere") {
    g.tip = palpate::TipShape::kSphere;
    g.tip_length_m = 0;
  }
  g.force_limit_n = 3;
  g.max_force_rate_n_per_s = 100;
  return g;
}

[[noreturn]] void die(const std::string& message) {
  std::fprintf(stderr, "palpate_held_still: %s\n", message.c_str());
  std::exit(2);
}

}  // namespace

int main(int argc, char** argv) {
  std::string file;
  std::size_t spot_count = 6;
  bool all = false;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--spots" && a + 1 < argc)
      spot_count = static_cast<std::size_t>(std::max(1, std::atoi(argv[++a])));
    else if (arg == "--all")
      all = true;
    else if (arg[0] == '-')
      die("unknown option " + arg + "; accepted: --spots N, --all");
    else
      file = arg;
  }
  if (file.empty()) die("usage: palpate_held_still COMPLIANCE.h5 [--spots N] [--all]");
  const palpate::SurfaceModel organ = palpate::load_surface_model("organ", file);
  const palpate::DrawnSurface& s = organ.surface;
  const Eigen::MatrixX3d normals = palpate::vertex_normals(s);
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
    if (spots.size() == spot_count) break;
  }

  const Tip tips[] = {{"sphere", 0.001},
                      {"sphere", 0.003},
                      {"sphere", 0.006},
                      {"sphere", 0.0125},
                      {"capsule", 0.004}};
  std::printf("%s: %zu spots\n", file.c_str(), spots.size());
  std::printf("%-8s %5s %4s %6s %5s %8s %10s %10s %6s\n", "tip", "r_mm", "mu", "spot", "depth",
              "F_N", "dF_p99_N", "d2F_p99_N", "count");
  struct Sum {
    int holds = 0, unsteady = 0;
    double worst_step = 0, worst_second = 0;
  };
  std::vector<Sum> sums;
  for (const Tip& tip : tips)
    for (const double friction : {0.0, 0.3}) {
      Sum sum;
      for (const int spot_vertex : spots) {
        const Vector3d normal = normals.row(spot_vertex);
        const Vector3d spot = s.rest_position(spot_vertex) + 0.0013 * normal.unitOrthogonal();
        const ToolGeometry g = tool_of(tip, friction);
        const double reach =
            g.tip == palpate::TipShape::kCapsule ? g.tip_length_m + tip.radius_m : tip.radius_m;
        palpate::ToolContactEngine engine(organ, {g}, {}, {});
        palpate::ToolPoseInput pose;
        pose.position_m = spot + (reach + 0.001) * normal;
        pose.orientation = Eigen::Quaterniond::FromTwoVectors(Vector3d::UnitZ(), -normal);
        double now = 0;
        std::vector<ToolOutput> log;
        const auto tick = [&] {
          ++pose.sequence;
          palpate::ToolPoseInput checked = pose;
          if (engine.check(0, checked) != palpate::PoseProblem::kNone)
            die(std::string("pose refused: ") + engine.problem_message());
          if (engine.update(0, checked, now) != palpate::RequestStatus::kOk)
            die(std::string("solve failed: ") + engine.solver_message());
          log.push_back(engine.output(0));
          now += kTick;
        };
        double depth_mm = 0;
        for (int target_mm = 1; target_mm <= 20; ++target_mm) {
          while (depth_mm < target_mm - 1e-9) {
            depth_mm += 0.02;
            pose.position_m -= 2e-5 * normal;
            tick();
          }
          for (int i = 0; i < kSettle + kHold; ++i) tick();
          const Hold h = measure(log, log.size() - kHold);
          ++sum.holds;
          if (!h.still()) ++sum.unsteady;
          sum.worst_step = std::max(sum.worst_step, h.step_p99);
          sum.worst_second = std::max(sum.worst_second, h.second_p99);
          if (all || !h.still())
            std::printf("%-8s %5.1f %4.1f %6d %5d %8.4f %10.6f %10.6f %3d-%d\n", tip.kind,
                        tip.radius_m * 1e3, friction, spot_vertex, target_mm, h.mean_force,
                        h.step_p99, h.second_p99, h.least_count, h.most_count);
          if (log.back().force_limited) break;  // deeper holds the limit
        }
      }
      sums.push_back(sum);
    }
  std::printf("\n%-8s %5s %4s %6s %10s %12s %12s\n", "tip", "r_mm", "mu", "holds", "not_still",
              "worst_dF_N", "worst_d2F_N");
  std::size_t k = 0;
  int holds = 0, unsteady = 0;
  for (const Tip& tip : tips)
    for (const double friction : {0.0, 0.3}) {
      const Sum& sum = sums[k++];
      holds += sum.holds;
      unsteady += sum.unsteady;
      std::printf("%-8s %5.1f %4.1f %6d %10d %12.6f %12.6f\n", tip.kind, tip.radius_m * 1e3,
                  friction, sum.holds, sum.unsteady, sum.worst_step, sum.worst_second);
    }
  std::printf("all: %d of %d holds not still\n", unsteady, holds);
  return 0;
}
