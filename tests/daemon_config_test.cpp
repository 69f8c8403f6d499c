// palpated's configuration file: defaults, every key, and errors that name
// the file, the line and the key.

#include "palpate/daemon_config.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "palpate/error.hpp"
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
[[model]]
id = "liver"
file = "organ.h5"
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
  ASSERT_EQ(config.models.size(), 1u);
  EXPECT_EQ(config.models[0].id, "liver");
  EXPECT_EQ(config.models[0].file, dir.path() / "organ.h5");
  EXPECT_NO_THROW(validate(config));
}

TEST(DaemonConfig, DefaultsNeedOnlyAModel) {
  DaemonConfig config;
  EXPECT_EQ(config.surface_rate_hz, 60);
  EXPECT_EQ(config.status_rate_hz, 1);
  EXPECT_TRUE(config.dds_config.empty()) << "loopback unless the user gives a configuration";
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
  config.log_level = "verbose";
  expect_error<InputError>([&] { validate(config); },
                           {"daemon.log_level 'verbose'", "trace, debug"});
}

}  // namespace
}  // namespace palpate
