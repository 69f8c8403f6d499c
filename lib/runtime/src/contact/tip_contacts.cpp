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

bool TipContacts::make_candidate(const TipQuery& q, DeformedSurface& surface, int tri,
                                 const std::array<double, 3>& weights, const Vector3d& p,
                                 const Vector3d& on_segment, double distance, bool active,
                                 TipCandidate& candidate) const {
  const ToolGeometry& g = *q.geometry;
  const double r = g.tip_radius_m;
  const int* corner = surface.corners(tri);
  const Vector3d& a = surface.deformed(corner[0]);
  const Vector3d& b = surface.deformed(corner[1]);
  const Vector3d& cc = surface.deformed(corner[2]);
  // Pushed from the axis to the point, onto the tip's surface. That
  // normal's tangent plane bounds the tip (it is convex), so a sliding
  // contact never pulls while the tissue would spring into the tip.
  // An axis on the triangle, or beyond it (the tip pushed through in
  // one tick), pushes along the triangle's inward normal.
  const Vector3d outward = (b - a).cross(cc - a);
  Vector3d normal = outward.squaredNorm() > 0 ? Vector3d(-outward.normalized())
                                              : Vector3d(-surface.vertex_normal_of(corner));
  if (distance > 1e-9 * r && (p - on_segment).dot(outward) <= 0)
    normal = (p - on_segment) / distance;
  candidate = TipCandidate{
      {tri, 0, {}, {}, Vector3d::Zero()}, r - distance, normal, on_segment + r * normal, p, active};
  bool movable = false;
  for (int i = 0; i < 3; ++i) {
    const double w = weights[static_cast<std::size_t>(i)];
    if (w == 0) continue;  // on the opposite edge: not part of the point
    candidate.vertices[static_cast<std::size_t>(candidate.count)] = corner[i];
    candidate.weights[static_cast<std::size_t>(candidate.count)] = w;
    ++candidate.count;
    candidate.rest += w * surface.rest(corner[i]);
    movable |= corner[i] < surface.compliance_count();
  }
  return movable;  // else a point of the attachment's edge
}

int TipContacts::find(const TipQuery& q, DeformedSurface& surface, std::span<const int> owner,
                      std::span<const int> previous_owner, std::span<const TipCandidate> kept,
                      std::span<TipCandidate> out) {
  const int compliance_count = surface.compliance_count();
  const ToolGeometry& g = *q.geometry;
  const Vector3d axis = q.rotation.col(2);
  const double r = g.tip_radius_m;
  const double shell = 0.05 * r;  // a contact stays while within 5 % of r outside the tip
  const double near = 0.25 * r;   // points this close are watched during the solve
  const bool jaws_open = g.jaw_length_m > 0 && q.jaw_angle_rad > g.grasp_angle_rad;
  // Tissue between open jaws is not pushed (it may be grasped), unless it
  // was pushed last tick.
  const auto between_jaws = [&](const Vector3d& p, bool was) {
    return jaws_open && !q.holding && !was &&
           JawGrasp::between({q.hinge, q.rotation, q.geometry, q.jaw_angle_rad}, p,
                             q.jaw_angle_rad);
  };
  // A triangle with a vertex of a held point, or wholly fixed, is not touched.
  const auto touchable = [&](int tri) {
    const int* corner = surface.corners(tri);
    int fixed = 0;
    for (int i = 0; i < 3; ++i) {
      if (corner[i] >= compliance_count)
        ++fixed;
      else if (owner[static_cast<std::size_t>(corner[i])] >= 0)
        return false;
    }
    return fixed < 3;
  };
  int total = 0;
  // The kept points first, material: the same triangle and weights, where
  // the surface has them now.
  // One that has not stuck for kMaterialAfter solves is not kept: the tip
  // slides over the tissue, and its triangle's closest point is found
  // below with the new ones.
  for (const TipCandidate& k : kept) {
    if (k.stuck < kMaterialAfter || surface.hidden(k.triangle) || !touchable(k.triangle)) continue;
    const int one[1] = {k.triangle};
    surface.deform_corners(one);
    const int* corner = surface.corners(k.triangle);
    std::array<double, 3> weights{};
    Vector3d p = Vector3d::Zero();
    for (int i = 0; i < k.count; ++i)
      for (int j = 0; j < 3; ++j)
        if (corner[j] == k.vertices[static_cast<std::size_t>(i)]) {
          weights[static_cast<std::size_t>(j)] = k.weights[static_cast<std::size_t>(i)];
          p += k.weights[static_cast<std::size_t>(i)] * surface.deformed(corner[j]);
        }
    const Vector3d on_segment = closest_on_segment(q.hinge, axis, tip_length(g), p);
    const double distance = (p - on_segment).norm();
    const bool active = distance < r || (k.touched && distance < r + shell);
    if (!active && distance >= r + near) continue;
    if (between_jaws(p, k.touched)) continue;
    TipCandidate& candidate = found_[static_cast<std::size_t>(total)];
    if (!make_candidate(q, surface, k.triangle, weights, p, on_segment, distance, active,
                        candidate))
      continue;
    candidate.touched = k.touched;
    candidate.stuck = k.stuck;
    ranked_[static_cast<std::size_t>(total)] = {candidate.depth, total};
    ++total;
  }
  const int kept_total = total;
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
  for (const int tri : near_triangles)
    if (touchable(tri) &&
        !(screen && surface.far_from(tri, q.hinge, axis, tip_length(g), r + near, spread)))
      near_triangles[m++] = tri;
  surface.deform_corners(near_triangles.first(m));
  for (const int tri : near_triangles.first(m)) {
    if (total == static_cast<int>(found_.size())) break;
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
    if (between_jaws(pair.on_triangle.point, was)) continue;
    TipCandidate& candidate = found_[static_cast<std::size_t>(total)];
    if (!make_candidate(q, surface, tri, pair.on_triangle.weights, pair.on_triangle.point,
                        pair.on_segment, pair.distance, active, candidate))
      continue;
    for (const TipCandidate& k : kept)  // its triangle's count of sticking solves
      if (k.triangle == tri && k.stuck < kMaterialAfter)
        candidate.stuck = std::max(candidate.stuck, k.stuck);
    ranked_[static_cast<std::size_t>(total)] = {candidate.depth, total};
    ++total;
  }
  // Deepest first, the kept points before the new ones; a point on an edge
  // or a vertex is found from every triangle around it: keep it once.
  // Points closer than 0.05 r to a deeper one would add a nearly equal row
  // (and the surface between them stays within ~(0.05 r)²/2r = 0.1 % of r
  // of the tip). A sticking point fixes three components, so with friction
  // points keep 0.3 r apart (within ~4.5 % of r): closer ones make a nearly
  // singular system. A kept point goes only when another kept one comes
  // within half that spacing (the points move with the tissue): the
  // hysteresis that keeps a still tool's points the same.
  // (Their depths are sorted, not the points: the same comparisons, so
  // the same order, equal depths included, without moving the points.)
  const auto deeper = [](const Ranked& x, const Ranked& y) { return x.depth > y.depth; };
  std::sort(ranked_.begin(), ranked_.begin() + kept_total, deeper);
  std::sort(ranked_.begin() + kept_total, ranked_.begin() + total, deeper);
  const double spacing2 = (g.friction > 0 ? 0.09 : 0.0025) * r * r;
  // Two points closer than r cannot push the tip from opposite sides: where
  // their pushes oppose, the tip has reached through a fold of tissue
  // thinner than itself, and one of them is the fold's far face, found from
  // within. Both kept, their rows are nearly opposite (a singular system:
  // forces of kilonewtons that cancel, points flung decimetres). The one
  // pushed more along the tool's direction z (away from the tool) stays.
  int kept_out = 0;
  for (int c = 0; c < total && kept_out < static_cast<int>(out.size()); ++c) {
    const TipCandidate& x =
        found_[static_cast<std::size_t>(ranked_[static_cast<std::size_t>(c)].index)];
    const bool x_kept = c < kept_total;
    // The spacing compares target − depth·n (spaced_at), the point itself
    // where n is the axis-to-point direction (as it always did); the
    // folds compare the points on the triangles.
    const Vector3d spaced_at = x.target - x.depth * x.normal;
    bool crowded = false;
    int replaced = -1;
    for (int k = 0; k < kept_out && !crowded; ++k) {
      const TipCandidate& y = out[static_cast<std::size_t>(k)];
      if (x.normal.dot(y.normal) < 0 && (y.point - x.point).squaredNorm() < r * r) {
        if (x.normal.dot(axis) > y.normal.dot(axis) && replaced < 0)
          replaced = k;
        else
          crowded = true;
        continue;
      }
      crowded = (y.target - y.depth * y.normal - spaced_at).squaredNorm() <
                (x_kept ? 0.25 * spacing2 : spacing2);
    }
    if (crowded) continue;
    out[static_cast<std::size_t>(replaced >= 0 ? replaced : kept_out++)] = x;
  }
  return kept_out;
}

}  // namespace palpate::detail
