/*
 * A 3D Systems (OpenHaptics HD API) device as one of palpated's tools,
 * through palpate's C API (docs/devices.md, "OpenHaptics"). Built only where
 * CMake finds HD/hd.h and libHD (examples/CMakeLists.txt).
 *
 * The HD scheduler's servo callback (1 kHz) reads the stylus's transform,
 * gives it to palpate_device_set_pose() and sends palpate_device_force() to
 * the motors. The conversions, all in palpate_device_options.frame:
 *   - HD_CURRENT_TRANSFORM: a column-major 4 x 4 matrix (OpenGL's layout),
 *     the translation in mm in elements 12, 13, 14: times 1e-3 to m;
 *   - the HD frame (x right, y up, z towards the user) turned onto the
 *     model's with x towards the user, y right, z up: the cyclic
 *     permutation (x, y, z)_model = (z, x, y)_HD, the quaternion
 *     (0.5, 0.5, 0.5, 0.5); forces come back in the HD frame;
 *   - the stylus: taken to point along its frame's -z (check on your
 *     device: docs/devices.md), so the tool's +z is the stylus's -z, half a
 *     turn about x: handle_to_tool = (0, 1, 0, 0);
 *   - HD_CURRENT_FORCE takes newtons, as palpate gives them.
 * The first stylus button closes the jaws (a grasp); released, they open
 * to 40 degrees.
 *
 *     openhaptics_bridge MODEL TOOL [SECONDS] [SCALE]
 */
#define _POSIX_C_SOURCE 200809L

#include <HD/hd.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "device_frames.h"
#include "palpate/device.h"

#define JAW_OPEN_RAD 0.698 /* 40 degrees */

typedef struct {
  palpate_device* tool;
  HHD device;
  int failed;
  char error[256];
  palpate_device_state state; /* copied out in the servo thread */
  palpate_device_event event;
  int got_event;
} Bridge;

/* The servo callback: the only thread that touches the handle while the
 * scheduler runs. Never blocks, allocates nothing. */
static HDCallbackCode HDCALLBACK servo(void* data) {
  Bridge* b = (Bridge*)data;
  hdBeginFrame(b->device);
  HDdouble m[16];
  HDint buttons = 0;
  hdGetDoublev(HD_CURRENT_TRANSFORM, m);
  hdGetIntegerv(HD_CURRENT_BUTTONS, &buttons);
  double position_m[3], orientation[4]; /* mm to m, the stylus's rotation */
  palpate_pose_of_hd_transform(m, position_m, orientation);
  const double jaw = (buttons & HD_DEVICE_BUTTON_1) ? 0.0 : JAW_OPEN_RAD;
  double force[3] = {0, 0, 0}, torque[3];
  if (palpate_device_set_pose(b->tool, 0, position_m, orientation, jaw, NULL, b->error,
                              sizeof b->error) != PALPATE_DEVICE_OK ||
      palpate_device_force(b->tool, 0, force, torque, b->error, sizeof b->error) !=
          PALPATE_DEVICE_OK) {
    force[0] = force[1] = force[2] = 0;
    b->failed = 1;
  }
  hdSetDoublev(HD_CURRENT_FORCE, force);
  hdEndFrame(b->device);
  HDErrorInfo e = hdGetError();
  if (HD_DEVICE_ERROR(e) || b->failed) return HD_CALLBACK_DONE;
  return HD_CALLBACK_CONTINUE;
}

/* Run in the servo thread by hdScheduleSynchronous: what the main thread prints. */
static HDCallbackCode HDCALLBACK look(void* data) {
  Bridge* b = (Bridge*)data;
  b->state.struct_size = sizeof b->state;
  palpate_device_get_state(b->tool, &b->state, NULL, 0);
  b->event.struct_size = sizeof b->event;
  b->got_event = palpate_device_next_event(b->tool, &b->event, NULL, 0) == PALPATE_DEVICE_OK;
  return HD_CALLBACK_DONE;
}

int main(int argc, char** argv) {
  if (argc < 3) {
    fprintf(stderr, "usage: openhaptics_bridge MODEL TOOL [SECONDS] [SCALE]\n");
    return 2;
  }
  const double seconds = argc > 3 ? atof(argv[3]) : 60;
  Bridge b = {0};
  palpate_device_options options;
  palpate_device_options_init(&options);
  options.model_id = argv[1];
  options.tool_id = argv[2];
  options.frame.scale = argc > 4 ? atof(argv[4]) : 1;
  /* (x, y, z)_model = (z, x, y)_HD: a third of a turn about (1, 1, 1). */
  const double hd_to_model[4] = {0.5, 0.5, 0.5, 0.5};
  const double stylus_to_tool[4] = {0, 1, 0, 0};
  for (int i = 0; i < 4; ++i) {
    options.frame.rotation_wxyz[i] = hd_to_model[i];
    options.frame.handle_to_tool_wxyz[i] = stylus_to_tool[i];
  }
  char error[512];
  if (palpate_device_open(&options, &b.tool, error, sizeof error) != PALPATE_DEVICE_OK) {
    fprintf(stderr, "openhaptics_bridge: %s\n", error);
    return 3;
  }
  b.device = hdInitDevice(HD_DEFAULT_DEVICE);
  HDErrorInfo e = hdGetError();
  if (HD_DEVICE_ERROR(e)) {
    fprintf(stderr, "openhaptics_bridge: no HD device: %s\n", hdGetErrorString(e.errorCode));
    palpate_device_close(b.tool);
    return 3;
  }
  hdEnable(HD_FORCE_OUTPUT);
  const HDSchedulerHandle servo_handle =
      hdScheduleAsynchronous(servo, &b, HD_MAX_SCHEDULER_PRIORITY);
  hdStartScheduler();
  for (double t = 0; t < seconds && !b.failed; t += 0.1) {
    hdScheduleSynchronous(look, &b, HD_DEFAULT_SCHEDULER_PRIORITY);
    if (b.got_event) printf("%8.1f s  %s\n", t, b.event.message);
    if ((int)(t * 10) % 10 == 0)
      printf("%8.1f s  state %d, contacts %u, rendered (%.2f, %.2f, %.2f) N, round trip %.0f us\n",
             t, b.state.tool_state, b.state.contacts, b.state.rendered_force_n[0],
             b.state.rendered_force_n[1], b.state.rendered_force_n[2], b.state.round_trip_s * 1e6);
    fflush(stdout);
    struct timespec tenth = {0, 100000000};
    nanosleep(&tenth, NULL);
  }
  hdStopScheduler();
  hdUnschedule(servo_handle);
  hdDisableDevice(b.device);
  if (b.failed) fprintf(stderr, "openhaptics_bridge: %s\n", b.error);
  palpate_device_close(b.tool); /* ends the session: palpated lets go at once */
  return b.failed ? 5 : 0;
}
