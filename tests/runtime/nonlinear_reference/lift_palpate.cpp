// palpate's side of the large-rotation check (docs/model/warped.md, "Large
// rotations: warped compliance"; tests/runtime/nonlinear_reference/): a patch
// of surface vertices grasped and lifted along a rotation, answered by the
// request path (imposed displacements) in the linear and the warped model,
// for lift_test.py to compare with the nonlinear finite-element reference.
//
// The grasped vertices are the compliance vertices in the boxes and balls
// (--box X0,Y0,Z0,X1,Y1,Z1 and --sphere CX,CY,CZ,R, repeatable: their
// union); each goes to
// a + R(θ) (p − a), R(θ) the rotation by θ about the axis through a along e
// (right-handed). The summed force the grasp exerts is printed per angle.
//
// Usage: palpate_lift MODEL.h5 --box X0,Y0,Z0,X1,Y1,Z1 --axis-point AX,AY,AZ
//            --axis-direction EX,EY,EZ --angles 5,15,... [--radius-m R]
// Prints CSV on stdout: theta_deg, mode, fx, fy, fz, iterations, status; exits 2
// on bad arguments or an unreadable model.

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <string>
#include <vector>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/warped_solver.hpp"
#include "support/number_list.hpp"

namespace {

[[noreturn]] void usage(const std::string& why) {
  std::fprintf(stderr,
               "palpate_lift: %s\nusage: palpate_lift MODEL.h5 --box X0,Y0,Z0,X1,Y1,Z1 "
               "--axis-point AX,AY,AZ --axis-direction EX,EY,EZ --angles A1,A2,... "
               "[--radius-m R]\n",
               why.c_str());
  std::exit(2);
}

std::vector<double> numbers(const std::string& option, const std::string& text,
                            std::size_t count = 0) {
  const auto list = palpate::testing::number_list(text);
  if (!list) usage(option + " '" + text + "': expected numbers separated by commas");
  if (count != 0 && list->size() != count)
    usage(option + " '" + text + "': expected " + std::to_string(count) + " numbers");
  return *list;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) usage("no model file");
  std::vector<std::vector<double>> boxes, spheres;
  std::vector<double> point, direction, angles;
  double radius = 0;
  for (int i = 2; i < argc; i += 2) {
    const std::string option = argv[i];
    if (i + 1 >= argc) usage(option + " needs a value");
    const std::string value = argv[i + 1];
    if (option == "--box")
      boxes.push_back(numbers(option, value, 6));
    else if (option == "--sphere")
      spheres.push_back(numbers(option, value, 4));
    else if (option == "--axis-point")
      point = numbers(option, value, 3);
    else if (option == "--axis-direction")
      direction = numbers(option, value, 3);
    else if (option == "--angles")
      angles = numbers(option, value);
    else if (option == "--radius-m")
      radius = numbers(option, value, 1)[0];
    else
      usage("unknown option " + option);
  }
  if ((boxes.empty() && spheres.empty()) || point.empty() || direction.empty() || angles.empty())
    usage("--box or --sphere, --axis-point, --axis-direction and --angles are required");
  palpate::SurfaceModel model;
  try {
    model = palpate::load_surface_model("lift", argv[1]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate_lift: %s\n", e.what());
    return 2;
  }
  const auto& surface = model.surface;
  std::vector<int> grasped;
  for (int v = 0; v < surface.compliance_vertex_count; ++v) {
    const Eigen::Vector3d p = surface.rest_position(v);
    bool in_any = false;
    for (const auto& box : boxes) {
      bool inside = true;
      for (int d = 0; d < 3; ++d) inside = inside && p[d] >= box[d] && p[d] <= box[3 + d];
      in_any = in_any || inside;
    }
    for (const auto& ball : spheres)
      in_any = in_any || (p - Eigen::Vector3d(ball[0], ball[1], ball[2])).norm() <= ball[3];
    if (in_any) grasped.push_back(v);
  }
  if (grasped.empty()) usage("no compliance vertex in the box");
  if (radius <= 0) radius = palpate::default_smoothing_radius(surface);
  const palpate::RotationField field(surface, radius);
  palpate::SolverLimits limits;
  limits.max_constraints = static_cast<int>(grasped.size());
  palpate::ConstraintSolver linear(model, limits);
  palpate::WarpedSolver warped(model, limits, field);

  const Eigen::Vector3d a(point[0], point[1], point[2]);
  const Eigen::Vector3d e = Eigen::Vector3d(direction[0], direction[1], direction[2]).normalized();
  std::printf("# %zu grasped vertices, smoothing radius %.4g m (%.1f vertices per neighbourhood)\n",
              grasped.size(), radius, field.mean_neighbourhood());
  std::printf("theta_deg,mode,fx,fy,fz,iterations,status\n");
  for (const double theta : angles) {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(theta * M_PI / 180, e).toRotationMatrix();
    auto run = [&](auto& solver, const char* mode, auto iterations) {
      solver.begin(grasped.size());
      palpate::RequestStatus status = palpate::RequestStatus::kOk;
      for (const int v : grasped) {
        const Eigen::Vector3d p = surface.rest_position(v);
        const Eigen::Vector3d d = a + R * (p - a) - p;
        const double normal[3] = {0, 0, 0};
        status = solver.add(surface.vertex_ids[static_cast<std::size_t>(v)], 1, d.data(), normal);
        if (status != palpate::RequestStatus::kOk) break;
      }
      if (status == palpate::RequestStatus::kOk) status = solver.solve();
      const Eigen::Vector3d f =
          status == palpate::RequestStatus::kOk
              ? Eigen::Vector3d(solver.total_force())
              : Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
      std::printf("%.6g,%s,%.10g,%.10g,%.10g,%d,%s\n", theta, mode, f.x(), f.y(), f.z(),
                  iterations(solver), palpate::status_name(status));
    };
    run(linear, "linear", [](const palpate::ConstraintSolver&) { return 1; });
    run(warped, "warped", [](const palpate::WarpedSolver& s) { return s.iterations(); });
  }
  return 0;
}
