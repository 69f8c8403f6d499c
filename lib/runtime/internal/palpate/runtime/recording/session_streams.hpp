#pragma once
// Private to palpate_runtime: what a session file holds and how it is laid
// out (docs/session-recording.md): the format's name and version, each
// tool's streams (ticks, contacts, what the device rendered) and summary,
// the events, the open file. session_recorder.cpp owns the rings and the
// writer thread that feed them.

#include <fmt/format.h>
#include <hdf5.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include "palpate/file/detail/hdf5_support.hpp"
#include "palpate/runtime/recording/session_columns.hpp"
#include "palpate/runtime/session_recorder.hpp"

namespace palpate::detail {

using hdf5::check;
using hdf5::Handle;
using hdf5::write_double_attribute;
using hdf5::write_int64_attribute;
using hdf5::write_int_attribute;
using hdf5::write_string_attribute;
using hdf5::write_strings_attribute;
using hdf5::write_uint64_attribute;

constexpr const char* kFormatName = "palpate-session";
constexpr int kFormatVersion = 1;
// Rows per chunk: about a second of one tool at 1 kHz; contacts are denser.
constexpr hsize_t kTickChunk = 1024;
constexpr hsize_t kContactChunk = 4096;
constexpr hsize_t kEventChunk = 256;
constexpr hsize_t kRenderedChunk = 4096;

// "2026-11-21T18:00:00.123Z" from nanoseconds since 1970 (UTC).
inline std::string iso_utc(std::int64_t unix_ns) {
  std::int64_t s = unix_ns / 1'000'000'000;
  std::int64_t ns = unix_ns % 1'000'000'000;
  if (ns < 0) {
    --s;
    ns += 1'000'000'000;
  }
  const std::time_t t = static_cast<std::time_t>(s);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  return fmt::format("{}.{:03d}Z", buf, ns / 1'000'000);
}

inline std::int64_t unix_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The assessment of one tool's gesture, accumulated tick by tick. The
// definitions are those of docs/session-recording.md (scripts/session_report.py
// computes the same from the datasets): a tick's state and force hold until
// the tool's next tick, so the interval t_k − t_{k−1} counts as "in contact"
// when tick k−1 was not free (a non-increasing time adds nothing).
struct ToolSummary {
  std::uint64_t ticks = 0;
  std::uint64_t grasps = 0;  // ticks grasping whose previous tick was not
  std::uint64_t truncated_contact_ticks = 0;
  double first_time_s = 0, last_time_s = 0;
  double time_in_contact_s = 0, time_grasping_s = 0;
  double force_time_in_contact_ns = 0;  // ∫ |f| dt over contact, N·s
  double max_force_n = 0, max_grip_n = 0, path_length_m = 0;
  ToolState last_state = ToolState::kFree;
  double last_force_n = 0;
  double last_position_m[3]{};

  void add(const ToolTickRecord& t) {
    const double force = std::hypot(t.force_n[0], t.force_n[1], t.force_n[2]);
    if (ticks == 0) {
      first_time_s = t.time_s;
    } else {
      const double dt = std::max(0.0, t.time_s - last_time_s);
      if (last_state != ToolState::kFree) {
        time_in_contact_s += dt;
        force_time_in_contact_ns += last_force_n * dt;
      }
      if (last_state == ToolState::kGrasping) time_grasping_s += dt;
      path_length_m +=
          std::hypot(t.position_m[0] - last_position_m[0], t.position_m[1] - last_position_m[1],
                     t.position_m[2] - last_position_m[2]);
    }
    if (t.state == ToolState::kGrasping && (ticks == 0 || last_state != ToolState::kGrasping))
      ++grasps;
    max_force_n = std::max(max_force_n, force);
    max_grip_n = std::max(max_grip_n, t.grip_n);
    last_state = t.state;
    last_force_n = force;
    std::copy_n(t.position_m, 3, last_position_m);
    last_time_s = t.time_s;
    ++ticks;
  }

  void write(hid_t group, std::uint64_t dropped_ticks) const {
    write_uint64_attribute(group, "ticks", ticks);
    write_double_attribute(group, "duration_s", ticks > 0 ? last_time_s - first_time_s : 0.0);
    write_double_attribute(group, "time_in_contact_s", time_in_contact_s);
    write_double_attribute(group, "time_grasping_s", time_grasping_s);
    write_double_attribute(group, "max_force_n", max_force_n);
    write_double_attribute(
        group, "mean_force_in_contact_n",
        time_in_contact_s > 0 ? force_time_in_contact_ns / time_in_contact_s : 0.0);
    write_double_attribute(group, "max_grip_n", max_grip_n);
    write_double_attribute(group, "path_length_m", path_length_m);
    write_uint64_attribute(group, "grasps", grasps);
    write_uint64_attribute(group, "dropped_ticks", dropped_ticks);
    write_uint64_attribute(group, "truncated_contact_ticks", truncated_contact_ticks);
  }
};

const char* tip_name(TipShape tip) { return tip == TipShape::kSphere ? "sphere" : "capsule"; }

// /tools/<id>: one tool's geometry, samples, contacts and summary.
struct ToolStream {
  ToolStream(hid_t tools, const ToolGeometry& g, int index)
      : group(hdf5::group(tools, g.id)),
        time_s(group, "time_s", 1, kTickChunk, "s"),
        sequence(group, "sequence", 1, kTickChunk),
        send_time_ns(group, "send_time_ns", 1, kTickChunk, "ns"),
        position(group, "position", 3, kTickChunk, "m"),
        orientation(group, "orientation", 4, kTickChunk),
        jaw_angle(group, "jaw_angle", 1, kTickChunk, "rad"),
        force(group, "force", 3, kTickChunk, "N"),
        torque(group, "torque", 3, kTickChunk, "N·m"),
        grip(group, "grip", 1, kTickChunk, "N"),
        state(group, "state", 1, kTickChunk),
        watchdog(group, "watchdog", 1, kTickChunk),
        force_limited(group, "force_limited", 1, kTickChunk),
        held(group, "held", 1, kTickChunk),
        compute_ns(group, "compute_ns", 1, kTickChunk, "ns"),
        contact_start(group, "contact_start", 1, kTickChunk),
        contact_count(group, "contact_count", 1, kTickChunk),
        contacts(hdf5::group(group, "contacts")),
        contact_vertex(contacts, "vertex", 1, kContactChunk),
        contact_force(contacts, "force", 3, kContactChunk, "N"),
        rendered(hdf5::group(group, "rendered")),
        rendered_time_ns(rendered, "time_ns", 1, kRenderedChunk, "ns"),
        rendered_answer(rendered, "answer_sequence", 1, kRenderedChunk),
        rendered_position(rendered, "position", 3, kRenderedChunk, "m"),
        rendered_force(rendered, "force", 3, kRenderedChunk, "N"),
        rendered_damping(rendered, "damping", 1, kRenderedChunk, "N·s/m") {
    write_int_attribute(group, "index", index);
    write_string_attribute(group, "tip", tip_name(g.tip));
    write_double_attribute(group, "tip_radius_m", g.tip_radius_m);
    write_double_attribute(group, "tip_length_m", g.tip_length_m);
    write_double_attribute(group, "friction", g.friction);
    write_double_attribute(group, "jaw_length_m", g.jaw_length_m);
    write_double_attribute(group, "jaw_width_m", g.jaw_width_m);
    write_double_attribute(group, "grasp_angle_rad", g.grasp_angle_rad);
    write_double_attribute(group, "release_angle_rad", g.release_angle_rad);
    write_double_attribute(group, "max_jaw_angle_rad", g.max_jaw_angle_rad);
    write_double_attribute(group, "force_limit_n", g.force_limit_n);
    write_double_attribute(group, "max_force_rate_n_per_s", g.max_force_rate_n_per_s);
    write_string_attribute(orientation.id(), "order", "w x y z");
    std::vector<std::string> names;
    for (auto s : {ToolState::kFree, ToolState::kTouching, ToolState::kGrasping})
      names.emplace_back(tool_state_name(s));
    write_strings_attribute(state.id(), "names", names);
  }

  // Stages tick @p t, whose contacts are read by @p contact(i) → (vertex id, force[3]).
  template <typename Contact>
  void stage(const ToolTickRecord& t, std::uint32_t count, bool truncated, Contact&& contact) {
    time_s.stage(t.time_s);
    sequence.stage(t.sequence);
    send_time_ns.stage(t.send_time_ns);
    position.stage(t.position_m);
    orientation.stage(t.orientation_wxyz);
    jaw_angle.stage(t.jaw_angle_rad);
    force.stage(t.force_n);
    torque.stage(t.torque_nm);
    grip.stage(t.grip_n);
    state.stage(static_cast<std::int8_t>(t.state));
    watchdog.stage(static_cast<std::uint8_t>(t.watchdog));
    force_limited.stage(static_cast<std::uint8_t>(t.force_limited));
    held.stage(t.held);
    compute_ns.stage(t.compute_ns);
    contact_start.stage(contacts_total);
    contact_count.stage(count);
    for (std::uint32_t i = 0; i < count; ++i) {
      const auto [vertex, f] = contact(i);
      contact_vertex.stage(vertex);
      contact_force.stage(f);
    }
    contacts_total += count;
    summary.add(t);
    if (truncated) ++summary.truncated_contact_ticks;
  }

  void write() {
    time_s.write();
    sequence.write();
    send_time_ns.write();
    position.write();
    orientation.write();
    jaw_angle.write();
    force.write();
    torque.write();
    grip.write();
    state.write();
    watchdog.write();
    force_limited.write();
    held.write();
    compute_ns.write();
    contact_start.write();
    contact_count.write();
    contact_vertex.write();
    contact_force.write();
    rendered_time_ns.write();
    rendered_answer.write();
    rendered_position.write();
    rendered_force.write();
    rendered_damping.write();
  }

  void stage(const RenderedRecord& r) {
    rendered_time_ns.stage(r.time_ns);
    rendered_answer.stage(r.answer_sequence);
    rendered_position.stage(r.position_m);
    rendered_force.stage(r.force_n);
    rendered_damping.stage(r.damping);
    ++rendered_steps;
    const double magnitude = std::sqrt(r.force_n[0] * r.force_n[0] + r.force_n[1] * r.force_n[1] +
                                       r.force_n[2] * r.force_n[2]);
    max_rendered_force = std::max(max_rendered_force, magnitude);
    max_damping = std::max(max_damping, r.damping);
  }

  Handle group;
  Column<double> time_s;
  Column<std::uint64_t> sequence;
  Column<std::int64_t> send_time_ns;
  Column<double> position, orientation, jaw_angle, force, torque, grip;
  Column<std::int8_t> state;
  Column<std::uint8_t> watchdog, force_limited;
  Column<std::uint32_t> held;
  Column<std::uint64_t> compute_ns, contact_start;
  Column<std::uint32_t> contact_count;
  Handle contacts;
  Column<std::uint32_t> contact_vertex;
  Column<double> contact_force;
  Handle rendered;
  Column<std::int64_t> rendered_time_ns;
  Column<std::uint64_t> rendered_answer;
  Column<double> rendered_position, rendered_force, rendered_damping;
  std::uint64_t contacts_total = 0;
  ToolSummary summary;
  std::uint64_t rendered_steps = 0;
  double max_rendered_force = 0, max_damping = 0;
};

// /events: the tools' state changes, one row each.
struct EventStream {
  explicit EventStream(hid_t file)
      : group(hdf5::group(file, "events")),
        time_s(group, "time_s", 1, kEventChunk, "s"),
        tool(group, "tool", 1, kEventChunk),
        kind(group, "kind", 1, kEventChunk),
        pose_sequence(group, "pose_sequence", 1, kEventChunk) {
    std::vector<std::string> names;
    for (int k = 0; k <= static_cast<int>(kLastToolEventKind); ++k)
      names.emplace_back(tool_event_name(static_cast<ToolEventKind>(k)));
    write_strings_attribute(kind.id(), "names", names);
  }

  void write() {
    time_s.write();
    tool.write();
    kind.write();
    pose_sequence.write();
  }

  Handle group;
  Column<double> time_s;
  Column<std::int32_t> tool, kind;
  Column<std::uint64_t> pose_sequence;
  std::uint64_t count = 0;
};

// The open file; members close in reverse order, the file last.
struct SessionFile {
  Handle file;
  std::vector<std::unique_ptr<ToolStream>> tools;
  std::unique_ptr<EventStream> events;
  std::uint64_t ticks = 0;  // staged so far
};

}  // namespace palpate::detail
