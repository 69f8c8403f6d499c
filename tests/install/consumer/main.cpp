// An application of the installed library: the run-time pieces that need
// no DDS (ids, the drawn surface and its normals, a gesture placed on it).
#include <cmath>
#include <cstdio>

#include "palpate/core/ids.hpp"
#include "palpate/core/version.hpp"
#include "palpate/runtime/drawn_surface.hpp"
#include "palpate/runtime/gesture.hpp"

int main() {
  // An octahedron of radius 1 cm: every vertex normal is its own direction.
  palpate::DrawnSurface s;
  s.compliance_vertex_count = 6;
  s.vertex_ids = {0, 1, 2, 3, 4, 5};
  s.rest_positions_m = {0, 0, .01, .01, 0, 0, 0, .01, 0, -.01, 0, 0, 0, -.01, 0, 0, 0, -.01};
  for (std::uint32_t i = 0; i < 4; ++i) {
    const std::uint32_t a = 1 + i, b = 1 + (i + 1) % 4;
    s.triangles.insert(s.triangles.end(), {0, a, b});
    s.triangles.insert(s.triangles.end(), {5, b, a});
  }
  const Eigen::MatrixX3d n = palpate::vertex_normals(s);
  if (std::abs(n(0, 2) - 1) > 1e-12 || !palpate::is_valid_id("liver")) {
    std::fprintf(stderr, "consumer: wrong answers from palpate %s\n", PALPATE_VERSION);
    return 1;
  }
  const auto gesture = palpate::parse_gesture(
      "[[tool]]\nid = \"left\"\n[[tool.keyframe]]\nt = 0\nposition = [0, 0, 2]\n", "inline");
  const auto anchors = palpate::place_gesture(gesture, s);
  std::printf("consumer: palpate %s, normal (%g, %g, %g), anchor vertex %u\n", PALPATE_VERSION,
              n(0, 0), n(0, 1), n(0, 2), anchors.front().vertex_id);
  return 0;
}
