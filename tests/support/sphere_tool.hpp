#pragma once
// A sphere-tipped tool without jaws, for the tests that press or glide with
// one: its force limit (100 N) and rate (1e9 N/s) out of the way of what
// they check.

#include <string>

#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::testing {

inline ToolGeometry sphere_tool(const std::string& id, double radius_m, double friction = 0) {
  ToolGeometry g;
  g.id = id;
  g.tip = TipShape::kSphere;
  g.tip_radius_m = radius_m;
  g.tip_length_m = 0;
  g.friction = friction;
  g.jaw_length_m = 0;
  g.force_limit_n = 100;
  g.max_force_rate_n_per_s = 1e9;
  return g;
}

}  // namespace palpate::testing
