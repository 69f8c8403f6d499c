// A CHAI3D haptic device (cGenericHapticDevice: any device CHAI3D drives)
// as one of palpated's tools, through palpate's C API (docs/devices.md,
// "CHAI3D"). Built only where CMake finds chai3d.h and the chai3d library
// (examples/CMakeLists.txt).
//
// A cThread at CHAI3D's haptics priority runs the servo loop: the device's
// pose to palpate_device_set_pose() (poses go to palpated at 1 kHz),
// palpate_device_force() to the device. CHAI3D's conventions make the
// conversions trivial:
//   - getPosition: m; getRotation: a cMatrix3d, the handle's axes as its
//     columns; its device frame: x towards the user, y to the right, z up
//     (taken as the model's frame: the identity);
//   - getGripperAngleRad: rad, times 2.5 the jaw opening;
//   - setForceAndTorqueAndGripperForce: N, N·m, N, as palpate gives them.
//
//     chai3d_bridge MODEL TOOL [SECONDS] [SCALE]

#include <chai3d.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "device_frames.h"
#include "palpate/device.h"

namespace {

struct Bridge {
  chai3d::cGenericHapticDevicePtr device;
  palpate_device* tool = nullptr;
  std::atomic<bool> running{true}, finished{false};
  std::atomic<int> status{PALPATE_DEVICE_OK};
  char error[512] = {};
};

// The servo loop: the only thread that touches the handle while it runs.
void servo(void* data) {
  Bridge& b = *static_cast<Bridge*>(data);
  while (b.running) {
    chai3d::cVector3d p;
    chai3d::cMatrix3d r;
    double angle = 0;
    b.device->getPosition(p);
    b.device->getRotation(r);
    b.device->getGripperAngleRad(angle);
    const double position[3] = {p(0), p(1), p(2)};
    const double rows[3][3] = {
        {r(0, 0), r(0, 1), r(0, 2)}, {r(1, 0), r(1, 1), r(1, 2)}, {r(2, 0), r(2, 1), r(2, 2)}};
    double q[4];
    palpate_quaternion_of_rows(rows, q);
    double force[3] = {0, 0, 0}, torque[3] = {0, 0, 0};
    int status = palpate_device_set_pose(b.tool, 0, position, q, 2.5 * std::fabs(angle), nullptr,
                                         b.error, sizeof b.error);
    if (status == PALPATE_DEVICE_OK)
      status = palpate_device_force(b.tool, 0, force, torque, b.error, sizeof b.error);
    if (status != PALPATE_DEVICE_OK) {
      force[0] = force[1] = force[2] = torque[0] = torque[1] = torque[2] = 0;
      b.status = status;
      b.running = false;
    }
    b.device->setForceAndTorqueAndGripperForce(chai3d::cVector3d(force[0], force[1], force[2]),
                                               chai3d::cVector3d(torque[0], torque[1], torque[2]),
                                               0.0);
  }
  b.device->setForceAndTorqueAndGripperForce(chai3d::cVector3d(0, 0, 0), chai3d::cVector3d(0, 0, 0),
                                             0.0);
  b.finished = true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: chai3d_bridge MODEL TOOL [SECONDS] [SCALE]\n");
    return 2;
  }
  const double seconds = argc > 3 ? std::atof(argv[3]) : 60;
  palpate_device_options options;
  palpate_device_options_init(&options);
  options.model_id = argv[1];
  options.tool_id = argv[2];
  options.frame.scale = argc > 4 ? std::atof(argv[4]) : 1;
  Bridge b;
  if (palpate_device_open(&options, &b.tool, b.error, sizeof b.error) != PALPATE_DEVICE_OK) {
    std::fprintf(stderr, "chai3d_bridge: %s\n", b.error);
    return 3;
  }
  chai3d::cHapticDeviceHandler handler;
  if (!handler.getDevice(b.device, 0) || !b.device->open()) {
    std::fprintf(stderr, "chai3d_bridge: no haptic device found by CHAI3D\n");
    palpate_device_close(b.tool);
    return 3;
  }
  b.device->calibrate();
  chai3d::cThread thread;
  thread.start(servo, chai3d::CTHREAD_PRIORITY_HAPTICS, &b);
  chai3d::cSleepMs(static_cast<unsigned int>(seconds * 1e3));
  b.running = false;
  while (!b.finished) chai3d::cSleepMs(1);  // the loop's own end (cThread::stop() kills it)
  b.device->close();
  if (b.status != PALPATE_DEVICE_OK) std::fprintf(stderr, "chai3d_bridge: %s\n", b.error);
  // The servo thread has stopped: the handle is this thread's now.
  palpate_device_close(b.tool);  // ends the session: palpated lets go at once
  return b.status == PALPATE_DEVICE_OK ? 0 : 5;
}
