#include "palpate/runtime/contact/tip_contacts.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "palpate/runtime/contact/contact_geometry.hpp"
#include "palpate/runtime/contact/jaw_grasp.hpp"

namespace palpate::detail {

using Eigen::Vector3d;

namespace {

/// Where on its triangle a frictionless point that pushed last tick applies its
/// load now (docs/tools.md, "Where a frictionless point pushes"): its weights w
/// then, moved by β times the step r = c − w to the closest point c of its
/// triangle now (@p closest). Plain iteration, β = 1, of "the load is at the
/// closest point of the triangle it deforms" overshoots where a wide tip's
/// load tilts its triangle more than the tip's curvature follows (a slope
/// s < −1 of c in w): the load then jumps between two places every tick.
/// Where the last step did not shrink (nor grow fourfold: then the tool
/// moved) and overshot, the slope along it, from
/// the tick before (w', r'), s − 1 = (r − r')·(w − w') / |w − w'|², gives
/// β = 1 / (1 − s), the secant's landing on the fixed point of that line;
/// else β = 1 (the plain step, which then converges). β ∈ (0, 1]: the load
/// stays on the segment from w to c, on the triangle.
std::array<double, 3> load_place(const TipCandidate& last, const std::array<double, 3>& step,
                                 const std::array<double, 3>& closest) {
  if (!last.placed) return closest;
  const std::array<double, 3>& w = last.corner_weights;
  double moved2 = 0, turned = 0, step2 = 0, step_before2 = 0;
  for (std::size_t j = 0; j < 3; ++j) {
    const double dw = w[j] - last.weights_before[j];
    moved2 += dw * dw;
    turned += (step[j] - last.step_before[j]) * dw;
    step2 += step[j] * step[j];
    step_before2 += last.step_before[j] * last.step_before[j];
  }
  // A step that shrank converges; one more than four times the last is the
  // tool's own motion (the line through both says nothing of the fixed
  // point); s < 0 ⇔ (s − 1)·|Δw|² = turned < −|Δw|².
  if (step2 < step_before2 || step2 > 16 * step_before2 || !(moved2 > 0) || -turned <= moved2)
    return closest;
  const double beta = moved2 / -turned;
  std::array<double, 3> place{};
  for (std::size_t j = 0; j < 3; ++j) place[j] = w[j] + beta * step[j];
  return place;
}

}  // namespace

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
  candidate.corner_weights = weights;
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
    const std::array<double, 3>& weights = k.corner_weights;  // 0 off the point
    Vector3d p = Vector3d::Zero();
    for (std::size_t j = 0; j < 3; ++j)
      if (weights[j] != 0) p += weights[j] * surface.deformed(corner[j]);
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
    // A frictionless point that pushed last tick from this triangle: its
    // load moves toward the closest point by the secant's step
    // (load_place); its gap, normal and target stay the closest point's,
    // the tangent plane there. (A sliding frictional point's place is also
    // where the tool drags it: the line through its last two places mixes
    // the drag with the overshoot: measured, the secant made a frictional
    // glide's largest step 1.7 times what it was.)
    const TipCandidate* last = nullptr;
    int stuck = 0;
    for (const TipCandidate& k : kept)
      if (k.triangle == tri && k.stuck < kMaterialAfter) {
        stuck = std::max(stuck, k.stuck);  // its triangle's count of sticking solves
        if (k.touched && g.friction == 0) last = &k;
      }
    std::array<double, 3> weights = pair.on_triangle.weights;
    std::array<double, 3> step{};
    if (last != nullptr) {
      for (std::size_t j = 0; j < 3; ++j) step[j] = weights[j] - last->corner_weights[j];
      weights = load_place(*last, step, weights);
    }
    const double distance = pair.distance;
    const bool active = distance < r || (was && distance < r + shell);
    if (!active && distance >= r + near) continue;
    if (between_jaws(pair.on_triangle.point, was)) continue;
    TipCandidate& candidate = found_[static_cast<std::size_t>(total)];
    if (!make_candidate(q, surface, tri, weights, pair.on_triangle.point, pair.on_segment, distance,
                        active, candidate))
      continue;
    candidate.stuck = stuck;
    if (last != nullptr) {
      candidate.weights_before = last->corner_weights;
      candidate.step_before = step;
      candidate.placed = true;
    }
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
