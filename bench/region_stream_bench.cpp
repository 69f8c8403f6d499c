// The surface stream while a region is cut (issue 20: "the stream at 60 Hz
// with the changing topology"): reads every surface sample of one model for
// a while, as a viewer does, and prints the rate, the gaps, the time
// between samples (all, and into each sample that carries a new topology
// version) and what the region adds to a sample. Run by
// bench/region_stream.sh, which serves the cut demo's organ and plays the
// cut gesture meanwhile (docs/benchmarks-history.md, "The stream while the region is
// cut").
//
//   build/bench/palpate_region_stream_bench MODEL SECONDS
//
// Over DDS: run it only inside a private network namespace whose only
// interface is loopback (the script does); it uses palpate's loopback-only
// configuration unless CYCLONEDDS_URI says otherwise.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "palpate/core/statistics.hpp"
#include "palpate/transport/client.hpp"

namespace {

using Clock = std::chrono::steady_clock;

struct Quantiles {
  double p50 = 0, p99 = 0, max = 0;
};
Quantiles quantiles(std::vector<double> v) {
  if (v.empty()) return {};
  std::sort(v.begin(), v.end());
  return {palpate::sorted_percentile(v, 0.5), palpate::sorted_percentile(v, 0.99), v.back()};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s MODEL SECONDS\n", argv[0]);
    return 2;
  }
  const std::string model = argv[1];
  const double seconds = std::atof(argv[2]);
  palpate::ClientOptions options;
  options.client_id = "region-stream-bench";
  options.subscribe_surface = true;
  palpate::Client client(options);
  if (!client.wait_for_model(model, std::chrono::seconds(30))) {
    std::fprintf(stderr, "no model '%s' within 30 s\n", model.c_str());
    return 1;
  }
  const auto end = Clock::now() + std::chrono::duration<double>(seconds);
  std::uint64_t next = 1, first = 0, last = 0, version = 0;
  long samples = 0, gaps = 0, versions = 0;
  double region_bytes = 0, largest_region_bytes = 0;
  std::vector<double> between_ms, into_new_version_ms;
  Clock::time_point first_at{}, previous_at{};
  while (Clock::now() < end) {
    const auto sample = client.wait_surface(model, next, 0, std::chrono::milliseconds(200));
    if (!sample) continue;
    const Clock::time_point at = Clock::now();
    if (samples == 0) {
      first = sample->sequence_number;
      first_at = at;
    } else {
      gaps += static_cast<long>(sample->sequence_number - last - 1);
      const double ms = std::chrono::duration<double, std::milli>(at - previous_at).count();
      between_ms.push_back(ms);
      if (sample->topology_version != version) into_new_version_ms.push_back(ms);
    }
    versions += samples > 0 && sample->topology_version != version;
    version = sample->topology_version;
    const double bytes = 8.0 * static_cast<double>(sample->region_positions_m.size()) +
                         4.0 * static_cast<double>(sample->region_triangles.size() +
                                                   sample->hidden_triangles.size());
    region_bytes += bytes;
    largest_region_bytes = std::max(largest_region_bytes, bytes);
    last = sample->sequence_number;
    next = last + 1;
    previous_at = at;
    ++samples;
  }
  const double span_s = std::chrono::duration<double>(previous_at - first_at).count();
  const Quantiles all = quantiles(between_ms), changed = quantiles(into_new_version_ms);
  std::printf(
      "model %s: %ld samples (sequence %llu to %llu, %ld missed) in %.2f s: %.1f per s\n"
      "  between samples: p50 %.1f ms, p99 %.1f ms, max %.1f ms\n"
      "  %ld new topology versions (last %llu); into those samples: p50 %.1f ms, p99 %.1f ms, "
      "max %.1f ms\n"
      "  the region's part of a sample: mean %.0f bytes, largest %.0f bytes\n",
      model.c_str(), samples, static_cast<unsigned long long>(first),
      static_cast<unsigned long long>(last), gaps, span_s,
      span_s > 0 ? static_cast<double>(samples - 1) / span_s : 0.0, all.p50, all.p99, all.max,
      versions, static_cast<unsigned long long>(version), changed.p50, changed.p99, changed.max,
      samples > 0 ? region_bytes / static_cast<double>(samples) : 0.0, largest_region_bytes);
  return samples > 0 ? 0 : 1;
}
