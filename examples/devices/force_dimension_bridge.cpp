// A Force Dimension device (delta.x, omega.x, sigma.x, lambda.x; the DHD
// API of the Force Dimension SDK) as one of palpated's tools, through
// palpate's C API (docs/devices.md, "Force Dimension"). Built only where
// CMake finds dhdc.h and libdhd (examples/CMakeLists.txt). C++ because
// dhdc.h declares default arguments.
//
// The loop runs as fast as the device's USB link allows (4-8 kHz): it reads
// the handle, gives it to palpate_device_set_pose() (poses go to palpated at
// 1 kHz) and sends palpate_device_force() to the motors. The conversions:
//   - dhdGetPosition: m, in the device's frame (x towards the user, y to
//     the right, z up), taken as the model's frame: the identity;
//   - dhdGetOrientationFrame: the handle's axes as a row-major 3 x 3 matrix;
//     its axis along the wrist's handle is taken as the tool's shaft (+z): a
//     quarter turn that your device may not need (docs/devices.md);
//   - the gripper: dhdGetGripperAngleRad (about 0 to 0.52 rad on an omega.7;
//     negative on a left-hand device) times 2.5 is the jaw opening;
//   - dhdSetForceAndTorqueAndGripperForce: N, N·m, N, as palpate gives them.
//
//     force_dimension_bridge MODEL TOOL [SECONDS] [SCALE]

#include <dhdc.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "device_frames.h"
#include "palpate/device.h"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: force_dimension_bridge MODEL TOOL [SECONDS] [SCALE]\n");
    return 2;
  }
  const double seconds = argc > 3 ? std::atof(argv[3]) : 60;
  palpate_device_options options;
  palpate_device_options_init(&options);
  options.model_id = argv[1];
  options.tool_id = argv[2];
  options.frame.scale = argc > 4 ? std::atof(argv[4]) : 1;
  // The tool's +z along the handle's x axis (pointing away from the user's
  // palm on an omega.7 at rest): a quarter turn about y.
  const double handle_to_tool[4] = {std::sqrt(0.5), 0, std::sqrt(0.5), 0};
  for (int i = 0; i < 4; ++i) options.frame.handle_to_tool_wxyz[i] = handle_to_tool[i];
  char error[512];
  palpate_device* tool = nullptr;
  if (palpate_device_open(&options, &tool, error, sizeof error) != PALPATE_DEVICE_OK) {
    std::fprintf(stderr, "force_dimension_bridge: %s\n", error);
    return 3;
  }
  const int id = dhdOpen();
  if (id < 0) {
    std::fprintf(stderr, "force_dimension_bridge: no Force Dimension device: %s\n",
                 dhdErrorGetLastStr());
    palpate_device_close(tool);
    return 3;
  }
  const char device = static_cast<char>(id);
  dhdEnableForce(DHD_ON, device);
  const bool wrist = dhdHasWrist(device), gripper = dhdHasGripper(device);
  const std::int64_t end = palpate_device_now_ns() + static_cast<std::int64_t>(seconds * 1e9);
  int status = PALPATE_DEVICE_OK;
  std::int64_t next_print = 0;
  while (status == PALPATE_DEVICE_OK && palpate_device_now_ns() < end) {
    double p[3] = {0, 0, 0}, r[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, angle = 0;
    dhdGetPosition(&p[0], &p[1], &p[2], device);
    if (wrist) dhdGetOrientationFrame(r, device);
    if (gripper) dhdGetGripperAngleRad(&angle, device);
    double q[4];
    palpate_quaternion_of_rows(r, q);
    double force[3] = {0, 0, 0}, torque[3] = {0, 0, 0};
    status = palpate_device_set_pose(tool, 0, p, q, 2.5 * std::fabs(angle), nullptr, error,
                                     sizeof error);
    if (status == PALPATE_DEVICE_OK)
      status = palpate_device_force(tool, 0, force, torque, error, sizeof error);
    if (status != PALPATE_DEVICE_OK) force[0] = force[1] = force[2] = 0;
    dhdSetForceAndTorqueAndGripperForce(force[0], force[1], force[2], torque[0], torque[1],
                                        torque[2], 0.0, device);
    // Events and a line a second, in this thread: a handle has one.
    palpate_device_event event;
    event.struct_size = sizeof event;
    while (palpate_device_next_event(tool, &event, nullptr, 0) == PALPATE_DEVICE_OK)
      std::printf("  %s\n", event.message);
    if (const std::int64_t now = palpate_device_now_ns(); now >= next_print) {
      palpate_device_state state;
      state.struct_size = sizeof state;
      palpate_device_get_state(tool, &state, nullptr, 0);
      std::printf("state %d, contacts %u, rendered (%.2f, %.2f, %.2f) N, round trip %.0f us\n",
                  state.tool_state, state.contacts, state.rendered_force_n[0],
                  state.rendered_force_n[1], state.rendered_force_n[2], state.round_trip_s * 1e6);
      std::fflush(stdout);
      next_print = now + 1000000000;
    }
  }
  dhdSetForceAndTorqueAndGripperForce(0, 0, 0, 0, 0, 0, 0, device);
  dhdClose(device);
  if (status != PALPATE_DEVICE_OK) std::fprintf(stderr, "force_dimension_bridge: %s\n", error);
  palpate_device_close(tool);  // ends the session: palpated lets go at once
  return status == PALPATE_DEVICE_OK ? 0 : 5;
}
