#pragma once
// A one-line progress bar on stderr, drawn only when stderr is a terminal.

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>

namespace palpate::precompute {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label) : label_(std::move(label)) {}
  static bool wanted() { return ::isatty(STDERR_FILENO) == 1; }

  void operator()(long done, long total) {
    const auto now = std::chrono::steady_clock::now();
    if (done < total && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double frac = total > 0 ? static_cast<double>(done) / total : 1.0;
    const int width = 30, filled = static_cast<int>(frac * width);
    std::string bar(static_cast<size_t>(filled), '#');
    bar.resize(width, '.');
    const double eta = frac > 0 ? elapsed * (1 - frac) / frac : 0;
    std::fprintf(stderr, "\r  %-18s [%s] %3.0f%%  %.1f s, %.1f s left ", label_.c_str(),
                 bar.c_str(), 100 * frac, elapsed, eta);
    if (done >= total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }

 private:
  std::string label_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace palpate::precompute
