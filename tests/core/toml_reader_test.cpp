// The TOML reader every configuration goes through (core/detail/toml_reader.hpp):
// each failure names the file, the line, the key and what is accepted.
#include "palpate/core/detail/toml_reader.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "palpate/core/error.hpp"
#include "support/expect_error.hpp"

namespace palpate {
namespace {

using testing::expect_error;

std::filesystem::path write(const std::string& name, const std::string& text) {
  const auto path = std::filesystem::temp_directory_path() / name;
  std::ofstream(path) << text;
  return path;
}

TEST(TomlReader, ReadsTypedValues) {
  const auto file =
      write("toml_reader_ok.toml", "[a]\nx = 1.5\nn = 2\nflag = true\nv = [1, 2, 3]\n");
  const toml::table root = detail::parse_toml_file(file);
  const detail::TomlReader r(file.string());
  const auto& a = r.table(*root.get("a"), "a");
  r.only_keys(a, "a", {"x", "n", "flag", "v"});
  EXPECT_EQ(r.number(*a.get("x"), "a.x"), 1.5);
  EXPECT_EQ(r.number(*a.get("n"), "a.n"), 2.0);  // an integer is a number
  EXPECT_TRUE(r.boolean(*a.get("flag"), "a.flag"));
  EXPECT_EQ(r.vec3(*a.get("v"), "a.v"), Eigen::Vector3d(1, 2, 3));
}

TEST(TomlReader, FailuresNameFileLineKeyAndWhatIsAccepted) {
  const auto file = write("toml_reader_bad.toml", "[a]\nx = \"text\"\nunknown = 1\nv = [1, 2]\n");
  const toml::table root = detail::parse_toml_file(file);
  const detail::TomlReader r(file.string());
  const auto& a = r.table(*root.get("a"), "a");
  expect_error<InputError>([&] { r.number(*a.get("x"), "a.x"); },
                           {file.string() + ":2:", "a.x", "expected a number"});
  expect_error<InputError>(
      [&] {
        r.only_keys(a, "a", {"x", "v"});
      },
      {":3:", "a.unknown", "unknown key", "accepted here: x, v"});
  expect_error<InputError>([&] { r.vec3(*a.get("v"), "a.v"); },
                           {":4:", "a.v", "array of 3 numbers"});
}

TEST(TomlReader, MissingFileAndSyntaxErrors) {
  expect_error<InputError>([] { detail::parse_toml_file("/nonexistent/job.toml"); },
                           {"/nonexistent/job.toml", "no such file"});
  const auto file = write("toml_reader_syntax.toml", "[a]\nx = = 1\n");
  expect_error<InputError>([&] { detail::parse_toml_file(file); },
                           {file.string() + ":2:", "not valid TOML"});
}

TEST(TomlReader, RelativePathsAreTakenFromTheFilesDirectory) {
  EXPECT_EQ(detail::relative_to("/etc/palpate", "models/liver.h5"),
            std::filesystem::path("/etc/palpate/models/liver.h5"));
  EXPECT_EQ(detail::relative_to("/etc/palpate", "/data/liver.h5"),
            std::filesystem::path("/data/liver.h5"));
}

}  // namespace
}  // namespace palpate
