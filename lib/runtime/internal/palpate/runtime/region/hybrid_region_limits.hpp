#pragma once
// Private to palpate_runtime: what hybrid_region.cpp and
// hybrid_region_step.cpp (one class, HybridRegion, in two files) share.

namespace palpate::detail {

// What HybridRegion's messages name.
inline constexpr const char* kRegionWhat = "cut region";
// Simulated time one advance() may cover: a tick after a pause of seconds
// is not replayed step by step (docs/model/hybrid-serving.md, "The hybrid model as served").
inline constexpr double kRegionMaxAdvanceS = 0.01;

}  // namespace palpate::detail
