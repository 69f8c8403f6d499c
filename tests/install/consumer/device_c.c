/* A haptic device's bridge in plain C99 on the installed C API
 * (palpate/device.h, palpate::device or pkg-config palpate-device): joins
 * the DDS domain (palpate's loopback configuration: the test runs it in a
 * private network namespace) and opens a tool on a model no palpated
 * serves: the status and message say so. */
#include <stdio.h>
#include <string.h>

#include "palpate/device.h"

int main(void) {
  int major = 0, minor = 0, patch = 0;
  palpate_device_version(&major, &minor, &patch);
  if (major != PALPATE_DEVICE_VERSION_MAJOR) {
    fprintf(stderr, "device_c: header %d, library %d\n", PALPATE_DEVICE_VERSION_MAJOR, major);
    return 1;
  }
  palpate_device_options options;
  palpate_device_options_init(&options);
  options.model_id = "liver";
  options.tool_id = "left";
  options.timeout_s = 0.2;
  palpate_device* tool = NULL;
  char error[256];
  const int status = palpate_device_open(&options, &tool, error, sizeof error);
  printf("device_c: palpate/device.h %d.%d.%d; open: %s (%s)\n", major, minor, patch,
         palpate_device_status_name(status), error);
  palpate_device_close(tool);
  return status == PALPATE_DEVICE_E_NO_PALPATED && tool == NULL &&
                 strstr(error, "no palpated within") != NULL
             ? 0
             : 1;
}
