// Gesture files (palpate-pliers): parse_gesture on fuzzed TOML, then what
// pliers does with one: place it on a model's surface and play it. A
// gesture that parses and places must play finite poses.

#include <cmath>
#include <cstdint>
#include <string_view>

#include "fuzz_support.hpp"
#include "palpate/runtime/gesture.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const palpate::SurfaceModel& model = palpate::fuzz::box_model();
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  palpate::Gesture gesture;
  if (!palpate::fuzz::accepted([&] { gesture = palpate::parse_gesture(text, "fuzz.toml"); }))
    return 0;
  PALPATE_FUZZ_CHECK(!gesture.tools.empty());
  for (const auto& tool : gesture.tools) {
    PALPATE_FUZZ_CHECK(!tool.keyframes.empty());
    for (std::size_t k = 1; k < tool.keyframes.size(); ++k)
      PALPATE_FUZZ_CHECK(tool.keyframes[k].time_s > tool.keyframes[k - 1].time_s);
  }

  const palpate::DrawnSurface& surface = model.surface;
  std::vector<palpate::AnchorFrame> anchors;
  if (!palpate::fuzz::accepted([&] { anchors = palpate::place_gesture(gesture, surface); }))
    return 0;
  const palpate::GesturePlayer player(gesture, anchors);
  const double duration = player.duration_s();
  PALPATE_FUZZ_CHECK(std::isfinite(duration) && duration >= 0);
  for (int t = 0; t < player.tool_count(); ++t)
    for (const double f : {-1.0, 0.0, 0.25, 0.5, 0.999, 1.0, 2.0}) {
      const palpate::GesturePose p = player.sample(t, f * duration);
      PALPATE_FUZZ_CHECK(p.hinge_m.allFinite() && p.tip_m.allFinite());
      PALPATE_FUZZ_CHECK(p.orientation.coeffs().allFinite());
      PALPATE_FUZZ_CHECK(std::abs(p.orientation.norm() - 1) < 1e-9);
      PALPATE_FUZZ_CHECK(std::isfinite(p.jaw_angle_rad));
    }
  return 0;
}
