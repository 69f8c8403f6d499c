// The C API for haptic devices (palpate/device.h, docs/devices.md): a
// palpate::ToolClient per handle (device_handle.hpp), behind extern "C"
// functions that check their arguments, catch every exception and turn it
// into a status and one line of message, and copy into their caller's
// structs.
//
// The servo calls (set_pose, force, get_state, next_answer) allocate
// nothing: the tool is opened in palpate_device_open(), the answers are
// kept in fixed rings, and messages are written with snprintf into the
// caller's buffer.

#include "palpate/device.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <thread>

#include "device_handle.hpp"
#include "palpate/core/error.hpp"
#include "palpate/core/ids.hpp"
#include "palpate/transport/tool_client.hpp"

namespace {

using Clock = std::chrono::steady_clock;

/// Writes one line into the caller's buffer (when there is one) and
/// returns @p status. Allocates nothing.
[[gnu::format(printf, 4, 5)]] int fail(char* error, std::size_t error_size, int status,
                                       const char* format, ...) {
  if (error != nullptr && error_size > 0) {
    va_list args;
    va_start(args, format);
    std::vsnprintf(error, error_size, format, args);
    va_end(args);
  }
  return status;
}

int ok(char* error, std::size_t error_size) {
  if (error != nullptr && error_size > 0) error[0] = '\0';
  return PALPATE_DEVICE_OK;
}

bool finite(const double* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

/// A unit quaternion from w x y z, or nullopt when it is not finite or is
/// (nearly) zero.
std::optional<Eigen::Quaterniond> unit_quaternion(const double* wxyz) {
  if (!finite(wxyz, 4)) return std::nullopt;
  const Eigen::Quaterniond q(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
  if (!(q.norm() > 1e-9)) return std::nullopt;
  return q.normalized();
}

/// Copies the first @p caller_size bytes of @p full into @p out (a struct
/// the caller may know in an older, shorter version), its struct_size set.
template <typename T>
void copy_out(const T& full, T* out, std::uint32_t caller_size) {
  T copy = full;
  copy.struct_size = std::min<std::uint32_t>(caller_size, sizeof(T));
  std::memcpy(out, &copy, copy.struct_size);
}

/// The smallest struct_size accepted: the struct as version 1.0 has it.
constexpr std::uint32_t kStateV1 = sizeof(palpate_device_state);
constexpr std::uint32_t kAnswerV1 = sizeof(palpate_device_answer);
constexpr std::uint32_t kEventV1 = sizeof(palpate_device_event);
constexpr std::uint32_t kModelV1 = offsetof(palpate_device_model, cut_region);
constexpr std::uint32_t kOptionsV1 = sizeof(palpate_device_options);

std::int64_t now_or(std::int64_t now_ns) {
  return now_ns != 0 ? now_ns : palpate::ToolClient::now_ns();
}

/// Runs @p body, turning any exception into a status and its message.
template <typename Body>
int guarded(char* error, std::size_t error_size, int input_status, Body body) noexcept {
  try {
    return body();
  } catch (const palpate::InputError& e) {
    return fail(error, error_size, input_status, "%s", e.what());
  } catch (const palpate::SystemError& e) {
    return fail(error, error_size, PALPATE_DEVICE_E_DDS, "%s", e.what());
  } catch (const std::bad_alloc&) {
    return fail(error, error_size, PALPATE_DEVICE_E_INTERNAL, "out of memory");
  } catch (const std::exception& e) {
    return fail(error, error_size, PALPATE_DEVICE_E_INTERNAL, "%s", e.what());
  } catch (...) {
    return fail(error, error_size, PALPATE_DEVICE_E_INTERNAL, "unknown exception");
  }
}

#define PALPATE_DEVICE_NEED(pointer)                                                               \
  do {                                                                                             \
    if ((pointer) == nullptr)                                                                      \
      return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT, "%s: %s is NULL", what, #pointer); \
  } while (false)
// A caller's struct older than version 1 of it (struct_size too small).
#define PALPATE_DEVICE_NEED_SIZE(pointer, minimum, type)                                       \
  do {                                                                                         \
    if ((pointer)->struct_size < (minimum))                                                    \
      return fail(error, error_size, PALPATE_DEVICE_E_VERSION,                                 \
                  "%s: %s->struct_size %u: expected at least %u (sizeof(%s))", what, #pointer, \
                  (pointer)->struct_size, (minimum), #type);                                   \
  } while (false)

/// The options after checking them, or a status and message.
int check_options(const palpate_device_options& o, char* error, std::size_t error_size) {
  const char* what = "palpate_device_open";
  auto bad_id = [&](const char* kind, const char* id) {
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: %s id '%.80s': expected 1 to 63 characters among A-Z a-z 0-9 _ - .", what,
                kind, id);
  };
  if (o.model_id == nullptr)
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->model_id is NULL (the id of a model palpated serves)", what);
  if (o.tool_id == nullptr)
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->tool_id is NULL (one of palpated's tools, e.g. left)", what);
  if (!palpate::is_valid_id(o.model_id)) return bad_id("model", o.model_id);
  if (!palpate::is_valid_id(o.tool_id)) return bad_id("tool", o.tool_id);
  auto range = [&](const char* name, double v, double lo, double hi) {
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->%s = %g: expected %g to %g", what, name, v, lo, hi);
  };
  if (!(o.pose_rate_hz >= 1 && o.pose_rate_hz <= 20000))
    return range("pose_rate_hz", o.pose_rate_hz, 1, 20000);
  if (!(o.timeout_s >= 0 && o.timeout_s <= 3600)) return range("timeout_s", o.timeout_s, 0, 3600);
  if (!(o.max_damping_n_s_per_m >= 0 && o.max_damping_n_s_per_m <= 1e6))
    return range("max_damping_n_s_per_m", o.max_damping_n_s_per_m, 0, 1e6);
  if (!(o.max_angular_damping_nm_s_per_rad >= 0 && o.max_angular_damping_nm_s_per_rad <= 1e3))
    return range("max_angular_damping_nm_s_per_rad", o.max_angular_damping_nm_s_per_rad, 0, 1e3);
  if (!(o.hold_s >= 0 && o.hold_s <= 10)) return range("hold_s", o.hold_s, 0, 10);
  if (!(o.ramp_s >= 0 && o.ramp_s <= 10)) return range("ramp_s", o.ramp_s, 0, 10);
  if (!(o.frame.scale > 0 && o.frame.scale <= 1e3))
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->frame.scale = %g: expected more than 0, at most 1000 (model metres "
                "per device metre)",
                what, o.frame.scale);
  if (!(o.frame.force_scale >= 0 && o.frame.force_scale <= 1e3))
    return range("frame.force_scale", o.frame.force_scale, 0, 1e3);
  if (!finite(o.frame.offset_m, 3))
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->frame.offset_m is not finite", what);
  if (!unit_quaternion(o.frame.rotation_wxyz))
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->frame.rotation_wxyz is not a rotation (zero or not finite)", what);
  if (!unit_quaternion(o.frame.handle_to_tool_wxyz))
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: options->frame.handle_to_tool_wxyz is not a rotation (zero or not finite)",
                what);
  return PALPATE_DEVICE_OK;
}

}  // namespace

extern "C" {

void palpate_device_version(int* major, int* minor, int* patch) {
  if (major != nullptr) *major = PALPATE_DEVICE_VERSION_MAJOR;
  if (minor != nullptr) *minor = PALPATE_DEVICE_VERSION_MINOR;
  if (patch != nullptr) *patch = PALPATE_DEVICE_VERSION_PATCH;
}

const char* palpate_device_status_name(int status) {
  switch (status) {
    case PALPATE_DEVICE_OK:
      return "ok";
    case PALPATE_DEVICE_NONE:
      return "none";
    case PALPATE_DEVICE_E_ARGUMENT:
      return "argument";
    case PALPATE_DEVICE_E_VERSION:
      return "version";
    case PALPATE_DEVICE_E_NO_PALPATED:
      return "no palpated";
    case PALPATE_DEVICE_E_NO_MODEL:
      return "no model";
    case PALPATE_DEVICE_E_NO_TOOLS:
      return "no tools";
    case PALPATE_DEVICE_E_CONFIG:
      return "configuration";
    case PALPATE_DEVICE_E_DDS:
      return "dds";
    case PALPATE_DEVICE_E_TIMEOUT:
      return "timeout";
    case PALPATE_DEVICE_E_INTERNAL:
      return "internal";
    default:
      return "unknown status";
  }
}

int64_t palpate_device_now_ns(void) { return palpate::ToolClient::now_ns(); }

void palpate_device_options_init(palpate_device_options* options) {
  if (options == nullptr) return;
  *options = palpate_device_options{};
  options->struct_size = sizeof *options;
  options->pose_rate_hz = 1000;
  options->timeout_s = 10;
  const palpate::RenderSettings render;
  options->local_model = render.local_model ? 1 : 0;
  options->passivity = render.passivity ? 1 : 0;
  options->max_damping_n_s_per_m = render.max_damping_n_s_per_m;
  options->max_angular_damping_nm_s_per_rad = render.max_angular_damping_nm_s_per_rad;
  options->hold_s = render.hold_s;
  options->ramp_s = render.ramp_s;
  options->frame.scale = 1;
  options->frame.rotation_wxyz[0] = 1;
  options->frame.handle_to_tool_wxyz[0] = 1;
  options->frame.force_scale = 1;
}

int palpate_device_open(const palpate_device_options* options, palpate_device** tool, char* error,
                        size_t error_size) {
  const char* what = "palpate_device_open";
  PALPATE_DEVICE_NEED(tool);
  *tool = nullptr;
  PALPATE_DEVICE_NEED(options);
  if (options->struct_size < kOptionsV1)
    return fail(error, error_size, PALPATE_DEVICE_E_VERSION,
                "%s: options->struct_size %u: expected at least %u (fill the options with "
                "palpate_device_options_init())",
                what, options->struct_size, kOptionsV1);
  // A caller built against a newer header may give a longer struct: its
  // fields beyond this library's are not known here.
  palpate_device_options o;
  std::memcpy(&o, options, sizeof o);
  if (const int status = check_options(o, error, error_size); status != PALPATE_DEVICE_OK)
    return status;
  return guarded(error, error_size, PALPATE_DEVICE_E_CONFIG, [&]() -> int {
    palpate::ToolClientOptions client_options;
    client_options.domain_id = o.domain_id;
    client_options.dds_config = o.dds_config != nullptr ? o.dds_config : "";
    client_options.busy_wait = o.busy_wait != 0;
    client_options.feedback_timeout = std::chrono::milliseconds(std::llround(o.hold_s * 1e3));
    client_options.feedback_ramp = std::chrono::milliseconds(std::llround(o.ramp_s * 1e3));
    client_options.render.local_model = o.local_model != 0;
    client_options.render.passivity = o.passivity != 0;
    client_options.render.max_damping_n_s_per_m = o.max_damping_n_s_per_m;
    client_options.render.max_angular_damping_nm_s_per_rad = o.max_angular_damping_nm_s_per_rad;
    client_options.report_rendering = o.report_rendering != 0;
    auto d = std::make_unique<palpate_device>(client_options);
    d->model_id = o.model_id;
    d->tool_id = o.tool_id;
    d->scale = o.frame.scale;
    d->force_scale = o.frame.force_scale;
    d->rotation = *unit_quaternion(o.frame.rotation_wxyz);
    d->handle_to_tool = *unit_quaternion(o.frame.handle_to_tool_wxyz);
    d->offset = Eigen::Vector3d(o.frame.offset_m[0], o.frame.offset_m[1], o.frame.offset_m[2]);
    d->period_ns = std::max<std::int64_t>(1, std::llround(1e9 / o.pose_rate_hz));
    d->sequence = d->first_sequence =
        o.first_sequence != 0 ? o.first_sequence
                              : static_cast<std::uint64_t>(palpate::ToolClient::now_ns() / 1000);
    d->next_sequence = d->sequence + 1;

    const auto timeout = std::chrono::milliseconds(std::llround(o.timeout_s * 1e3));
    const auto give_up = Clock::now() + timeout;
    auto model = d->client.wait_for_model(d->model_id, timeout);
    if (!model) {
      const auto seen = d->client.models_seen();
      if (seen.empty())
        return fail(error, error_size, PALPATE_DEVICE_E_NO_PALPATED,
                    "no palpated within %g s: no model description on DDS domain %u (is palpated "
                    "running, in this network namespace?)",
                    o.timeout_s, o.domain_id);
      std::string ids;
      for (const auto& id : seen) ids += (ids.empty() ? "" : ", ") + id;
      return fail(error, error_size, PALPATE_DEVICE_E_NO_MODEL,
                  "model '%s' is not served by palpated; served: %s", d->model_id.c_str(),
                  ids.c_str());
    }
    d->model = std::move(*model);
    // The tool's readers before the match: the answers to its first poses
    // are then not lost while they are matched.
    d->client.open_tool(d->tool_id);
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(give_up - Clock::now());
    if (!d->client.wait_for_daemon(std::max(std::chrono::milliseconds(100), left)))
      return fail(error, error_size, PALPATE_DEVICE_E_NO_TOOLS,
                  "palpated serves model '%s' but reads no tool poses (or writes no feedback) "
                  "within %g s: is it a palpated with tools?",
                  d->model_id.c_str(), o.timeout_s);
    *tool = d.release();
    return ok(error, error_size);
  });
}

int palpate_device_set_pose(palpate_device* tool, int64_t now_ns, const double position_m[3],
                            const double orientation_wxyz[4], double jaw_rad,
                            uint64_t* sent_sequence, char* error, size_t error_size) {
  const char* what = "palpate_device_set_pose";
  if (sent_sequence != nullptr) *sent_sequence = 0;
  PALPATE_DEVICE_NEED(tool);
  PALPATE_DEVICE_NEED(position_m);
  PALPATE_DEVICE_NEED(orientation_wxyz);
  if (!finite(position_m, 3) || !std::isfinite(jaw_rad))
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: position (%g, %g, %g) m or jaw %g rad is not finite", what, position_m[0],
                position_m[1], position_m[2], jaw_rad);
  const auto handle = unit_quaternion(orientation_wxyz);
  if (!handle)
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: orientation (%g, %g, %g, %g) is not a rotation (zero or not finite)", what,
                orientation_wxyz[0], orientation_wxyz[1], orientation_wxyz[2], orientation_wxyz[3]);
  palpate_device& d = *tool;
  const Eigen::Vector3d x =
      d.offset +
      d.scale * (d.rotation * Eigen::Vector3d(position_m[0], position_m[1], position_m[2]));
  const Eigen::Quaterniond q = (d.rotation * *handle * d.handle_to_tool).normalized();
  d.position = {x.x(), x.y(), x.z()};
  d.orientation = {q.w(), q.x(), q.y(), q.z()};
  d.jaw = jaw_rad;
  d.has_pose = true;
  const std::int64_t now = now_or(now_ns);
  if (d.poses_sent > 0 && now < d.next_due_ns) return ok(error, error_size);
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    const std::uint64_t sequence = d.sequence + 1;
    d.last_send_ns =
        d.client.send_pose(d.tool_id, d.model_id, sequence, d.position, d.orientation, d.jaw);
    d.sequence = sequence;
    // The next pose one period after this one's due time, so that a device
    // whose ticks jitter still sends at the rate; never a burst to catch up.
    d.next_due_ns = d.poses_sent == 0 ? now + d.period_ns : d.next_due_ns + d.period_ns;
    if (d.next_due_ns <= now) d.next_due_ns = now + d.period_ns;
    ++d.poses_sent;
    d.session_live = true;
    if (sent_sequence != nullptr) *sent_sequence = sequence;
    return ok(error, error_size);
  });
}

int palpate_device_force(palpate_device* tool, int64_t now_ns, double force_n[3],
                         double torque_nm[3], char* error, size_t error_size) {
  const char* what = "palpate_device_force";
  PALPATE_DEVICE_NEED(tool);
  PALPATE_DEVICE_NEED(force_n);
  palpate_device& d = *tool;
  auto out = [&] {
    for (int i = 0; i < 3; ++i) {
      force_n[i] = d.rendered_force[i];
      if (torque_nm != nullptr) torque_nm[i] = d.rendered_torque[i];
    }
  };
  if (!d.has_pose) {
    d.rendered = palpate::RenderedWrench{};
    d.rendered_force.setZero();
    d.rendered_torque.setZero();
    out();
    return ok(error, error_size);
  }
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    d.rendered = d.client.render(d.tool_id, d.position, d.orientation, now_or(now_ns));
    d.drain();
    // To the device's frame: F_device = k Rᵀ F_model (and τ likewise).
    const Eigen::Quaterniond back = d.rotation.conjugate();
    d.rendered_force = d.force_scale * (back * d.rendered.force_n);
    d.rendered_torque = d.force_scale * (back * d.rendered.torque_nm);
    out();
    return ok(error, error_size);
  });
}

int palpate_device_get_state(palpate_device* tool, palpate_device_state* state, char* error,
                             size_t error_size) {
  const char* what = "palpate_device_get_state";
  PALPATE_DEVICE_NEED(tool);
  PALPATE_DEVICE_NEED(state);
  PALPATE_DEVICE_NEED_SIZE(state, kStateV1, palpate_device_state);
  palpate_device& d = *tool;
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    palpate_device_state s{};
    const palpate::DaemonPresence presence = d.client.daemon_presence();
    s.daemon = presence.state == palpate::DaemonState::kPresent ? PALPATE_DEVICE_DAEMON_PRESENT
               : presence.state == palpate::DaemonState::kLost  ? PALPATE_DEVICE_DAEMON_LOST
                                                                : PALPATE_DEVICE_DAEMON_UNKNOWN;
    s.daemon_losses = presence.losses;
    s.daemon_restarts = presence.restarts;
    s.daemon_silent_s = presence.silent_s;
    s.daemon_uptime_s = presence.uptime_s;
    s.first_sequence = d.first_sequence + 1;
    s.last_sequence = d.poses_sent > 0 ? d.sequence : 0;
    s.last_send_time_ns = d.last_send_ns;
    s.poses_sent = d.poses_sent;
    s.answers_taken = d.answers_taken;
    s.answers_dropped = d.answers_dropped;
    s.has_answer = d.has_answer ? 1 : 0;
    s.answer_age_s = -1;
    if (d.has_answer) {
      const palpate::ToolFeedbackSample& a = d.newest;
      s.answer_sequence = a.sequence;
      s.tool_state = static_cast<int>(a.state);
      s.contacts = a.contacts;
      s.grip_n = a.grip_n;
      std::copy(a.force_n.begin(), a.force_n.end(), s.answer_force_n);
      std::copy(a.torque_nm.begin(), a.torque_nm.end(), s.answer_torque_nm);
      s.force_limited = a.force_limited ? 1 : 0;
      s.watchdog = a.watchdog ? 1 : 0;
      s.round_trip_s = static_cast<double>(a.round_trip_ns()) * 1e-9;
      s.answer_age_s =
          static_cast<double>(palpate::ToolClient::now_ns() - a.receive_time_ns) * 1e-9;
    }
    for (int i = 0; i < 3; ++i) {
      s.rendered_force_n[i] = d.rendered_force[i];
      s.rendered_torque_nm[i] = d.rendered_torque[i];
    }
    s.damping_n_s_per_m = d.rendered.damping;
    s.energy_j = d.rendered.energy_j;
    s.render_limited = d.rendered.limited ? 1 : 0;
    s.render_scale = d.rendered.scale;
    copy_out(s, state, state->struct_size);
    return ok(error, error_size);
  });
}

int palpate_device_next_answer(palpate_device* tool, palpate_device_answer* answer, char* error,
                               size_t error_size) {
  const char* what = "palpate_device_next_answer";
  PALPATE_DEVICE_NEED(tool);
  PALPATE_DEVICE_NEED(answer);
  PALPATE_DEVICE_NEED_SIZE(answer, kAnswerV1, palpate_device_answer);
  palpate_device& d = *tool;
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    d.drain();
    if (d.answers.empty()) return fail(error, error_size, PALPATE_DEVICE_NONE, "no answer");
    copy_out(d.answers.front(), answer, answer->struct_size);
    d.answers.pop();
    return ok(error, error_size);
  });
}

int palpate_device_next_event(palpate_device* tool, palpate_device_event* event, char* error,
                              size_t error_size) {
  const char* what = "palpate_device_next_event";
  PALPATE_DEVICE_NEED(tool);
  PALPATE_DEVICE_NEED(event);
  PALPATE_DEVICE_NEED_SIZE(event, kEventV1, palpate_device_event);
  palpate_device& d = *tool;
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    if (d.events.empty()) {
      // This session's only: not another model's, nor an earlier run's
      // (its watchdog, say), whose sequences are below this handle's.
      for (const auto& e : d.client.take_events()) {
        if (e.model_id != d.model_id || e.pose_sequence <= d.first_sequence) continue;
        palpate_device_event out{};
        out.struct_size = sizeof out;
        out.kind = static_cast<int>(e.kind);
        out.pose_sequence = e.pose_sequence;
        out.held_points = e.held_vertices;
        out.receive_time_ns = e.receive_time_ns;
        std::snprintf(out.message, sizeof out.message, "%s", palpate::tool_event_name(e.kind));
        d.events.push(out);
      }
      for (const auto& n : d.client.take_notices()) {
        if (n.tool_id != d.tool_id || n.model_id != d.model_id ||
            n.pose_sequence <= d.first_sequence)
          continue;
        palpate_device_event out{};
        out.struct_size = sizeof out;
        out.kind = PALPATE_DEVICE_EVENT_REFUSED;
        out.pose_sequence = n.pose_sequence;
        out.receive_time_ns = n.receive_time_ns;
        std::snprintf(out.message, sizeof out.message, "%s", n.message.c_str());
        d.events.push(out);
      }
    }
    if (d.events.empty()) return fail(error, error_size, PALPATE_DEVICE_NONE, "no event");
    copy_out(d.events.front(), event, event->struct_size);
    d.events.pop();
    return ok(error, error_size);
  });
}

int palpate_device_wait(palpate_device* tool, int64_t deadline_ns, char* error, size_t error_size) {
  const char* what = "palpate_device_wait";
  PALPATE_DEVICE_NEED(tool);
  palpate_device& d = *tool;
  const auto deadline = Clock::time_point(std::chrono::nanoseconds(deadline_ns));
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    if (d.poses_sent == 0) {
      std::this_thread::sleep_until(deadline);
      return fail(error, error_size, PALPATE_DEVICE_NONE, "no pose sent");
    }
    d.drain();
    if (d.has_answer && d.newest.sequence >= d.sequence) return ok(error, error_size);
    const auto s = d.client.wait_feedback(d.tool_id, d.sequence, deadline);
    if (s) {
      d.took(*s);
      d.next_sequence = std::max(d.next_sequence, s->sequence + 1);
    }
    d.drain();
    if (s) return ok(error, error_size);
    return fail(error, error_size, PALPATE_DEVICE_NONE, "no answer before the deadline");
  });
}

int palpate_device_get_model(palpate_device* tool, palpate_device_model* model, char* error,
                             size_t error_size) {
  const char* what = "palpate_device_get_model";
  PALPATE_DEVICE_NEED(tool);
  PALPATE_DEVICE_NEED(model);
  PALPATE_DEVICE_NEED_SIZE(model, kModelV1, palpate_device_model);
  const palpate::ModelInfo& m = tool->model;
  palpate_device_model out{};
  out.model_id = m.model_id.c_str();
  out.mechanics = m.mechanics.c_str();
  out.compliance_vertex_count = static_cast<uint32_t>(m.surface.compliance_vertex_count);
  out.vertex_count = static_cast<uint32_t>(m.surface.vertex_ids.size());
  out.triangle_count = static_cast<uint32_t>(m.surface.triangles.size() / 3);
  out.vertex_ids = m.surface.vertex_ids.data();
  out.rest_positions_m = m.surface.rest_positions_m.data();
  out.triangles = m.surface.triangles.data();
  out.cut_region = m.cut_region.c_str();
  copy_out(out, model, model->struct_size);
  return ok(error, error_size);
}

int palpate_device_end_session(palpate_device* tool, double timeout_s, char* error,
                               size_t error_size) {
  const char* what = "palpate_device_end_session";
  PALPATE_DEVICE_NEED(tool);
  if (!(timeout_s >= 0 && timeout_s <= 3600))
    return fail(error, error_size, PALPATE_DEVICE_E_ARGUMENT,
                "%s: timeout_s = %g: expected 0 to 3600", what, timeout_s);
  palpate_device& d = *tool;
  if (!d.session_live) return ok(error, error_size);
  return guarded(error, error_size, PALPATE_DEVICE_E_ARGUMENT, [&]() -> int {
    d.session_live = false;
    if (!d.client.end_session(d.tool_id, d.model_id,
                              std::chrono::milliseconds(std::llround(timeout_s * 1e3))))
      return fail(error, error_size, PALPATE_DEVICE_E_TIMEOUT,
                  "palpated did not acknowledge the end of tool '%s''s session within %g s",
                  d.tool_id.c_str(), timeout_s);
    return ok(error, error_size);
  });
}

void palpate_device_close(palpate_device* tool) {
  if (tool == nullptr) return;
  palpate_device_end_session(tool, 1.0, nullptr, 0);
  delete tool;
}

}  // extern "C"
