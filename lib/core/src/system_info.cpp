#include "palpate/core/system_info.hpp"

#include <dlfcn.h>
#include <fmt/format.h>
#include <link.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace palpate {

namespace {

double status_kb(const char* path, const std::string& key) {
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key, 0) == 0) return std::strtod(line.c_str() + key.size(), nullptr);
  return 0;
}

}  // namespace

double peak_rss_bytes() { return status_kb("/proc/self/status", "VmHWM:") * 1024; }
double current_rss_bytes() { return status_kb("/proc/self/status", "VmRSS:") * 1024; }
double available_memory_bytes() { return status_kb("/proc/meminfo", "MemAvailable:") * 1024; }

bool reset_peak_rss() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  return static_cast<bool>(out);
}

void set_blas_threads(int count) {
  using SetFn = void (*)(int);
  if (auto set = reinterpret_cast<SetFn>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads")))
    set(count);
}

std::string blas_description() {
  std::vector<std::string> libs;
  dl_iterate_phdr(
      [](dl_phdr_info* info, size_t, void* data) {
        const std::string name = info->dlpi_name ? info->dlpi_name : "";
        if (name.find("blas") != std::string::npos) {
          std::error_code ec;
          const auto real = std::filesystem::canonical(name, ec);
          static_cast<std::vector<std::string>*>(data)->push_back(ec ? name : real.string());
        }
        return 0;
      },
      &libs);
  std::string text = libs.empty() ? "unknown" : libs.front();
  for (size_t i = 1; i < libs.size(); ++i) text += ", " + libs[i];
  using ConfigFn = char* (*)();
  using ThreadsFn = int (*)();
  if (auto config = reinterpret_cast<ConfigFn>(dlsym(RTLD_DEFAULT, "openblas_get_config"))) {
    text += fmt::format(" [{}", config());
    if (auto threads = reinterpret_cast<ThreadsFn>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads")))
      text += fmt::format(", {} threads", threads());
    if (auto core = reinterpret_cast<ConfigFn>(dlsym(RTLD_DEFAULT, "openblas_get_corename")))
      text += fmt::format(", core {}", core());
    text += "]";
  }
  return text;
}

void ensure_optimized_blas(char** argv) {
  using CoreFn = char* (*)();
  if (std::getenv("PALPATE_BLAS_REEXEC")) {
    ::unsetenv("PALPATE_BLAS_REEXEC");  // done: children start afresh
    return;
  }
  auto corename = reinterpret_cast<CoreFn>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  if (!corename || std::getenv("OPENBLAS_CORETYPE")) return;
  const std::string core = corename();
  if (core != "Prescott" && core != "Core2" && core != "Nehalem" && core != "Sandybridge") return;
  const char* better = nullptr;
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq"))
    better = "SkylakeX";
  else if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
    better = "Haswell";
  if (!better) return;
  ::setenv("OPENBLAS_CORETYPE", better, 1);
  ::setenv("PALPATE_BLAS_REEXEC", "1", 1);  // never loop
  ::execv("/proc/self/exe", argv);
  // execv failed: go on with the slow kernels rather than not at all.
  ::unsetenv("OPENBLAS_CORETYPE");
}

std::string utc_timestamp() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::string format_bytes(double bytes) {
  if (bytes >= 1e9) return fmt::format("{:.2f} GB", bytes / 1e9);
  if (bytes >= 1e6) return fmt::format("{:.1f} MB", bytes / 1e6);
  if (bytes >= 1e3) return fmt::format("{:.1f} kB", bytes / 1e3);
  return fmt::format("{:.0f} B", bytes);
}

}  // namespace palpate
