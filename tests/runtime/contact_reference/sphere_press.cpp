// palpate's side of the independent contact check (docs/model/contact-reference.md, "An
// independent check of the contact"; tests/runtime/contact_reference/): a
// frictionless rigid sphere pressed into the organ through
// ToolContactEngine's public interface, printed as JSON for
// sphere_press_test.py to compare with the finite-element contact solution
// of reference_contact.py.
//
// The sphere's centre starts at POINT + r·n (touching the rest surface at
// POINT, n its outward normal) and moves along −n: to each depth d (the
// centre at POINT + (r − d)·n) in ramp ticks of 1 ms, then held for hold
// ticks. The engine deforms the surface with the previous tick's loads
// (docs/tools.md, "One tick"), so a held press is a fixed-point iteration
// over ticks; the force reported is the mean over the last quarter of the
// held ticks, with its lowest and highest value (a contact set that
// alternates shows as a spread). Friction 0, no jaws, force and slew limits
// out of reach: the engine's own force, before the device.
//
// Usage: palpate_sphere_press MODEL.h5 --point X,Y,Z --normal NX,NY,NZ
//            --radius-mm R --depths-mm D1,D2,... [--ramp-ticks 200] [--hold-ticks 300]
//            [--max-iterations N (the [contact] setting, default 8)]
// Prints one JSON object on stdout; exits 2 on bad arguments or an unreadable
// model, 1 when a pose is refused or a solve fails.

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "palpate/core/rotation.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "support/number_list.hpp"

namespace {

using Eigen::Vector3d;

[[noreturn]] void usage(const std::string& why) {
  std::fprintf(stderr,
               "sphere_press: %s\nusage: palpate_sphere_press MODEL.h5 --point X,Y,Z "
               "--normal NX,NY,NZ --radius-mm R --depths-mm D1,D2,... [--ramp-ticks N] "
               "[--hold-ticks N] [--max-iterations N]\n",
               why.c_str());
  std::exit(2);
}

std::vector<double> numbers(const std::string& option, const std::string& text) {
  auto list = palpate::testing::number_list(text);
  if (!list) usage(option + " '" + text + "': expected numbers separated by commas");
  return *list;
}

std::string vec(const Vector3d& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "[%.12g, %.12g, %.12g]", v.x(), v.y(), v.z());
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  std::string model_path;
  std::vector<double> point, normal, depths_mm;
  double radius_mm = 0;
  int ramp_ticks = 200, hold_ticks = 300;
  palpate::ContactSettings settings;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    auto next = [&]() -> std::string {
      if (a + 1 >= argc) usage(arg + " needs a value");
      return argv[++a];
    };
    if (arg == "--point")
      point = numbers(arg, next());
    else if (arg == "--normal")
      normal = numbers(arg, next());
    else if (arg == "--radius-mm")
      radius_mm = numbers(arg, next()).at(0);
    else if (arg == "--depths-mm")
      depths_mm = numbers(arg, next());
    else if (arg == "--ramp-ticks")
      ramp_ticks = static_cast<int>(numbers(arg, next()).at(0));
    else if (arg == "--hold-ticks")
      hold_ticks = static_cast<int>(numbers(arg, next()).at(0));
    else if (arg == "--max-iterations")
      settings.max_iterations = static_cast<int>(numbers(arg, next()).at(0));
    else if (!arg.empty() && arg[0] != '-' && model_path.empty())
      model_path = arg;
    else
      usage("unknown argument " + arg);
  }
  if (model_path.empty()) usage("no MODEL.h5 given");
  if (point.size() != 3 || normal.size() != 3) usage("--point and --normal take 3 numbers each");
  if (!(radius_mm > 0)) usage("--radius-mm must be positive");
  if (depths_mm.empty()) usage("--depths-mm is required");
  if (ramp_ticks < 1 || hold_ticks < 4) usage("--ramp-ticks ≥ 1 and --hold-ticks ≥ 4");

  palpate::SurfaceModel model;
  try {
    model = palpate::load_surface_model("organ", model_path);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphere_press: %s\n", e.what());
    return 2;
  }
  const Vector3d p(point[0], point[1], point[2]);
  const Vector3d n = Vector3d(normal[0], normal[1], normal[2]).normalized();
  const double r = radius_mm * 1e-3;

  palpate::ToolGeometry sphere;
  sphere.id = "sphere";
  sphere.tip = palpate::TipShape::kSphere;
  sphere.tip_radius_m = r;
  sphere.tip_length_m = 0;
  sphere.friction = 0;
  sphere.jaw_length_m = 0;
  sphere.force_limit_n = 1e6;
  sphere.max_force_rate_n_per_s = 1e12;
  palpate::SolverLimits limits;
  palpate::ToolContactEngine engine(model, {sphere}, settings, limits);
  // A sphere has no orientation of its own; the tool's +z along the press.
  const Eigen::Quaterniond q = palpate::rotation_taking(Vector3d::UnitZ(), -n);

  std::string json = "{\n  \"model\": \"" + model_path +
                     "\",\n  \"radius_m\": " + std::to_string(r) + ",\n  \"point_m\": " + vec(p) +
                     ",\n  \"normal\": " + vec(n) + ",\n  \"presses\": [";
  std::uint64_t sequence = 0;
  double t = 0, previous_depth = 0;
  for (std::size_t k = 0; k < depths_mm.size(); ++k) {
    const double depth = depths_mm[k] * 1e-3;
    const Vector3d centre = p + (r - depth) * n;
    const int averaged = std::max(1, hold_ticks / 4);
    double sum = 0, lo = INFINITY, hi = -INFINITY;
    std::string held;
    Vector3d sum_vector = Vector3d::Zero();
    for (int i = 1; i <= ramp_ticks + hold_ticks; ++i) {
      const double d =
          previous_depth + (depth - previous_depth) * std::min(1.0, double(i) / ramp_ticks);
      palpate::ToolPoseInput pose;
      pose.sequence = ++sequence;
      pose.position_m = p + (r - d) * n;
      pose.orientation = q;
      if (engine.check(0, pose) != palpate::PoseProblem::kNone) {
        std::fprintf(stderr, "sphere_press: pose refused: %s\n", engine.problem_message());
        return 1;
      }
      if (engine.update(0, pose, t) != palpate::RequestStatus::kOk) {
        std::fprintf(stderr, "sphere_press: solve failed at depth %.3f mm: %s\n", d * 1e3,
                     engine.solver_message());
        return 1;
      }
      t += 1e-3;
      if (i > ramp_ticks + hold_ticks - averaged) {
        // The force on the organ is minus the force on the tool.
        const Vector3d f = -engine.output(0).force_n;
        const double along = -f.dot(n);
        sum += along;
        sum_vector += f;
        held += std::string(held.empty() ? "" : ", ") + std::to_string(along);
        lo = std::min(lo, along);
        hi = std::max(hi, along);
      }
    }
    previous_depth = depth;
    json += std::string(k ? "," : "") + "\n    {\"depth_m\": " + std::to_string(depth) +
            ", \"centre_m\": " + vec(centre) + ", \"force_n\": " + std::to_string(sum / averaged) +
            ", \"force_min_n\": " + std::to_string(lo) +
            ", \"force_max_n\": " + std::to_string(hi) +
            ", \"force_vector_n\": " + vec(sum_vector / averaged) + ",\n     \"held_forces_n\": [" +
            held + "],\n     \"contact_points\": [";
    // The last tick's contacts and loads, for the test's own checks.
    bool first = true;
    for (const palpate::ContactPoint& c : engine.contact_points()) {
      json += std::string(first ? "" : ", ") + "{\"position_m\": " + vec(c.position_m) +
              ", \"force_n\": " + vec(c.force_n) + "}";
      first = false;
    }
    json += "],\n     \"loads\": [";
    const auto idx = engine.contact_indices();
    const auto f = engine.contact_forces();
    for (std::size_t l = 0; l < idx.size(); ++l)
      json += std::string(l ? ", " : "") + "{\"compliance_index\": " + std::to_string(idx[l]) +
              ", \"force_n\": " + vec(Vector3d(f[3 * l], f[3 * l + 1], f[3 * l + 2])) + "}";
    json += "]}";
  }
  json += "\n  ]\n}\n";
  std::fputs(json.c_str(), stdout);
  return 0;
}
