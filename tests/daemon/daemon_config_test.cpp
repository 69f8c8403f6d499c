// palpated's configuration file: defaults, every key, and errors that name
// the file, the line and the key.

#include "palpate/daemon/daemon_config.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "palpate/core/error.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;

std::filesystem::path write(const testing::TempDir& dir, const std::string& text) {
  const auto path = dir / "palpated.toml";
  std::ofstream(path) << text;
  return path;
}

TEST(DaemonConfig, ReadsEveryKeyAndResolvesPathsFromTheFile) {
  testing::TempDir dir;
  std::ofstream(dir / "organ.h5") << "placeholder";
  std::ofstream(dir / "flap.h5") << "placeholder";
  const auto config = read_daemon_config(write(dir, R"(
[daemon]
id = "or-3"
log_level = "debug"
[dds]
domain = 7
config = "cyclone.xml"
[rates]
surface_hz = 30
status_hz = 2.5
[limits]
max_constraints = 20
max_condition = 1e9
cache_slots = 4
max_clients = 8
max_displacement_fraction = 0.05
max_force_n = 20
[[model]]
id = "liver"
file = "organ.h5"
[[model]]
id = "flap"
file = "flap.h5"
warping = "warped"
)"));
  EXPECT_EQ(config.daemon_id, "or-3");
  EXPECT_EQ(config.log_level, "debug");
  EXPECT_EQ(config.domain_id, 7u);
  EXPECT_EQ(config.dds_config, (dir.path() / "cyclone.xml").string());
  EXPECT_EQ(config.surface_rate_hz, 30);
  EXPECT_EQ(config.status_rate_hz, 2.5);
  EXPECT_EQ(config.limits.max_constraints, 20);
  EXPECT_EQ(config.limits.max_condition, 1e9);
  EXPECT_EQ(config.limits.cache_slots, 4);
  EXPECT_EQ(config.max_clients, 8);
  EXPECT_EQ(config.max_displacement_fraction, 0.05);
  EXPECT_EQ(config.max_force_n, 20);
  ASSERT_EQ(config.models.size(), 2u);
  EXPECT_EQ(config.models[0].id, "liver");
  EXPECT_EQ(config.models[0].file, dir.path() / "organ.h5");
  EXPECT_FALSE(config.models[0].warped) << "linear unless the file says warped";
  EXPECT_TRUE(config.models[1].warped);
  EXPECT_NO_THROW(validate(config));
}

TEST(DaemonConfig, DefaultsNeedOnlyAModel) {
  DaemonConfig config;
  EXPECT_EQ(config.surface_rate_hz, 60);
  EXPECT_EQ(config.status_rate_hz, 1);
  EXPECT_TRUE(config.dds_config.empty()) << "loopback unless the user gives a configuration";
  EXPECT_EQ(config.max_displacement_fraction, 0.1) << "10 % of the organ's size";
  EXPECT_EQ(config.max_force_n, 50);
  expect_error<InputError>([&] { validate(config); }, {"no model to serve", "--model ID=PATH"});
  config.models.push_back(parse_model_flag("liver=/nonexistent/liver.h5"));
  expect_error<InputError>([&] { validate(config); },
                           {"model 'liver'", "/nonexistent/liver.h5", "does not exist"});
}

TEST(DaemonConfig, ErrorsNameTheLineTheKeyAndWhatIsAccepted) {
  testing::TempDir dir;
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[rates]\nsurface_hz = -3\n")); },
                           {"palpated.toml:2", "rates.surface_hz", "positive"});
  expect_error<InputError>(
      [&] { read_daemon_config(write(dir, "[limits]\nmax_constraint = 3\n")); },
      {"palpated.toml:2", "limits.max_constraint", "unknown key", "max_constraints"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[dds]\ndomain = 300\n")); },
                           {"dds.domain", "[0, 232]"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[[model]]\nid = \"a\"\n")); },
                           {"palpated.toml:1", "needs id and file"});
  expect_error<InputError>(
      [&] {
        read_daemon_config(
            write(dir, "[[model]]\nid = \"a\"\nfile = \"a.h5\"\nwarping = \"corotational\"\n"));
      },
      {"palpated.toml:4", "model.warping", "'corotational'", "\"linear\" or \"warped\""});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[daemon\n")); },
                           {"palpated.toml:1", "not valid TOML"});
  expect_error<InputError>([&] { read_daemon_config(dir / "missing.toml"); },
                           {"missing.toml", "no such file"});
  expect_error<InputError>([] { parse_model_flag("liver.h5"); }, {"--model 'liver.h5'", "ID=PATH"});

  std::ofstream(dir / "a.h5") << "x";
  DaemonConfig config;
  config.models = {{"a", dir / "a.h5"}, {"a", dir / "a.h5"}};
  expect_error<InputError>([&] { validate(config); }, {"model id 'a' is given twice"});
  config.models = {{"bad id*", dir / "a.h5"}};
  expect_error<InputError>([&] { validate(config); }, {"model id 'bad id*'", "A-Z a-z 0-9"});
  config.models = {{"a", dir / "a.h5"}};
  config.max_displacement_fraction = 2;
  expect_error<InputError>([&] { validate(config); },
                           {"limits.max_displacement_fraction 2", "(0, 1]"});
  config.max_displacement_fraction = 0.1;
  config.max_force_n = INFINITY;
  expect_error<InputError>([&] { validate(config); }, {"limits.max_force_n inf", "> 0 in N"});
  config.max_force_n = 50;
  config.log_level = "verbose";
  expect_error<InputError>([&] { validate(config); },
                           {"daemon.log_level 'verbose'", "trace, debug"});
}

TEST(DaemonConfig, ReadsToolsInMillimetresAndDegreesAsSI) {
  testing::TempDir dir;
  std::ofstream(dir / "organ.h5") << "placeholder";
  std::ofstream(dir / "flap.h5") << "placeholder";
  std::filesystem::create_directory(dir / "sessions");
  const auto config = read_daemon_config(write(dir, R"(
[[model]]
id = "liver"
file = "organ.h5"
[[tools]]
id = "probe"
tip = "sphere"
tip_radius_mm = 2.5
friction = 0
jaw_length_mm = 0
force_limit_n = 3.3
max_force_rate_n_per_s = 200
[[tools]]
id = "grasper"
tip_length_mm = 12
grasp_angle_deg = 10
release_angle_deg = 30
max_jaw_angle_deg = 60
[contact]
watchdog_timeout_ms = 20
watchdog_ramp_ms = 100
search_margin_mm = 5
max_contacts_per_tool = 12
max_iterations = 3
workspace_margin_mm = 200
[recording]
directory = "sessions"
)"));
  ASSERT_EQ(config.tools.size(), 2u);
  const ToolGeometry& probe = config.tools[0];
  EXPECT_EQ(probe.id, "probe");
  EXPECT_EQ(probe.tip, TipShape::kSphere);
  EXPECT_DOUBLE_EQ(probe.tip_radius_m, 0.0025);
  EXPECT_EQ(probe.tip_length_m, 0.0);
  EXPECT_EQ(probe.friction, 0.0);
  EXPECT_EQ(probe.jaw_length_m, 0.0);
  EXPECT_EQ(probe.force_limit_n, 3.3);
  EXPECT_EQ(probe.max_force_rate_n_per_s, 200);
  const ToolGeometry& grasper = config.tools[1];
  EXPECT_EQ(grasper.tip, TipShape::kCapsule);
  EXPECT_DOUBLE_EQ(grasper.tip_length_m, 0.012);
  EXPECT_NEAR(grasper.grasp_angle_rad, 0.17453292519943295, 1e-15);
  EXPECT_NEAR(grasper.release_angle_rad, 0.52359877559829882, 1e-15);
  EXPECT_DOUBLE_EQ(config.contact.watchdog_timeout_s, 0.020);
  EXPECT_DOUBLE_EQ(config.contact.watchdog_ramp_s, 0.100);
  EXPECT_DOUBLE_EQ(config.contact.search_margin_m, 0.005);
  EXPECT_EQ(config.contact.max_contacts_per_tool, 12);
  EXPECT_EQ(config.contact.max_iterations, 3);
  EXPECT_DOUBLE_EQ(config.contact.workspace_margin_m, 0.2);
  EXPECT_EQ(config.record_directory, dir.path() / "sessions");
  EXPECT_NO_THROW(validate(config));

  DaemonConfig defaults;
  ASSERT_EQ(defaults.tools.size(), 2u);
  EXPECT_EQ(defaults.tools[0].id, "left");
  EXPECT_EQ(defaults.tools[1].id, "right");
  EXPECT_TRUE(defaults.record_directory.empty());
}

TEST(DaemonConfig, ToolErrorsSayWhatIsAccepted) {
  testing::TempDir dir;
  expect_error<InputError>(
      [&] { read_daemon_config(write(dir, "[[tools]]\nid = \"a\"\ntip = \"cone\"\n")); },
      {"palpated.toml:3", "tools.a.tip", "sphere", "capsule"});
  expect_error<InputError>(
      [&] {
        read_daemon_config(
            write(dir, "[[tools]]\nid = \"a\"\ntip = \"sphere\"\ntip_length_mm = 3\n"));
      },
      {"tools.a.tip_length_mm", "a sphere tip has no length"});
  expect_error<InputError>(
      [&] { read_daemon_config(write(dir, "[[tools]]\nid = \"a\"\ntip_radius_mm = -1\n")); },
      {"palpated.toml:3", "tools.a.tip_radius_mm", "positive"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[[tools]]\ntip = \"sphere\"\n")); },
                           {"needs an id"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[contact]\nwatchdog_ms = 3\n")); },
                           {"contact.watchdog_ms", "unknown key", "watchdog_timeout_ms"});

  std::ofstream(dir / "a.h5") << "x";
  DaemonConfig config;
  config.models = {{"a", dir / "a.h5"}};
  config.tools[1].id = "left";
  expect_error<InputError>([&] { validate(config); }, {"tool id 'left' is given twice"});
  config.tools = DaemonConfig::default_tools();
  config.tools[0].release_angle_rad = config.tools[0].grasp_angle_rad;
  expect_error<InputError>([&] { validate(config); }, {"tool 'left'", "grasp < release ≤ max"});
  config.tools = DaemonConfig::default_tools();
  config.record_directory = dir / "nowhere";
  expect_error<InputError>([&] { validate(config); },
                           {"recording.directory", "nowhere", "not a directory"});
}

TEST(DaemonConfig, RealtimeIsOffByDefaultAndReadFromItsTable) {
  const DaemonConfig defaults;
  EXPECT_EQ(defaults.serve, ServeMode::kListener) << "Cyclone's receive thread serves";
  EXPECT_EQ(defaults.realtime.priority, 0);
  EXPECT_TRUE(defaults.realtime.cpus.empty());
  EXPECT_FALSE(defaults.realtime.lock_memory);
  EXPECT_FALSE(defaults.realtime.any());

  testing::TempDir dir;
  const auto config = read_daemon_config(write(dir, R"(
[realtime]
serve = "busy"
priority = 49
cpus = [1, 0, 1]
lock_memory = true
)"));
  EXPECT_EQ(config.serve, ServeMode::kBusy);
  EXPECT_EQ(config.realtime.priority, 49);
  EXPECT_EQ(config.realtime.cpus, (std::vector<int>{0, 1})) << "sorted, each once";
  EXPECT_TRUE(config.realtime.lock_memory);
  // A CPU list as taskset -c takes it.
  const auto listed =
      read_daemon_config(write(dir, "[realtime]\nserve = \"waitset\"\ncpus = \"0-1,3\"\n"));
  EXPECT_EQ(listed.serve, ServeMode::kWaitset);
  EXPECT_EQ(listed.realtime.cpus, (std::vector<int>{0, 1, 3}));
  for (const ServeMode mode : {ServeMode::kListener, ServeMode::kWaitset, ServeMode::kBusy})
    EXPECT_EQ(parse_serve_mode(serve_mode_name(mode), "--serve"), mode);
}

TEST(DaemonConfig, RealtimeErrorsNameTheLineTheKeyAndWhatIsAccepted) {
  testing::TempDir dir;
  expect_error<InputError>(
      [&] { read_daemon_config(write(dir, "[realtime]\nserve = \"fast\"\n")); },
      {"palpated.toml:2", "realtime.serve: 'fast': expected \"listener\"", "\"waitset\"",
       "\"busy\""});
  expect_error<InputError>([&] { parse_serve_mode("poll", "--serve"); },
                           {"--serve 'poll': expected \"listener\""});
  expect_error<InputError>(
      [&] { read_daemon_config(write(dir, "[realtime]\npriority = 100\n")); },
      {"palpated.toml:2", "realtime.priority", "expected an integer in [0, 99]"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[realtime]\npriority = 2.5\n")); },
                           {"realtime.priority", "expected an integer"});
  expect_error<InputError>(
      [&] { read_daemon_config(write(dir, "[realtime]\ncpus = \"2-1\"\n")); },
      {"palpated.toml:2", "realtime.cpus: '2-1': the range 2-1 goes down", "taskset -c"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[realtime]\ncpus = [-1]\n")); },
                           {"realtime.cpus", "expected an integer in [0, 1023]"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[realtime]\ncpus = 1\n")); },
                           {"realtime.cpus", "an array of CPU numbers", "a CPU list string"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[realtime]\nlock_memory = 1\n")); },
                           {"realtime.lock_memory", "expected true or false"});
  expect_error<InputError>([&] { read_daemon_config(write(dir, "[realtime]\npriorty = 1\n")); },
                           {"realtime.priorty", "unknown key", "priority, cpus, lock_memory"});

  // A CPU this process may not run on is found by validate(), whatever set it.
  std::ofstream(dir / "a.h5") << "x";
  DaemonConfig config;
  config.models = {{"a", dir / "a.h5"}};
  const int absent = realtime::online_cpus().back() + 1;
  config.realtime.cpus = {absent};
  expect_error<InputError>(
      [&] { validate(config); },
      {"realtime.cpus [" + std::to_string(absent) + "]", "is not online on this machine"});
  config.realtime = {};
  config.realtime.priority = 120;  // as --rt-priority 120 sets it
  expect_error<InputError>([&] { validate(config); },
                           {"realtime.priority 120: expected a SCHED_FIFO priority from 1"});
}

}  // namespace
}  // namespace palpate
