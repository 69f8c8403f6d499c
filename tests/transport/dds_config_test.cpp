// Where a process's DDS configuration comes from (transport/dds.hpp): the
// user's, or palpate's loopback one (config/dds-loopback.xml). No
// participant is created here.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>

#include "palpate/core/error.hpp"
#include "palpate/transport/dds.hpp"
#include "support/expect_error.hpp"
#include "support/files.hpp"

#ifndef PALPATE_SOURCE_DIR
#error "PALPATE_SOURCE_DIR: the checkout, for config/dds-loopback.xml"
#endif

namespace palpate {
namespace {

/// CYCLONEDDS_URI unset for the test's duration.
struct NoUri {
  std::string saved;
  bool had = false;
  NoUri() {
    if (const char* v = std::getenv("CYCLONEDDS_URI")) had = true, saved = v;
    unsetenv("CYCLONEDDS_URI");
  }
  ~NoUri() {
    if (had) setenv("CYCLONEDDS_URI", saved.c_str(), 1);
  }
};

TEST(DdsConfig, TheBuiltInOneIsTheLoopbackFile) {
  std::string expected = palpate::testing::slurp(std::filesystem::path(PALPATE_SOURCE_DIR) /
                                                 "config/dds-loopback.xml");
  while (!expected.empty() && std::isspace(static_cast<unsigned char>(expected.back())))
    expected.pop_back();
  EXPECT_EQ(dds::loopback_config(), expected);
  // What keeps DDS off the real network.
  for (const char* must :
       {"<NetworkInterface name=\"lo\" multicast=\"false\"/>",
        "<AllowMulticast>false</AllowMulticast>", "<Peer address=\"127.0.0.1\"/>"})
    EXPECT_NE(dds::loopback_config().find(must), std::string::npos) << must;
}

TEST(DdsConfig, UserConfigurationFirstThenTheEnvironmentThenLoopback) {
  NoUri clean;
  const auto loopback = dds::resolve_domain_config("");
  EXPECT_EQ(loopback.text, dds::loopback_config());
  EXPECT_EQ(loopback.origin, "built-in loopback");

  setenv("CYCLONEDDS_URI", "<General/>", 1);
  const auto from_env = dds::resolve_domain_config("");
  EXPECT_EQ(from_env.text, "<General/>");
  EXPECT_NE(from_env.origin.find("CYCLONEDDS_URI"), std::string::npos);

  const auto fragment = dds::resolve_domain_config("<Discovery/>");
  EXPECT_EQ(fragment.text, "<Discovery/>") << "the flag wins over the environment";
  unsetenv("CYCLONEDDS_URI");
}

TEST(DdsConfig, AFileIsPassedAsAUriAndAMissingOneIsRefused) {
  NoUri clean;
  const auto path = std::filesystem::temp_directory_path() / "dds_config_test.xml";
  std::ofstream(path) << "<CycloneDDS><Domain Id=\"any\"/></CycloneDDS>\n";
  const auto from_file = dds::resolve_domain_config(path.string());
  EXPECT_EQ(from_file.text, "file://" + path.string()) << "Cyclone reads the file itself";
  testing::expect_error<InputError>(
      [] { dds::resolve_domain_config("/nonexistent/cyclonedds.xml"); },
      {"/nonexistent/cyclonedds.xml"});
}

TEST(DdsConfig, ReplyPartitionsAreNamedAfterTheClient) {
  EXPECT_EQ(dds::reply_partition("pliers-1"), "palpate.client.pliers-1");
}

}  // namespace
}  // namespace palpate
