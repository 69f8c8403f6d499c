#include "palpate/runtime/contact/contact_geometry.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace palpate::detail {

using Eigen::Vector3d;

TrianglePoint closest_on_triangle(const Vector3d& x, const Vector3d& a, const Vector3d& b,
                                  const Vector3d& c) {
  // The regions of the vertices, then of the edges, else the face.
  const Vector3d ab = b - a, ac = c - a, ax = x - a;
  const double d1 = ab.dot(ax), d2 = ac.dot(ax);
  if (d1 <= 0 && d2 <= 0) return {a, {1, 0, 0}};
  const Vector3d bx = x - b;
  const double d3 = ab.dot(bx), d4 = ac.dot(bx);
  if (d3 >= 0 && d4 <= d3) return {b, {0, 1, 0}};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double t = d1 / (d1 - d3);
    return {a + t * ab, {1 - t, t, 0}};
  }
  const Vector3d cx = x - c;
  const double d5 = ab.dot(cx), d6 = ac.dot(cx);
  if (d6 >= 0 && d5 <= d6) return {c, {0, 0, 1}};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double t = d2 / (d2 - d6);
    return {a + t * ac, {1 - t, 0, t}};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {b + t * (c - b), {0, 1 - t, t}};
  }
  const double denominator = 1 / (va + vb + vc);
  const double v = vb * denominator, w = vc * denominator;
  return {a + v * ab + w * ac, {1 - v - w, v, w}};
}

namespace {

/// Closest points of segments p + s·d (s ∈ [0, 1]) and q + t·e (t ∈ [0, 1]).
void closest_segment_segment(const Vector3d& p, const Vector3d& d, const Vector3d& q,
                             const Vector3d& e, double& s, double& t) {
  const Vector3d r = p - q;
  const double a = d.squaredNorm(), b = d.dot(e), c = e.squaredNorm();
  const double f = e.dot(r), g = d.dot(r);
  const double denominator = a * c - b * b;
  s = denominator > 1e-14 * a * c ? std::clamp((b * f - c * g) / denominator, 0.0, 1.0) : 0.0;
  t = (b * s + f) / c;
  if (t < 0) {
    t = 0;
    s = std::clamp(-g / a, 0.0, 1.0);
  } else if (t > 1) {
    t = 1;
    s = std::clamp((b - g) / a, 0.0, 1.0);
  }
}

}  // namespace

SegmentTrianglePair closest_segment_triangle(const Vector3d& start, const Vector3d& axis,
                                             double length, const Vector3d& a, const Vector3d& b,
                                             const Vector3d& c) {
  SegmentTrianglePair best{start, closest_on_triangle(start, a, b, c), 0};
  best.distance = (best.on_triangle.point - start).norm();
  if (length <= 0) return best;

  // Does the segment cross the triangle? (Möller–Trumbore.)
  const Vector3d ab = b - a, ac = c - a;
  const Vector3d h = axis.cross(ac);
  const double det = ab.dot(h);
  if (std::abs(det) > 1e-300) {
    const double inverse = 1 / det;
    const Vector3d s = start - a;
    const double u = inverse * s.dot(h);
    const Vector3d qv = s.cross(ab);
    const double v = inverse * axis.dot(qv);
    const double t = inverse * ac.dot(qv);
    if (u >= 0 && v >= 0 && u + v <= 1 && t >= 0 && t <= length) {
      const Vector3d x = start + t * axis;
      return {x, {x, {1 - u - v, u, v}}, 0};
    }
  }
  auto consider = [&](const Vector3d& on_segment, const TrianglePoint& on_triangle) {
    const double distance = (on_triangle.point - on_segment).norm();
    if (distance < best.distance) best = {on_segment, on_triangle, distance};
  };
  const Vector3d end = start + length * axis;
  consider(end, closest_on_triangle(end, a, b, c));
  const Vector3d segment = end - start;
  const std::array<Vector3d, 3> corner{a, b, c};
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3;
    double s = 0, t = 0;
    closest_segment_segment(start, segment, corner[i], corner[j] - corner[i], s, t);
    TrianglePoint on{corner[i] + t * (corner[j] - corner[i]), {0, 0, 0}};
    on.weights[i] = 1 - t;
    on.weights[j] = t;
    consider(start + s * segment, on);
  }
  return best;
}

}  // namespace palpate::detail
