#include "palpate/runtime/contact/tip_contacts.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "palpate/runtime/contact/contact_geometry.hpp"
#include "palpate/runtime/contact/jaw_grasp.hpp"

namespace palpate::detail {

using Eigen::Vector3d;

TipContacts::TipContacts(int triangles)
    : found_(static_cast<std::size_t>(triangles)), ranked_(static_cast<std::size_t>(triangles)) {}

int TipContacts::find(const TipQuery& q, DeformedSurface& surface, std::span<const int> owner,
                      std::span<const int> previous_owner, std::span<TipCandidate> out) {
  const int compliance_count = surface.compliance_count();
  const ToolGeometry& g = *q.geometry;
  const Vector3d axis = q.rotation.col(2);
  const double r = g.tip_radius_m;
  const double shell = 0.05 * r;  // a contact stays while within 5 % of r outside the tip
  const double near = 0.25 * r;   // triangles this close are watched during the solve
  const bool jaws_open = g.jaw_length_m > 0 && q.jaw_angle_rad > g.grasp_angle_rad;
  int total = 0;
  // The triangles to test, in the order met: none with a vertex of a
  // held point, none wholly fixed.
  const std::span<int> near_triangles = surface.triangles_around(
      surface.vertices_near(q.hinge, axis, reach_length(g), q.search_radius));
  std::size_t m = 0;
  // far_from_tip pays only where it can skip triangles: each candidate
  // triangle has a corner within the search radius of the axis, so none is
  // skipped unless the loads move the softest triangle's points less than
  // that radius minus r + near (a deep wide press moves them more).
  const double spread = surface.spread();
  const bool screen =
      !surface.warped() && surface.max_softness() * spread + r + near < q.search_radius;
  for (const int tri : near_triangles) {
    const int* corner = surface.corners(tri);
    bool blocked = false;
    int fixed = 0;
    for (int i = 0; i < 3; ++i) {
      if (corner[i] >= compliance_count)
        ++fixed;
      else if (owner[static_cast<std::size_t>(corner[i])] >= 0)
        blocked = true;
    }
    if (!blocked && fixed < 3 &&
        !(screen && surface.far_from(tri, q.hinge, axis, tip_length(g), r + near, spread)))
      near_triangles[m++] = tri;
  }
  surface.deform_corners(near_triangles.first(m));
  for (const int tri : near_triangles.first(m)) {
    const int* corner = surface.corners(tri);
    const Vector3d& a = surface.deformed(corner[0]);
    const Vector3d& b = surface.deformed(corner[1]);
    const Vector3d& cc = surface.deformed(corner[2]);
    // Most of a wide tip's triangles are far from it: a triangle within
    // the ball about its centre through its farthest corner, a ball
    // r + near away from the axis, has no point nearer, and goes without
    // its closest points. The margin, 1e-6 r, is far above the round-off
    // of either distance: this skips only what the test below would.
    // (Any centre will do; the distances compare squared.)
    const Vector3d centre = (a + b + cc) * (1.0 / 3);
    const double ball = std::sqrt(std::max(
        {(a - centre).squaredNorm(), (b - centre).squaredNorm(), (cc - centre).squaredNorm()}));
    const double beyond = r + near + 1e-6 * r + ball;
    if ((centre - closest_on_segment(q.hinge, axis, tip_length(g), centre)).squaredNorm() >=
        beyond * beyond)
      continue;
    const detail::SegmentTrianglePair pair =
        closest_segment_triangle(q.hinge, axis, tip_length(g), a, b, cc);
    const bool was = previous_owner[static_cast<std::size_t>(tri)] == q.tool;
    const bool active = pair.distance < r || (was && pair.distance < r + shell);
    if (!active && pair.distance >= r + near) continue;
    const Vector3d& p = pair.on_triangle.point;
    // Tissue between open jaws is not pushed: it may be grasped.
    if (jaws_open && !q.holding && !was &&
        JawGrasp::between({q.hinge, q.rotation, q.geometry, q.jaw_angle_rad}, p, q.jaw_angle_rad))
      continue;
    // Pushed from the axis to the point, onto the tip's surface. That
    // normal's tangent plane bounds the tip (it is convex), so a sliding
    // contact never pulls while the tissue would spring into the tip.
    // An axis on the triangle, or beyond it (the tip pushed through in
    // one tick), pushes along the triangle's inward normal.
    const Vector3d outward = (b - a).cross(cc - a);
    Vector3d normal = outward.squaredNorm() > 0 ? Vector3d(-outward.normalized())
                                                : Vector3d(-surface.vertex_normal_of(corner));
    if (pair.distance > 1e-9 * r && (p - pair.on_segment).dot(outward) <= 0)
      normal = (p - pair.on_segment) / pair.distance;
    TipCandidate candidate{{tri, 0, {}, {}, Vector3d::Zero()},
                           r - pair.distance,
                           normal,
                           pair.on_segment + r * normal,
                           p,
                           active};
    bool movable = false;
    for (int i = 0; i < 3; ++i) {
      const double w = pair.on_triangle.weights[static_cast<std::size_t>(i)];
      if (w == 0) continue;  // on the opposite edge: not part of the point
      candidate.vertices[static_cast<std::size_t>(candidate.count)] = corner[i];
      candidate.weights[static_cast<std::size_t>(candidate.count)] = w;
      ++candidate.count;
      candidate.rest += w * surface.rest(corner[i]);
      movable |= corner[i] < compliance_count;
    }
    if (!movable) continue;  // a point of the attachment's edge
    ranked_[static_cast<std::size_t>(total)] = {candidate.depth, total};
    found_[static_cast<std::size_t>(total++)] = candidate;
  }
  // Deepest first; a point on an edge or a vertex is found from every
  // triangle around it: keep it once. Points closer than 0.05 r to a
  // deeper one would add a nearly equal row (and the surface between them
  // stays within ~(0.05 r)²/2r = 0.1 % of r of the tip). A sticking point
  // fixes three components, so with friction points keep 0.3 r apart
  // (within ~4.5 % of r): closer ones make a nearly singular system.
  // (Their depths are sorted, not the points: the same comparisons, so
  // the same order, equal depths included, without moving the points.)
  std::sort(ranked_.begin(), ranked_.begin() + total,
            [](const Ranked& x, const Ranked& y) { return x.depth > y.depth; });
  const double spacing2 = (g.friction > 0 ? 0.09 : 0.0025) * r * r;
  // Two points closer than r cannot push the tip from opposite sides: where
  // their pushes oppose, the tip has reached through a fold of tissue
  // thinner than itself, and one of them is the fold's far face, found from
  // within. Both kept, their rows are nearly opposite (a singular system:
  // forces of kilonewtons that cancel, points flung decimetres). The one
  // pushed more along the tool's direction z (away from the tool) stays.
  int kept = 0;
  for (int c = 0; c < total && kept < static_cast<int>(out.size()); ++c) {
    const TipCandidate& x =
        found_[static_cast<std::size_t>(ranked_[static_cast<std::size_t>(c)].index)];
    // The spacing compares target − depth·n (spaced_at), the point itself
    // where n is the axis-to-point direction (as it always did); the
    // folds compare the points on the triangles.
    const Vector3d spaced_at = x.target - x.depth * x.normal;
    bool crowded = false;
    int replaced = -1;
    for (int k = 0; k < kept && !crowded; ++k) {
      const TipCandidate& y = out[static_cast<std::size_t>(k)];
      if (x.normal.dot(y.normal) < 0 && (y.point - x.point).squaredNorm() < r * r) {
        if (x.normal.dot(axis) > y.normal.dot(axis) && replaced < 0)
          replaced = k;
        else
          crowded = true;
        continue;
      }
      crowded = (y.target - y.depth * y.normal - spaced_at).squaredNorm() < spacing2;
    }
    if (crowded) continue;
    out[static_cast<std::size_t>(replaced >= 0 ? replaced : kept++)] = x;
  }
  return kept;
}

}  // namespace palpate::detail
