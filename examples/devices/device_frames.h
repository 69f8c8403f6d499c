/*
 * Rotations as the device SDKs give them, to the unit quaternions (w x y z)
 * palpate/device.h takes: shared by the example bridges
 * (docs/devices.md) and checked by tests/device/device_frames_test.cpp.
 */
#ifndef PALPATE_EXAMPLES_DEVICE_FRAMES_H
#define PALPATE_EXAMPLES_DEVICE_FRAMES_H

#include <math.h>

/* The unit quaternion q (w x y z) of the rotation matrix R whose columns
 * are c0, c1, c2 (R(i, j) = cj[i]): the end effector's axes in the device's
 * frame. Shepperd's method: the largest of w, x, y, z first, for accuracy. */
static inline void palpate_quaternion_of_columns(const double c0[3], const double c1[3],
                                                 const double c2[3], double q[4]) {
  const double trace = c0[0] + c1[1] + c2[2];
  if (trace > 0) {
    const double s = 2 * sqrt(1 + trace); /* 4 w */
    q[0] = s / 4;
    q[1] = (c1[2] - c2[1]) / s;
    q[2] = (c2[0] - c0[2]) / s;
    q[3] = (c0[1] - c1[0]) / s;
  } else if (c0[0] > c1[1] && c0[0] > c2[2]) {
    const double s = 2 * sqrt(1 + c0[0] - c1[1] - c2[2]); /* 4 x */
    q[0] = (c1[2] - c2[1]) / s;
    q[1] = s / 4;
    q[2] = (c1[0] + c0[1]) / s;
    q[3] = (c2[0] + c0[2]) / s;
  } else if (c1[1] > c2[2]) {
    const double s = 2 * sqrt(1 + c1[1] - c0[0] - c2[2]); /* 4 y */
    q[0] = (c2[0] - c0[2]) / s;
    q[1] = (c1[0] + c0[1]) / s;
    q[2] = s / 4;
    q[3] = (c2[1] + c1[2]) / s;
  } else {
    const double s = 2 * sqrt(1 + c2[2] - c0[0] - c1[1]); /* 4 z */
    q[0] = (c0[1] - c1[0]) / s;
    q[1] = (c2[0] + c0[2]) / s;
    q[2] = (c2[1] + c1[2]) / s;
    q[3] = s / 4;
  }
}

/* From a row-major 3 x 3 matrix r[i][j] = R(i, j) (Force Dimension's
 * dhdGetOrientationFrame, CHAI3D's cMatrix3d(i, j)). */
static inline void palpate_quaternion_of_rows(const double r[3][3], double q[4]) {
  const double c0[3] = {r[0][0], r[1][0], r[2][0]};
  const double c1[3] = {r[0][1], r[1][1], r[2][1]};
  const double c2[3] = {r[0][2], r[1][2], r[2][2]};
  palpate_quaternion_of_columns(c0, c1, c2, q);
}

/* From OpenHaptics' HD_CURRENT_TRANSFORM: 16 doubles, column-major (OpenGL's
 * layout): the rotation's columns at 0, 4, 8 and the translation, in mm, at
 * 12, 13, 14. Writes the position in m and the orientation. */
static inline void palpate_pose_of_hd_transform(const double m[16], double position_m[3],
                                                double q[4]) {
  position_m[0] = m[12] * 1e-3;
  position_m[1] = m[13] * 1e-3;
  position_m[2] = m[14] * 1e-3;
  palpate_quaternion_of_columns(&m[0], &m[4], &m[8], q);
}

#endif /* PALPATE_EXAMPLES_DEVICE_FRAMES_H */
