/*
 * A haptic device in software, on the C API alone (palpate/device.h,
 * docs/devices.md, "The simulated device").
 *
 * The device's handle is a point mass with viscous friction; a hand holds
 * it through a spring and a damper (a human hand's impedance) and follows a
 * scripted press: 15 mm above the organ's surface, down to 6 mm below it
 * along the inward normal, held, back out. At every 4 kHz servo step the
 * program gives the handle's pose to palpate_device_set_pose() (poses go to
 * palpated at 1 kHz), asks palpate_device_force() what to render, and
 * integrates the handle (semi-implicit Euler):
 *
 *     m dv/dt = F_hand + F_rendered - b v,   F_hand = k_h (x_h - x) + b_h (v_h - v)
 *
 * The press is made where the organ is freest: the compliance vertex
 * farthest from every fixed (attached) surface vertex, along its outward
 * normal (the area-weighted normals of the triangles around it), as a
 * gesture's "auto" anchor (docs/pliers.md).
 *
 * It prints what the device felt, and a last line of key=value pairs that
 * tests/device/device_test.cpp reads. Exit: 0 played, 2 bad arguments, 3 no
 * palpated (or it refused the tool), 5 another failure.
 *
 *     simulated_device MODEL [TOOL] [--rate HZ] [--vertex ID]
 *
 * --vertex: press at this mesh vertex (a compliance vertex) instead.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "palpate/device.h"

/* The device and the hand (SI). */
#define HANDLE_MASS_KG 0.1
#define HANDLE_DAMPING_N_S_PER_M 1.0
#define HAND_STIFFNESS_N_PER_M 300.0
#define HAND_DAMPING_N_S_PER_M 4.0
/* The default tool's hinge to the end of its capsule tip, along the shaft
 * (docs/tools.md: a 15 mm capsule of radius 4 mm). */
#define REACH_M 0.019

/* The script: phases of the hand's target depth below the rest surface
 * along the inward normal, m (negative: above it). */
typedef struct {
  const char* name;
  double duration_s, from_m, to_m;
} Phase;
static const Phase kPhases[] = {
    {"free", 0.3, -0.015, -0.015}, {"down", 0.5, -0.015, 0.006},  {"hold", 0.8, 0.006, 0.006},
    {"up", 0.5, 0.006, -0.015},    {"away", 0.3, -0.015, -0.015},
};
#define PHASES ((int)(sizeof kPhases / sizeof kPhases[0]))

static double dot(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
static double norm(const double a[3]) { return sqrt(dot(a, a)); }

/* The quaternion (w x y z) turning +z onto the unit vector d. */
static void z_onto(const double d[3], double q[4]) {
  const double c = d[2]; /* cos of the angle between +z and d */
  if (c < -1 + 1e-12) {  /* opposite: half a turn about x */
    q[0] = 0, q[1] = 1, q[2] = 0, q[3] = 0;
    return;
  }
  /* q = (1 + c, z × d) normalized */
  q[0] = 1 + c, q[1] = -d[1], q[2] = d[0], q[3] = 0;
  const double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
  for (int i = 0; i < 4; ++i) q[i] /= n;
}

/* The press point: the compliance vertex of mesh id @p wanted (any when
 * negative: the freest) and its outward normal. Returns the drawn vertex,
 * -1 if there is none. */
static long anchor(const palpate_device_model* m, long wanted, double point[3], double normal[3]) {
  const double* p = m->rest_positions_m;
  long best = -1;
  double best_d2 = -1;
  for (uint32_t a = 0; a < m->compliance_vertex_count; ++a) {
    if (wanted >= 0) {
      if (m->vertex_ids[a] == (uint32_t)wanted) best = (long)a;
      continue;
    }
    double d2 = m->vertex_count > m->compliance_vertex_count ? INFINITY : 0;
    for (uint32_t f = m->compliance_vertex_count; f < m->vertex_count; ++f) {
      const double dx = p[3 * a] - p[3 * f], dy = p[3 * a + 1] - p[3 * f + 1],
                   dz = p[3 * a + 2] - p[3 * f + 2];
      const double e = dx * dx + dy * dy + dz * dz;
      if (e < d2) d2 = e;
    }
    if (d2 > best_d2) best_d2 = d2, best = (long)a;
  }
  if (best < 0) return -1;
  normal[0] = normal[1] = normal[2] = 0;
  for (uint32_t t = 0; t < m->triangle_count; ++t) {
    const uint32_t* v = m->triangles + 3 * t;
    if (v[0] != (uint32_t)best && v[1] != (uint32_t)best && v[2] != (uint32_t)best) continue;
    const double* a = p + 3 * v[0];
    const double* b = p + 3 * v[1];
    const double* c = p + 3 * v[2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    /* (b - a) × (c - a): twice the area times the outward unit normal */
    normal[0] += u[1] * w[2] - u[2] * w[1];
    normal[1] += u[2] * w[0] - u[0] * w[2];
    normal[2] += u[0] * w[1] - u[1] * w[0];
  }
  const double n = norm(normal);
  if (!(n > 0)) return -1;
  for (int i = 0; i < 3; ++i) normal[i] /= n, point[i] = p[3 * best + i];
  return best;
}

static void sleep_until_ns(int64_t t) {
  struct timespec ts;
  ts.tv_sec = (time_t)(t / 1000000000);
  ts.tv_nsec = (long)(t % 1000000000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
  }
}

static int exit_code(int status) {
  switch (status) {
    case PALPATE_DEVICE_E_ARGUMENT:
    case PALPATE_DEVICE_E_NO_MODEL:
      return 2;
    case PALPATE_DEVICE_E_NO_PALPATED:
    case PALPATE_DEVICE_E_NO_TOOLS:
      return 3;
    default:
      return 5;
  }
}

int main(int argc, char** argv) {
  const char* model_id = NULL;
  const char* tool_id = "left";
  double rate_hz = 4000;
  long wanted = -1;
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--rate") == 0 && i + 1 < argc)
      rate_hz = atof(argv[++i]);
    else if (strcmp(argv[i], "--vertex") == 0 && i + 1 < argc)
      wanted = atol(argv[++i]);
    else if (model_id == NULL)
      model_id = argv[i];
    else
      tool_id = argv[i];
  }
  if (model_id == NULL || !(rate_hz >= 100 && rate_hz <= 20000)) {
    fprintf(stderr,
            "usage: simulated_device MODEL [TOOL] [--rate HZ (100 to 20000)] [--vertex ID]\n");
    return 2;
  }

  char error[512];
  palpate_device_options options;
  palpate_device_options_init(&options);
  options.model_id = model_id;
  options.tool_id = tool_id;
  palpate_device* tool = NULL;
  int status = palpate_device_open(&options, &tool, error, sizeof error);
  if (status != PALPATE_DEVICE_OK) {
    fprintf(stderr, "simulated_device: %s\n", error);
    return exit_code(status);
  }
  palpate_device_model model;
  model.struct_size = sizeof model;
  palpate_device_get_model(tool, &model, NULL, 0);
  double surface[3], normal[3];
  const long vertex = anchor(&model, wanted, surface, normal);
  if (vertex < 0) {
    fprintf(stderr, "simulated_device: model '%s' has no free surface vertex %ld to press\n",
            model_id, wanted);
    palpate_device_close(tool);
    return 2;
  }
  const double inward[3] = {-normal[0], -normal[1], -normal[2]};
  double orientation[4]; /* the shaft (tool +z) along the inward normal */
  z_onto(inward, orientation);
  printf(
      "simulated_device: model %s, tool %s, %.0f Hz; press at vertex %u (%.4f, %.4f, %.4f) m, "
      "outward normal (%.3f, %.3f, %.3f)\n",
      model_id, tool_id, rate_hz, model.vertex_ids[vertex], surface[0], surface[1], surface[2],
      normal[0], normal[1], normal[2]);

  /* The handle's tip point, along the normal from the rest surface (m,
   * negative outside), and its velocity. */
  const double dt = 1.0 / rate_hz;
  const int64_t dt_ns = (int64_t)llround(1e9 / rate_hz);
  double depth = kPhases[0].from_m, velocity = 0;
  double free_max_n = 0, free_damping_max_n = 0, contact_max_n = 0, max_damping = 0;
  double posed_depth = depth; /* the depth of the pose given at the step before */
  double hold_force = 0, hold_spring = 0, hold_answer = 0;
  long hold_samples = 0, steps = 0, free_steps = 0;
  int64_t free_since = -1; /* when the answers began to say the tool is free */
  int touch = 0, leave = 0, ended = 0, refused = 0;
  int64_t t = palpate_device_now_ns() + 1000000;
  for (int p = 0; p < PHASES && status == PALPATE_DEVICE_OK; ++p) {
    const Phase* phase = &kPhases[p];
    const long n = lround(phase->duration_s * rate_hz);
    for (long k = 0; k < n; ++k, ++steps, t += dt_ns) {
      sleep_until_ns(t);
      const double s = (double)(k + 1) / (double)n;
      const double target = phase->from_m + (phase->to_m - phase->from_m) * s;
      const double target_velocity = (phase->to_m - phase->from_m) / phase->duration_s;
      const double posing_depth = depth;
      /* The hinge: the tip point minus the reach along the shaft. */
      double hinge[3];
      for (int i = 0; i < 3; ++i) hinge[i] = surface[i] + (depth - REACH_M) * inward[i];
      status = palpate_device_set_pose(tool, t, hinge, orientation, 0.0, NULL, error, sizeof error);
      double force[3], torque[3];
      if (status == PALPATE_DEVICE_OK)
        status = palpate_device_force(tool, t, force, torque, error, sizeof error);
      if (status != PALPATE_DEVICE_OK) break;
      /* Along the inward normal: the organ pushes the handle out. */
      const double along = dot(force, inward);
      const double hand = HAND_STIFFNESS_N_PER_M * (target - depth) +
                          HAND_DAMPING_N_S_PER_M * (target_velocity - velocity);
      velocity += dt * (hand + along - HANDLE_DAMPING_N_S_PER_M * velocity) / HANDLE_MASS_KG;
      depth += dt * velocity;

      const double magnitude = norm(force);
      palpate_device_state state;
      state.struct_size = sizeof state;
      palpate_device_get_state(tool, &state, NULL, 0);
      if (state.damping_n_s_per_m > max_damping) max_damping = state.damping_n_s_per_m;
      /* The velocity of the poses given (the step before to this one), along
       * the inward normal: the passivity controller damps it, -alpha v. */
      const double speed = (posing_depth - posed_depth) / dt;
      posed_depth = posing_depth;
      /* Free: the tip a clear 5 mm outside the rest surface, and palpated
       * has said so for 20 ms (a touch's force, slew limited at 500 N/s,
       * is gone by then): nothing is rendered but the damping that pays
       * back an energy debt the touch left (docs/model/rendering.md, passivity). */
      if (!state.has_answer || state.tool_state != PALPATE_DEVICE_FREE)
        free_since = -1;
      else if (free_since < 0)
        free_since = t;
      if (depth < -0.005 && free_since >= 0 && t - free_since >= 20000000) {
        double damping_force[3], beside[3];
        for (int i = 0; i < 3; ++i) {
          damping_force[i] = -state.damping_n_s_per_m * speed * inward[i];
          beside[i] = force[i] - damping_force[i];
        }
        ++free_steps;
        const double beside_n = norm(beside), damping_n = norm(damping_force);
        if (beside_n > free_max_n) free_max_n = beside_n;
        if (damping_n > free_damping_max_n) free_damping_max_n = damping_n;
      }
      if (magnitude > contact_max_n) contact_max_n = magnitude;
      /* The last half of the hold, settled: the device's force and the hand's. */
      if (strcmp(phase->name, "hold") == 0 && 2 * k >= n) {
        hold_force += -along;
        hold_spring += HAND_STIFFNESS_N_PER_M * (target - depth);
        hold_answer += -dot(state.answer_force_n, inward);
        ++hold_samples;
      }
    }
  }
  if (status != PALPATE_DEVICE_OK) {
    fprintf(stderr, "simulated_device: %s\n", error);
    palpate_device_close(tool);
    return exit_code(status);
  }

  /* The end of the session: palpated lets go and says so (ENDED). */
  status = palpate_device_end_session(tool, 2.0, error, sizeof error);
  if (status != PALPATE_DEVICE_OK) fprintf(stderr, "simulated_device: %s\n", error);
  palpate_device_state state;
  state.struct_size = sizeof state;
  palpate_device_get_state(tool, &state, NULL, 0);
  const int64_t give_up = palpate_device_now_ns() + 3000000000LL;
  while (!ended && palpate_device_now_ns() < give_up) {
    palpate_device_event event;
    event.struct_size = sizeof event;
    const int got = palpate_device_next_event(tool, &event, error, sizeof error);
    if (got == PALPATE_DEVICE_NONE) {
      sleep_until_ns(palpate_device_now_ns() + 2000000);
      continue;
    }
    if (got != PALPATE_DEVICE_OK) break;
    printf("  %-8s [pose %llu] %s\n", event.kind == PALPATE_DEVICE_EVENT_REFUSED ? "refused" : "",
           (unsigned long long)(event.pose_sequence - state.first_sequence + 1), event.message);
    touch += event.kind == PALPATE_DEVICE_EVENT_TOUCH;
    leave += event.kind == PALPATE_DEVICE_EVENT_LEAVE;
    ended += event.kind == PALPATE_DEVICE_EVENT_ENDED;
    refused += event.kind == PALPATE_DEVICE_EVENT_REFUSED;
  }
  palpate_device_close(tool);

  const double samples = hold_samples > 0 ? (double)hold_samples : 1;
  printf(
      "simulated_device: %ld steps, %llu poses, %llu answers; pushed back %.3f N held (the "
      "hand's spring %.3f N, palpated's answer %.3f N), at most %.3f N; free (answered so) at most "
      "%.3g N beside %.3g N of damping; damping at most %.3g N s/m\n",
      steps, (unsigned long long)state.poses_sent, (unsigned long long)state.answers_taken,
      hold_force / samples, hold_spring / samples, hold_answer / samples, contact_max_n, free_max_n,
      free_damping_max_n, max_damping);
  printf(
      "result steps=%ld poses=%llu answers=%llu hold_force_n=%.6f hold_spring_n=%.6f "
      "hold_answer_n=%.6f max_force_n=%.6f free_steps=%ld free_max_n=%.9f "
      "free_damping_max_n=%.9f max_damping=%.6f touch=%d leave=%d ended=%d refused=%d\n",
      steps, (unsigned long long)state.poses_sent, (unsigned long long)state.answers_taken,
      hold_force / samples, hold_spring / samples, hold_answer / samples, contact_max_n, free_steps,
      free_max_n, free_damping_max_n, max_damping, touch, leave, ended, refused);
  return refused > 0 ? 3 : 0;
}
