// The session recorder: what it writes, read back with the HDF5 C API (no
// code shared with the writer); the summaries against hand-computed values;
// full rings; errors; the .partial file's life, including a crash.

#include "palpate/runtime/session_recorder.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "palpate/core/error.hpp"
#include "support/allocation_counter.hpp"
#include "support/expect_error.hpp"
#include "support/h5_reader.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::H5Reader;
using testing::TempDir;

// Two tools that differ in every geometry field the file records.
SessionInfo two_tools() {
  SessionInfo info;
  info.model_id = "liver";
  info.model_file = "/data/liver-h12.h5";
  info.input_hash = "sha256:0123";
  info.daemon_id = "palpated-test";
  info.tools.resize(2);
  info.tools[0].id = "left";
  info.tools[1].id = "right";
  info.tools[1].tip = TipShape::kSphere;
  info.tools[1].tip_radius_m = 0.003;
  info.tools[1].force_limit_n = 5;
  info.contact.max_contacts_per_tool = 12;
  info.start_unix_ns = 1'700'000'000'123'456'789;  // 2023-11-14T22:13:20.123Z
  return info;
}

// The index of the first element where @p a and @p b differ, or -1.
template <typename T>
long first_difference(const std::vector<T>& a, const std::vector<T>& b) {
  if (a.size() != b.size()) return 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!(a[i] == b[i])) return static_cast<long>(i);
  return -1;
}

struct ToolExpectation {
  std::vector<double> time_s, position, orientation, jaw_angle, force, torque, grip;
  std::vector<std::uint64_t> sequence, compute_ns, contact_start;
  std::vector<std::int64_t> send_time_ns;
  std::vector<std::int8_t> state;
  std::vector<std::uint8_t> watchdog, force_limited;
  std::vector<std::uint32_t> held, contact_count, vertex;
  std::vector<double> contact_force;

  void add(const ToolTickRecord& t, const std::vector<std::uint32_t>& ids,
           const std::vector<double>& forces) {
    time_s.push_back(t.time_s);
    sequence.push_back(t.sequence);
    send_time_ns.push_back(t.send_time_ns);
    position.insert(position.end(), t.position_m, t.position_m + 3);
    orientation.insert(orientation.end(), t.orientation_wxyz, t.orientation_wxyz + 4);
    jaw_angle.push_back(t.jaw_angle_rad);
    force.insert(force.end(), t.force_n, t.force_n + 3);
    torque.insert(torque.end(), t.torque_nm, t.torque_nm + 3);
    grip.push_back(t.grip_n);
    state.push_back(static_cast<std::int8_t>(t.state));
    watchdog.push_back(t.watchdog);
    force_limited.push_back(t.force_limited);
    held.push_back(t.held);
    compute_ns.push_back(t.compute_ns);
    contact_start.push_back(vertex.size());
    contact_count.push_back(static_cast<std::uint32_t>(ids.size()));
    vertex.insert(vertex.end(), ids.begin(), ids.end());
    contact_force.insert(contact_force.end(), forces.begin(), forces.end());
  }
};

TEST(SessionRecorder, RoundTripOfTwoToolsWithContactsAndEvents) {
  TempDir dir;
  const auto file = dir / "session.h5";
  // Rings much smaller than the session and a writer that wakes every
  // millisecond: the rings wrap around many times and the file is extended
  // in many batches and flushed between them.
  RecorderLimits limits;
  limits.ring_ticks = 64;
  limits.ring_contacts = 256;
  limits.max_contacts_per_tick = 8;
  limits.ring_events = 4;
  limits.write_interval_s = 0.001;
  limits.flush_interval_s = 0.003;
  SessionRecorder recorder(file, two_tools(), limits);

  std::mt19937_64 rng(20261121);
  std::uniform_real_distribution<double> u(-1, 1);
  std::array<ToolExpectation, 2> expected;
  std::array<std::uint64_t, 2> sequence{};
  std::uint64_t refused = 0;
  const int n_ticks = 3000;
  for (int k = 0; k < n_ticks; ++k) {
    ToolTickRecord t;
    t.tool = (k % 3 == 0) ? 1 : 0;
    t.time_s = 0.0005 * k;
    t.sequence = ++sequence[static_cast<std::size_t>(t.tool)];
    t.send_time_ns = static_cast<std::int64_t>(rng() >> 2);
    for (double& x : t.position_m) x = 0.1 * u(rng);
    for (double& x : t.orientation_wxyz) x = u(rng);
    t.jaw_angle_rad = std::abs(u(rng));
    for (double& x : t.force_n) x = 8 * u(rng);
    for (double& x : t.torque_nm) x = 0.1 * u(rng);
    t.grip_n = 3 * std::abs(u(rng));
    t.state = static_cast<ToolState>(rng() % 3);
    t.watchdog = k % 17 == 0;
    t.force_limited = k % 5 == 0;
    t.held = static_cast<std::uint32_t>(rng() % 11);
    t.compute_ns = rng() % 100000;
    std::vector<std::uint32_t> ids(rng() % 9);  // 0 to max_contacts_per_tick
    std::vector<double> forces(3 * ids.size());
    for (auto& id : ids) id = static_cast<std::uint32_t>(rng());
    for (double& f : forces) f = u(rng);
    // A full ring is refused and counted; this producer waits and retries.
    while (!recorder.record(t, ids, forces)) {
      ++refused;
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    expected[static_cast<std::size_t>(t.tool)].add(t, ids, forces);
  }
  struct Event {
    double time_s;
    std::int32_t tool;
    std::int32_t kind;
    std::uint64_t sequence;
  };
  std::vector<Event> events;
  std::uint64_t refused_events = 0;
  for (int e = 0; e < 40; ++e) {
    const Event ev{0.01 * e, e % 2, e % 6, static_cast<std::uint64_t>(1000 + e)};
    while (!recorder.record_event(ev.time_s, ev.tool, static_cast<ToolEventKind>(ev.kind),
                                  ev.sequence)) {
      ++refused_events;
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    events.push_back(ev);
  }
  EXPECT_EQ(recorder.recorded(), static_cast<std::uint64_t>(n_ticks));
  EXPECT_EQ(recorder.dropped(), refused);
  EXPECT_EQ(recorder.dropped_events(), refused_events);
  recorder.close();
  EXPECT_LE(recorder.flushed(), static_cast<std::uint64_t>(n_ticks));
  ASSERT_TRUE(std::filesystem::exists(file));

  H5Reader h5(file);
  EXPECT_EQ(h5.string_attribute("/", "format"), "palpate-session");
  EXPECT_EQ(h5.attribute<std::int32_t>("/", "format_version"), 1);
  EXPECT_EQ(h5.string_attribute("/", "model_id"), "liver");
  EXPECT_EQ(h5.string_attribute("/", "model_file"), "/data/liver-h12.h5");
  EXPECT_EQ(h5.string_attribute("/", "input_hash"), "sha256:0123");
  EXPECT_EQ(h5.string_attribute("/", "daemon_id"), "palpated-test");
  EXPECT_EQ(h5.attribute<std::int64_t>("/", "start_unix_ns"), 1'700'000'000'123'456'789);
  EXPECT_EQ(h5.string_attribute("/", "started_utc"), "2023-11-14T22:13:20.123Z");
  EXPECT_EQ(h5.string_attribute("/", "units"), "m, N, s, rad");
  EXPECT_EQ(h5.attribute<std::uint64_t>("/", "ticks"), static_cast<std::uint64_t>(n_ticks));
  EXPECT_EQ(h5.attribute<std::uint64_t>("/", "dropped_ticks"), refused);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/", "events"), events.size());
  EXPECT_EQ(h5.strings_attribute("/tools", "ids"), (std::vector<std::string>{"left", "right"}));
  EXPECT_EQ(h5.attribute<std::int32_t>("/tools", "max_contacts_per_tool"), 12);
  EXPECT_EQ(h5.attribute<std::int32_t>("/tools/right", "index"), 1);
  EXPECT_EQ(h5.string_attribute("/tools/right", "tip"), "sphere");
  EXPECT_EQ(h5.string_attribute("/tools/left", "tip"), "capsule");
  EXPECT_EQ(h5.attribute<double>("/tools/right", "tip_radius_m"), 0.003);
  EXPECT_EQ(h5.attribute<double>("/tools/right", "force_limit_n"), 5.0);
  EXPECT_EQ(h5.strings_attribute("/tools/left/state", "names"),
            (std::vector<std::string>{"free", "touching", "grasping"}));
  EXPECT_EQ(h5.string_attribute("/tools/left/force", "units"), "N");

  for (const char* id : {"left", "right"}) {
    SCOPED_TRACE(id);
    const ToolExpectation& x = expected[std::string(id) == "left" ? 0 : 1];
    const std::string g = std::string("/tools/") + id + "/";
    EXPECT_EQ(first_difference(h5.read<double>(g + "time_s"), x.time_s), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint64_t>(g + "sequence"), x.sequence), -1);
    EXPECT_EQ(first_difference(h5.read<std::int64_t>(g + "send_time_ns"), x.send_time_ns), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "position", 3), x.position), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "orientation", 4), x.orientation), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "jaw_angle"), x.jaw_angle), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "force", 3), x.force), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "torque", 3), x.torque), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "grip"), x.grip), -1);
    EXPECT_EQ(first_difference(h5.read<std::int8_t>(g + "state"), x.state), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint8_t>(g + "watchdog"), x.watchdog), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint8_t>(g + "force_limited"), x.force_limited), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint32_t>(g + "held"), x.held), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint64_t>(g + "compute_ns"), x.compute_ns), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint64_t>(g + "contact_start"), x.contact_start), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint32_t>(g + "contact_count"), x.contact_count), -1);
    EXPECT_EQ(first_difference(h5.read<std::uint32_t>(g + "contacts/vertex"), x.vertex), -1);
    EXPECT_EQ(first_difference(h5.read<double>(g + "contacts/force", 3), x.contact_force), -1);
    EXPECT_EQ(h5.attribute<std::uint64_t>(g, "ticks"), x.time_s.size());
  }
  // Every third tick is the right tool's.
  EXPECT_EQ(expected[0].time_s.size(), 2000u);
  EXPECT_EQ(expected[1].time_s.size(), 1000u);

  std::vector<double> time_s;
  std::vector<std::int32_t> tool, kind;
  std::vector<std::uint64_t> pose_sequence;
  for (const Event& e : events) {
    time_s.push_back(e.time_s);
    tool.push_back(e.tool);
    kind.push_back(e.kind);
    pose_sequence.push_back(e.sequence);
  }
  EXPECT_EQ(first_difference(h5.read<double>("/events/time_s"), time_s), -1);
  EXPECT_EQ(first_difference(h5.read<std::int32_t>("/events/tool"), tool), -1);
  EXPECT_EQ(first_difference(h5.read<std::int32_t>("/events/kind"), kind), -1);
  EXPECT_EQ(first_difference(h5.read<std::uint64_t>("/events/pose_sequence"), pose_sequence), -1);
  EXPECT_EQ(h5.strings_attribute("/events/kind", "names"),
            (std::vector<std::string>{"touch", "leave", "grasp", "release", "watchdog", "resumed",
                                      "ended"}));
}

ToolTickRecord tick(double time_s, ToolState state, std::array<double, 3> force,
                    std::array<double, 3> position, double grip) {
  ToolTickRecord t;
  t.time_s = time_s;
  t.state = state;
  std::copy(force.begin(), force.end(), t.force_n);
  std::copy(position.begin(), position.end(), t.position_m);
  t.grip_n = grip;
  return t;
}

TEST(SessionRecorder, WhatTheDevicesRenderedIsKeptPerToolInOrder) {
  // 4 kHz steps of both tools through a small ring: every one is in its
  // tool's /tools/<id>/rendered datasets, in order, with the summary.
  TempDir dir;
  const auto file = dir / "session.h5";
  RecorderLimits limits;
  limits.ring_rendered = 32;
  limits.write_interval_s = 0.001;
  std::vector<RenderedRecord> sent[2];
  {
    SessionRecorder recorder(file, two_tools(), limits);
    std::mt19937_64 rng(20261126);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int k = 0; k < 2000; ++k) {
      RenderedRecord r;
      r.tool = k % 2;
      r.time_ns = 250'000 * (k / 2) + 17;
      r.answer_sequence = static_cast<std::uint64_t>(k / 8);
      for (double& x : r.position_m) x = 0.1 * u(rng);
      for (double& x : r.force_n) x = 4 * u(rng);
      r.damping = k % 7 == 0 ? 3 * std::abs(u(rng)) : 0.0;
      while (!recorder.record_rendered(r))
        std::this_thread::sleep_for(std::chrono::microseconds(100));
      sent[r.tool].push_back(r);
    }
    RenderedRecord bad;
    bad.tool = 2;  // no such tool
    EXPECT_FALSE(recorder.record_rendered(bad));
    recorder.close();
    EXPECT_GE(recorder.dropped_rendered(), 1u);
  }
  H5Reader h5(file);
  for (int tool = 0; tool < 2; ++tool) {
    const std::string group =
        std::string("/tools/") + (tool == 0 ? "left" : "right") + "/rendered/";
    const auto time_ns = h5.read<std::int64_t>(group + "time_ns");
    const auto answer = h5.read<std::uint64_t>(group + "answer_sequence");
    const auto position = h5.read<double>(group + "position", 3);
    const auto force = h5.read<double>(group + "force", 3);
    const auto damping = h5.read<double>(group + "damping");
    const auto& expected = sent[tool];
    ASSERT_EQ(time_ns.size(), expected.size());
    double max_force = 0;
    for (std::size_t i = 0; i < expected.size(); ++i) {
      EXPECT_EQ(time_ns[i], expected[i].time_ns);
      EXPECT_EQ(answer[i], expected[i].answer_sequence);
      EXPECT_EQ(damping[i], expected[i].damping);
      for (int d = 0; d < 3; ++d) {
        EXPECT_EQ(position[3 * i + d], expected[i].position_m[d]);
        EXPECT_EQ(force[3 * i + d], expected[i].force_n[d]);
      }
      max_force = std::max(max_force, std::hypot(expected[i].force_n[0], expected[i].force_n[1],
                                                 expected[i].force_n[2]));
    }
    const std::string object = std::string("/tools/") + (tool == 0 ? "left" : "right");
    EXPECT_EQ(h5.attribute<std::uint64_t>(object, "rendered_steps"), expected.size());
    EXPECT_NEAR(h5.attribute<double>(object, "max_rendered_force_n"), max_force, 1e-12);
  }
  EXPECT_GE(h5.attribute<std::uint64_t>("/", "dropped_rendered"), 1u);
}

TEST(SessionRecorder, SummaryAttributesMatchHandComputedValues) {
  TempDir dir;
  const auto file = dir / "summary.h5";
  {
    SessionRecorder recorder(file, two_tools());
    // Tool "left", uneven intervals Δ = 1, 2, 1, 2, 1, 7 ms after a 0.25 s offset.
    constexpr auto F = ToolState::kFree, T = ToolState::kTouching, G = ToolState::kGrasping;
    const ToolTickRecord ticks[] = {
        tick(0.250, F, {0, 0, 0}, {0, 0, 0}, 0),                // |f| 0
        tick(0.251, T, {0, 0, 1}, {0.003, 0.004, 0}, 0),        // |f| 1, path +5 mm
        tick(0.253, G, {3, 4, 0}, {0.003, 0.004, 0.012}, 1.5),  // |f| 5, +12 mm, grasp 1
        tick(0.254, T, {0, 2, 0}, {0.003, 0.004, 0.012}, 0),    // |f| 2, +0
        tick(0.256, G, {0, 0, -4}, {0, 0, 0.012}, 2.5),         // |f| 4, +5 mm, grasp 2
        tick(0.257, G, {1, 2, 2}, {0, 0, 0}, 2.0),              // |f| 3, +12 mm
        tick(0.264, F, {0, 0, 0.5}, {0, 0, 0}, 0),              // |f| 0.5, +0
    };
    for (const auto& t : ticks) ASSERT_TRUE(recorder.record(t, {}, {}));
    // Tool "right" records nothing.
  }
  H5Reader h5(file);
  // Each interval counts with the state and force of the tick that opens it:
  // in contact: Δ2..Δ6 = 2+1+2+1+7 = 13 ms; grasping: Δ3 + Δ5 + Δ6 = 1+1+7 = 9 ms;
  // ∫|f|dt = 1·2 + 5·1 + 2·2 + 4·1 + 3·7 = 36 N·ms; mean 36/13 N. (Counting
  // each interval with the tick that closes it would give 7 ms, 5 ms.)
  // The times are sums of decimal fractions: 1e-12 s covers their rounding.
  const double time_tol = 1e-12;
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "ticks"), 7u);
  EXPECT_NEAR(h5.attribute<double>("/tools/left", "duration_s"), 0.014, time_tol);
  EXPECT_NEAR(h5.attribute<double>("/tools/left", "time_in_contact_s"), 0.013, time_tol);
  EXPECT_NEAR(h5.attribute<double>("/tools/left", "time_grasping_s"), 0.009, time_tol);
  EXPECT_DOUBLE_EQ(h5.attribute<double>("/tools/left", "max_force_n"), 5.0);
  // Relative rounding of the 1 ms intervals is about 1e-13: 1e-9 is loose.
  EXPECT_NEAR(h5.attribute<double>("/tools/left", "mean_force_in_contact_n"), 36.0 / 13, 1e-9);
  EXPECT_DOUBLE_EQ(h5.attribute<double>("/tools/left", "max_grip_n"), 2.5);
  EXPECT_NEAR(h5.attribute<double>("/tools/left", "path_length_m"), 0.034, 1e-15);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "grasps"), 2u);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "dropped_ticks"), 0u);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "truncated_contact_ticks"), 0u);
  // A tool without ticks: zeros, not NaN.
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/right", "ticks"), 0u);
  EXPECT_EQ(h5.attribute<double>("/tools/right", "duration_s"), 0.0);
  EXPECT_EQ(h5.attribute<double>("/tools/right", "mean_force_in_contact_n"), 0.0);
  EXPECT_EQ(h5.attribute<double>("/tools/right", "path_length_m"), 0.0);
  EXPECT_NEAR(h5.attribute<double>("/", "duration_s"), 0.264, time_tol);
  EXPECT_TRUE(h5.has_attribute("/", "closed_utc"));
}

TEST(SessionRecorder, FullRingsDropWithoutBlockingOrAllocating) {
  TempDir dir;
  const auto file = dir / "overflow.h5";
  RecorderLimits limits;
  limits.ring_ticks = 8;
  limits.ring_contacts = 12;
  limits.max_contacts_per_tick = 4;
  limits.ring_events = 2;
  limits.write_interval_s = 1e9;  // the writer never drains before close()
  SessionRecorder recorder(file, two_tools(), limits);

  const std::vector<std::uint32_t> six = {10, 11, 12, 13, 14, 15}, three = {20, 21, 22};
  const std::vector<double> six_forces(18, 0.5), three_forces(9, 0.25);
  ToolTickRecord t;
  ToolTickRecord bad_tool;
  bad_tool.tool = 2;
  std::array<bool, 12> taken{};
  std::array<bool, 3> events_taken{};
  const std::uint64_t allocations_before = testing::allocations_here();
  taken[0] = recorder.record(t, six, six_forces);                     // cut to 4 contacts
  taken[1] = recorder.record(t, three, three_forces);                 // 7 contacts
  taken[2] = recorder.record(t, three, three_forces);                 // 10 contacts
  taken[3] = recorder.record(t, three, three_forces);                 // 13 > 12: refused
  for (int i = 4; i < 9; ++i) taken[i] = recorder.record(t, {}, {});  // ticks 4 to 8
  taken[9] = recorder.record(t, {}, {});                              // 9 > 8: refused
  taken[10] = recorder.record(t, {}, {});                             // refused
  taken[11] = recorder.record(bad_tool, {}, {});                      // no such tool: refused
  for (int e = 0; e < 3; ++e)
    events_taken[e] = recorder.record_event(0.001 * e, 0, ToolEventKind::kTouch, 7);
  const std::uint64_t allocations_after = testing::allocations_here();

  EXPECT_EQ(allocations_after, allocations_before) << "record() allocated";
  const std::array<bool, 12> expected_taken = {true, true, true, false, true,  true,
                                               true, true, true, false, false, false};
  for (std::size_t i = 0; i < expected_taken.size(); ++i)
    EXPECT_EQ(taken[i], expected_taken[i]) << i;
  EXPECT_EQ(events_taken, (std::array<bool, 3>{true, true, false}));
  EXPECT_EQ(recorder.recorded(), 8u);
  EXPECT_EQ(recorder.dropped(), 4u);
  EXPECT_EQ(recorder.dropped_events(), 1u);
  recorder.close();
  EXPECT_FALSE(recorder.record(t, {}, {})) << "a closed recorder takes nothing";

  H5Reader h5(file);
  EXPECT_EQ(h5.read<std::uint32_t>("/tools/left/contact_count"),
            (std::vector<std::uint32_t>{4, 3, 3, 0, 0, 0, 0, 0}));
  EXPECT_EQ(h5.read<std::uint64_t>("/tools/left/contact_start"),
            (std::vector<std::uint64_t>{0, 4, 7, 10, 10, 10, 10, 10}));
  EXPECT_EQ(h5.read<std::uint32_t>("/tools/left/contacts/vertex"),
            (std::vector<std::uint32_t>{10, 11, 12, 13, 20, 21, 22, 20, 21, 22}));
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "dropped_ticks"), 3u);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "truncated_contact_ticks"), 1u);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/", "dropped_ticks"), 4u);  // with the unknown tool
  EXPECT_EQ(h5.attribute<std::uint64_t>("/", "dropped_events"), 1u);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/", "events"), 2u);
  EXPECT_EQ(h5.read<double>("/events/time_s"), (std::vector<double>{0.0, 0.001}));
}

TEST(SessionRecorder, BadPlacesAndToolsAreInputErrorsNamingThePath) {
  TempDir dir;
  const auto missing = dir / "no-such-dir" / "session.h5";
  testing::expect_error<InputError>([&] { SessionRecorder r(missing, two_tools()); },
                                    {missing.string(), "does not exist", "create it"});
  EXPECT_FALSE(std::filesystem::exists(missing.string() + ".partial"));

  const auto existing = dir / "taken.h5";
  std::ofstream(existing) << "an earlier session";
  testing::expect_error<InputError>([&] { SessionRecorder r(existing, two_tools()); },
                                    {existing.string(), "already exists", "another name"});
  const auto stale = dir / "crashed.h5";
  std::ofstream(stale.string() + ".partial") << "left by a crash";
  testing::expect_error<InputError>([&] { SessionRecorder r(stale, two_tools()); },
                                    {stale.string() + ".partial", "crash"});

  SessionInfo twice = two_tools();
  twice.tools[1].id = "left";
  testing::expect_error<InputError>([&] { SessionRecorder r(dir / "a.h5", twice); },
                                    {"tool id 'left' appears twice"});
  SessionInfo slash = two_tools();
  slash.tools[1].id = "a/b";
  testing::expect_error<InputError>([&] { SessionRecorder r(dir / "b.h5", slash); },
                                    {"tool id 'a/b'", "A-Z a-z 0-9 _ - ."});
  RecorderLimits limits;
  limits.ring_ticks = 0;
  testing::expect_error<InputError>([&] { SessionRecorder r(dir / "c.h5", two_tools(), limits); },
                                    {"ring_ticks"});
  for (const char* name : {"a.h5", "b.h5", "c.h5", "a.h5.partial", "b.h5.partial", "c.h5.partial"})
    EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
}

TEST(SessionRecorder, ClosingRenamesThePartialFileOnce) {
  TempDir dir;
  const auto file = dir / "session.h5";
  const std::filesystem::path partial = file.string() + ".partial";
  SessionRecorder recorder(file, two_tools());
  EXPECT_EQ(recorder.path(), file);
  EXPECT_TRUE(std::filesystem::exists(partial));
  EXPECT_FALSE(std::filesystem::exists(file));
  {
    H5Reader h5(partial);  // readable from the start, if empty
    EXPECT_EQ(h5.read<double>("/tools/left/time_s").size(), 0u);
    EXPECT_FALSE(h5.has_attribute("/", "closed_utc"));
  }
  ASSERT_TRUE(recorder.record(tick(0, ToolState::kFree, {0, 0, 0}, {0, 0, 0}, 0), {}, {}));
  recorder.close();
  EXPECT_TRUE(std::filesystem::exists(file));
  EXPECT_FALSE(std::filesystem::exists(partial));
  recorder.close();  // idempotent
  EXPECT_TRUE(std::filesystem::exists(file));
  H5Reader h5(file);
  EXPECT_EQ(h5.read<double>("/tools/left/time_s").size(), 1u);
}

TEST(SessionRecorder, DestructorWithoutCloseWritesTheFinalFile) {
  TempDir dir;
  const auto file = dir / "session.h5";
  {
    SessionRecorder recorder(file, two_tools());
    for (int k = 0; k < 100; ++k) {
      ToolTickRecord t = tick(0.001 * k, ToolState::kTouching, {0, 0, 1}, {0, 0, 0}, 0);
      t.tool = k % 2;
      ASSERT_TRUE(recorder.record(t, {}, {}));
    }
  }
  EXPECT_FALSE(std::filesystem::exists(file.string() + ".partial"));
  ASSERT_TRUE(std::filesystem::exists(file));
  H5Reader h5(file);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/left", "ticks"), 50u);
  EXPECT_EQ(h5.attribute<std::uint64_t>("/tools/right", "ticks"), 50u);
  EXPECT_EQ(h5.read<double>("/tools/right/time_s").size(), 50u);
}

TEST(SessionRecorder, AKilledProcessLeavesThePartialFileReadableUpToTheLastFlush) {
  TempDir dir;
  const auto file = dir / "crash.h5";
  const int n_ticks = 500;
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // The child records, waits until the writer has flushed every tick, and
    // is killed before closing: no destructor, no rename.
    RecorderLimits limits;
    limits.write_interval_s = 0.005;
    limits.flush_interval_s = 0.01;
    SessionRecorder recorder(file, two_tools(), limits);
    for (int k = 0; k < n_ticks; ++k) {
      const std::uint32_t id = static_cast<std::uint32_t>(k);
      const double f[3] = {0, 0, 1.0 * k};
      if (!recorder.record(tick(0.001 * k, ToolState::kTouching, {0, 0, 1}, {0, 0, 0}, 0), {&id, 1},
                           f))
        _exit(2);
    }
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (recorder.flushed() < static_cast<std::uint64_t>(n_ticks)) {
      if (std::chrono::steady_clock::now() > deadline) _exit(3);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    raise(SIGKILL);
    _exit(4);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);
  EXPECT_EQ(WTERMSIG(status), SIGKILL);

  EXPECT_FALSE(std::filesystem::exists(file));
  const std::filesystem::path partial = file.string() + ".partial";
  ASSERT_TRUE(std::filesystem::exists(partial));
  H5Reader h5(partial);
  const auto time_s = h5.read<double>("/tools/left/time_s");
  ASSERT_EQ(time_s.size(), static_cast<std::size_t>(n_ticks));
  EXPECT_EQ(time_s.back(), 0.001 * (n_ticks - 1));
  const auto vertex = h5.read<std::uint32_t>("/tools/left/contacts/vertex");
  ASSERT_EQ(vertex.size(), static_cast<std::size_t>(n_ticks));
  EXPECT_EQ(vertex.back(), static_cast<std::uint32_t>(n_ticks - 1));
  EXPECT_EQ(h5.read<double>("/tools/left/contacts/force", 3).back(), n_ticks - 1.0);
  EXPECT_EQ(h5.string_attribute("/", "format"), "palpate-session");
  EXPECT_FALSE(h5.has_attribute("/", "closed_utc"));  // no summary: it never closed
  EXPECT_FALSE(h5.has_attribute("/tools/left", "ticks"));
}

}  // namespace
}  // namespace palpate
