// Facts about the process and the machine (core/system_info.hpp).
#include "palpate/core/system_info.hpp"

#include <gtest/gtest.h>

#include <regex>
#include <vector>

namespace palpate {
namespace {

TEST(SystemInfo, ResidentMemoryGrowsWithWhatIsTouched) {
  const double before = current_rss_bytes();
  ASSERT_GT(before, 0);
  std::vector<char> block(64 << 20, 1);  // 64 MiB, every page written
  const double during = current_rss_bytes();
  // At least 3/4 of it is resident (the kernel may lag a little).
  EXPECT_GT(during - before, 0.75 * static_cast<double>(block.size())) << before << " " << during;
  EXPECT_GE(peak_rss_bytes(), during);
  EXPECT_GT(available_memory_bytes(), 0);
}

TEST(SystemInfo, BytesAndTimestampsForReports) {
  EXPECT_EQ(format_bytes(999), "999 B");
  EXPECT_EQ(format_bytes(1500), "1.5 kB");
  EXPECT_EQ(format_bytes(39.5e6), "39.5 MB");
  EXPECT_EQ(format_bytes(17.04e9), "17.04 GB");
  EXPECT_TRUE(std::regex_match(utc_timestamp(), std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ)")))
      << utc_timestamp();
}

}  // namespace
}  // namespace palpate
