/*
 * palpate/device.h: the C API for haptic devices (docs/devices.md).
 *
 * A haptic device's servo callback (OpenHaptics, Force Dimension, CHAI3D, or
 * a device of one's own) drives one of palpated's tools through it: open a
 * tool on a model, give the device's pose every servo tick, read the force
 * to render now, close. Underneath, a palpate::ToolClient (docs/pliers.md,
 * "The C++ ToolClient"): poses go to palpated at the pose rate (1 kHz by
 * default), and every call of palpate_device_force() renders the newest
 * answer's local contact model at the device's current pose, at the
 * device's own rate, with the device's limits and a passivity observer
 * (docs/pliers.md, "Rendering at the device's rate").
 *
 * Plain C99: opaque handles, no C++ type, no exception crosses it. Every
 * function that can fail returns a palpate_device_status and, when the
 * caller gives a buffer (error, error_size; NULL and 0 are allowed), writes
 * one line saying what went wrong, NUL-terminated and cut to error_size.
 *
 * Units are SI everywhere: m, N, N·m, rad, s; times are nanoseconds on the
 * steady clock (CLOCK_MONOTONIC: palpate_device_now_ns()). Positions and
 * orientations are given in the device's frame and converted to the model
 * frame by palpate_device_options.frame (identity by default: the device's
 * frame is the model's); forces come back in the device's frame.
 *
 * The tool frame (docs/tools.md): origin at the jaws' hinge, +z along the
 * shaft towards the tip, the jaws opening in the tool's x-z plane. A pose is
 * the hinge's position, the tool frame's orientation (a unit quaternion w,
 * x, y, z: tool -> model) and the jaw opening (rad, total).
 *
 * Threads: a handle is driven by one thread at a time (the servo thread);
 * different handles may be driven by different threads.
 * palpate_device_set_pose() and palpate_device_force() never block and
 * allocate nothing: call them from a 1-10 kHz servo callback.
 * palpate_device_open(), _wait(), _end_session() and _close() block; call
 * them outside the servo callback. palpate_device_next_event() never
 * blocks but allocates when events came (a touch, a grasp: a few a second).
 *
 * Network: without a configuration (options.dds_config NULL or "") the
 * handle joins DDS with palpate's loopback-only configuration (multicast
 * off), or the one CYCLONEDDS_URI names when that is set, as every palpate
 * program does (docs/dds.md, "Network configuration").
 */
#ifndef PALPATE_DEVICE_H
#define PALPATE_DEVICE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The version of this header. palpate_device_version() gives the library's:
 * the same major version is binary compatible (structs only grow at their
 * end, behind their struct_size). */
#define PALPATE_DEVICE_VERSION_MAJOR 1
#define PALPATE_DEVICE_VERSION_MINOR 0
#define PALPATE_DEVICE_VERSION_PATCH 0

#if defined(__GNUC__) || defined(__clang__)
#define PALPATE_DEVICE_API __attribute__((visibility("default")))
#else
#define PALPATE_DEVICE_API
#endif

/* What a call returns (docs/errors.md, "The C API"). 0 and the positive
 * values are not errors; the negative ones are. */
typedef enum palpate_device_status {
  PALPATE_DEVICE_OK = 0,
  /* Nothing to take or not yet: no event (next_event), no answer
   * (next_answer), the deadline came first (wait). */
  PALPATE_DEVICE_NONE = 1,
  /* A null pointer, a bad id, a value out of range or not finite. */
  PALPATE_DEVICE_E_ARGUMENT = -1,
  /* A struct whose struct_size this library does not accept. */
  PALPATE_DEVICE_E_VERSION = -2,
  /* No palpated within the timeout: no model description at all. */
  PALPATE_DEVICE_E_NO_PALPATED = -3,
  /* palpated answers but does not serve this model (the message lists those it does). */
  PALPATE_DEVICE_E_NO_MODEL = -4,
  /* palpated serves the model but does not read tool poses (a palpated without tools). */
  PALPATE_DEVICE_E_NO_TOOLS = -5,
  /* The DDS configuration cannot be read, or DDS Security refuses it. */
  PALPATE_DEVICE_E_CONFIG = -6,
  /* DDS failed: a participant, an endpoint or a write. */
  PALPATE_DEVICE_E_DDS = -7,
  /* palpated did not acknowledge in time (end_session). */
  PALPATE_DEVICE_E_TIMEOUT = -8,
  /* Anything else (out of memory, an internal invariant): a bug to report. */
  PALPATE_DEVICE_E_INTERNAL = -9
} palpate_device_status;

/* palpated's answer to a pose: the tool's state. */
enum { PALPATE_DEVICE_FREE = 0, PALPATE_DEVICE_TOUCHING = 1, PALPATE_DEVICE_GRASPING = 2 };

/* palpated's presence, from its status heartbeat (docs/faults.md). */
enum {
  PALPATE_DEVICE_DAEMON_UNKNOWN = 0, /* no heartbeat yet */
  PALPATE_DEVICE_DAEMON_PRESENT = 1,
  PALPATE_DEVICE_DAEMON_LOST = 2 /* silent: nothing is rendered until it is back */
};

/* Event kinds: palpated's tool events (docs/tools.md, "States"), and the
 * refusal of a pose (docs/tools.md, "Bad poses"). */
enum {
  PALPATE_DEVICE_EVENT_TOUCH = 0,
  PALPATE_DEVICE_EVENT_LEAVE = 1,
  PALPATE_DEVICE_EVENT_GRASP = 2,
  PALPATE_DEVICE_EVENT_RELEASE = 3,
  PALPATE_DEVICE_EVENT_WATCHDOG = 4,
  PALPATE_DEVICE_EVENT_RESUMED = 5,
  PALPATE_DEVICE_EVENT_ENDED = 6,
  PALPATE_DEVICE_EVENT_REFUSED = 16
};

/* The device's frame in the model's, and the handle's in the tool's:
 *
 *   x_model = offset_m + scale * R x_device            (R: rotation_wxyz)
 *   R_tool  = R * R_handle * H                          (H: handle_to_tool_wxyz)
 *   F_device = force_scale * R^T F_model,  tau_device = force_scale * R^T tau_model
 *
 * R_handle is the orientation the device reports (handle -> device frame);
 * H turns the handle's frame into the tool's (+z along the shaft towards
 * the tip). With scale s and force_scale k, the hand feels k/s times the
 * model's work on it: any positive s and k keep what is rendered passive. */
typedef struct palpate_device_frame {
  double scale;                  /* model metres per device metre; 1 */
  double rotation_wxyz[4];       /* device axes -> model axes; identity */
  double offset_m[3];            /* the device origin in the model, m; 0 */
  double handle_to_tool_wxyz[4]; /* the tool's axes in the handle's; identity */
  double force_scale;            /* N on the hand per N on the tool; 1 */
} palpate_device_frame;

/* How to open a tool. Fill it with palpate_device_options_init(), then set
 * model_id and tool_id. struct_size lets the struct grow at its end. */
typedef struct palpate_device_options {
  uint32_t struct_size; /* sizeof(palpate_device_options) */
  uint32_t domain_id;   /* DDS domain; 0 */
  const char* model_id; /* required: a model palpated serves */
  const char* tool_id;  /* required: one of palpated's tools ([[tools]]; default left, right) */
  /* Cyclone DDS configuration (XML, a file, or file:// URI); NULL or "":
   * palpate's loopback-only one, or CYCLONEDDS_URI when set. */
  const char* dds_config;
  double pose_rate_hz; /* poses to palpated at most this often, 1 to 20000; 1000 */
  double timeout_s;    /* open() waits this long for the model and for palpated; 10 */
  /* The sequence of the first pose minus one; 0: the steady clock in
   * microseconds (above any earlier run's). */
  uint64_t first_sequence;
  /* palpate_device_wait() polls (yielding the CPU) instead of sleeping on
   * a waitset: a shorter wake-up for a core kept busy; 0 */
  int busy_wait;
  /* Rendering (docs/pliers.md, "Rendering at the device's rate"). */
  int local_model;                         /* 1: the answer's local model; 0: its force, held */
  int passivity;                           /* 1: the passivity observer and controller */
  double max_damping_n_s_per_m;            /* most damping it may add; 50 */
  double max_angular_damping_nm_s_per_rad; /* 0.05 */
  double hold_s;                           /* an answer is rendered as it is this long; 0.05 */
  double ramp_s;                           /* then ramped to zero over this long; 0.25 */
  palpate_device_frame frame;              /* identity */
  /* 1: send palpated, with each pose, what was rendered since the previous
   * one, for its session recording (docs/session-recording.md, "What the
   * device rendered"); 0 */
  int report_rendering;
} palpate_device_options;

/* What the handle knows now: palpated, the newest answer, the last render. */
typedef struct palpate_device_state {
  uint32_t struct_size; /* the caller sets sizeof(palpate_device_state) */
  int daemon;           /* PALPATE_DEVICE_DAEMON_* */
  uint64_t daemon_losses, daemon_restarts;
  double daemon_silent_s;    /* since its last heartbeat */
  double daemon_uptime_s;    /* in its last heartbeat */
  uint64_t first_sequence;   /* of this handle's first pose */
  uint64_t last_sequence;    /* of the newest pose sent; 0: none */
  int64_t last_send_time_ns; /* the steady clock stamped into it */
  uint64_t poses_sent, answers_taken;
  uint64_t answers_dropped; /* from the log of answers (next_answer) when it was full */
  /* The newest answer (the highest sequence): palpated's, model frame. */
  int has_answer;
  uint64_t answer_sequence; /* the pose it answers */
  int tool_state;           /* PALPATE_DEVICE_FREE, _TOUCHING, _GRASPING */
  uint32_t contacts;        /* surface points the tool constrains */
  double grip_n;            /* squeeze per jaw */
  double answer_force_n[3]; /* what palpated fed back, after the device's limits */
  double answer_torque_nm[3];
  int force_limited, watchdog;
  double round_trip_s; /* its pose sent -> the answer taken */
  double answer_age_s; /* since it was taken; -1: none */
  /* The last palpate_device_force(), device frame. */
  double rendered_force_n[3];
  double rendered_torque_nm[3];
  double damping_n_s_per_m; /* the passivity controller's, that call */
  double energy_j;          /* the passivity observer's energy after it: >= 0 */
  int render_limited;       /* the force or slew limit acted */
  double render_scale;      /* the answer's age ramp, 1 -> 0 */
} palpate_device_state;

/* One of palpated's answers, as it came (palpate_device_next_answer). */
typedef struct palpate_device_answer {
  uint32_t struct_size;    /* the caller sets sizeof(palpate_device_answer) */
  uint64_t sequence;       /* the pose it answers */
  int64_t send_time_ns;    /* that pose's, steady clock */
  int64_t receive_time_ns; /* taken from DDS, steady clock */
  double force_n[3];       /* fed back, model frame */
  double torque_nm[3];     /* about the hinge, model frame */
  double grip_n;
  uint32_t contacts;
  int tool_state;
  int force_limited, watchdog;
  uint64_t compute_ns; /* palpated's, pose taken -> answer written */
  int model_valid;     /* it carries a local contact model */
} palpate_device_answer;

/* A tool event, or why palpated refused a pose. */
typedef struct palpate_device_event {
  uint32_t struct_size; /* the caller sets sizeof(palpate_device_event) */
  int kind;             /* PALPATE_DEVICE_EVENT_* */
  uint64_t pose_sequence;
  uint32_t held_points;    /* for a grasp */
  int64_t receive_time_ns; /* steady clock */
  char message[256];       /* the event's name, or the refusal's reason (one line) */
} palpate_device_event;

/* The model's surface as palpated describes it (docs/dds.md,
 * ModelDescription). The pointers stay valid until palpate_device_close(). */
typedef struct palpate_device_model {
  uint32_t struct_size; /* the caller sets sizeof(palpate_device_model) */
  const char* model_id;
  const char* mechanics; /* "linear" or "warped" */
  uint32_t compliance_vertex_count;
  uint32_t vertex_count; /* drawn vertices: compliance vertices first */
  uint32_t triangle_count;
  const uint32_t* vertex_ids;     /* vertex_count mesh vertex ids */
  const double* rest_positions_m; /* 3 per drawn vertex, model frame */
  const uint32_t* triangles;      /* 3 per triangle, into the drawn vertices, outward */
  /* Appended 2026-11-26: the cut region palpated simulates on this model (its
   * precompute spec, docs/dds.md "The cut region"); "" when none. */
  const char* cut_region;
} palpate_device_model;

typedef struct palpate_device palpate_device; /* opaque: one tool on one model */

/* The library's version. Any argument may be NULL. */
PALPATE_DEVICE_API void palpate_device_version(int* major, int* minor, int* patch);
/* "ok", "none", "argument", ...: a status's name (a static string). */
PALPATE_DEVICE_API const char* palpate_device_status_name(int status);
/* The steady clock (CLOCK_MONOTONIC), ns: the clock of every *_ns here. */
PALPATE_DEVICE_API int64_t palpate_device_now_ns(void);

/* Every option to its default (above); model_id and tool_id NULL. */
PALPATE_DEVICE_API void palpate_device_options_init(palpate_device_options* options);

/* Joins DDS, waits (options->timeout_s) for the model's description and for
 * palpated's tool topics, and opens the tool: *tool is the new handle, NULL
 * on failure. Blocks. */
PALPATE_DEVICE_API int palpate_device_open(const palpate_device_options* options,
                                           palpate_device** tool, char* error, size_t error_size);

/* The device's pose now (device frame: position m, orientation w x y z
 * handle -> device, jaw opening rad): the pose palpate_device_force()
 * renders at, and sent to palpated when one is due (at most pose_rate_hz:
 * the first call, then whenever now_ns reaches the next period). now_ns: the
 * device's time on palpate_device_now_ns()'s clock, or 0 for now.
 * *sent_sequence (may be NULL) is the sent pose's sequence, 0 when none was
 * sent. Never blocks, allocates nothing. */
PALPATE_DEVICE_API int palpate_device_set_pose(palpate_device* tool, int64_t now_ns,
                                               const double position_m[3],
                                               const double orientation_wxyz[4], double jaw_rad,
                                               uint64_t* sent_sequence, char* error,
                                               size_t error_size);

/* What to render now at the last pose given (device frame: force on the
 * hand N, torque about the hinge N·m): takes the answers that came and
 * renders the newest one's local model (zero before any answer, while
 * palpated is lost, and after the hold-and-ramp when answers stop). now_ns
 * as for set_pose. Never blocks, allocates nothing. */
PALPATE_DEVICE_API int palpate_device_force(palpate_device* tool, int64_t now_ns, double force_n[3],
                                            double torque_nm[3], char* error, size_t error_size);

/* What the handle knows now (state->struct_size set by the caller). Polls
 * palpated's heartbeat. Never blocks, allocates nothing. */
PALPATE_DEVICE_API int palpate_device_get_state(palpate_device* tool, palpate_device_state* state,
                                                char* error, size_t error_size);

/* The next of the answers taken, oldest first (the handle keeps the last
 * 256): PALPATE_DEVICE_OK with *answer filled, PALPATE_DEVICE_NONE when
 * there is none. Never blocks, allocates nothing. */
PALPATE_DEVICE_API int palpate_device_next_answer(palpate_device* tool,
                                                  palpate_device_answer* answer, char* error,
                                                  size_t error_size);

/* The next event of this tool's session, or why palpated refused a pose:
 * PALPATE_DEVICE_OK with *event filled, PALPATE_DEVICE_NONE when there is
 * none. Never blocks; allocates only when events came. */
PALPATE_DEVICE_API int palpate_device_next_event(palpate_device* tool, palpate_device_event* event,
                                                 char* error, size_t error_size);

/* For a program without a servo thread of its own (a simulated device,
 * palpate-pliers): blocks until the answer to the newest pose sent has been
 * taken (PALPATE_DEVICE_OK, at once if it already was) or until deadline_ns
 * (PALPATE_DEVICE_NONE). Never call it from a servo callback. */
PALPATE_DEVICE_API int palpate_device_wait(palpate_device* tool, int64_t deadline_ns, char* error,
                                           size_t error_size);

/* The model's surface (model->struct_size set by the caller). */
PALPATE_DEVICE_API int palpate_device_get_model(palpate_device* tool, palpate_device_model* model,
                                                char* error, size_t error_size);

/* Ends the tool's session: palpated lets go at once (no watchdog ramp) and
 * sends an ENDED event (next_event); the next pose starts a new session.
 * Waits up to timeout_s for palpated's acknowledgement
 * (PALPATE_DEVICE_E_TIMEOUT without it). Nothing to do (OK) when no pose was
 * sent since the last end. Blocks. */
PALPATE_DEVICE_API int palpate_device_end_session(palpate_device* tool, double timeout_s,
                                                  char* error, size_t error_size);

/* Ends the session if one is live (waiting up to 1 s), leaves DDS and frees
 * the handle. NULL is allowed. Blocks. */
PALPATE_DEVICE_API void palpate_device_close(palpate_device* tool);

#ifdef __cplusplus
}
#endif

#endif /* PALPATE_DEVICE_H */
