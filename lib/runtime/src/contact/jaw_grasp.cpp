#include "palpate/runtime/contact/jaw_grasp.hpp"

#include <algorithm>
#include <cmath>

#include "palpate/runtime/contact/contact_geometry.hpp"

namespace palpate::detail {

using Eigen::Vector3d;

IndependentRows::IndependentRows(int rows)
    : capacity_(rows),
      column_vertex_(3 * static_cast<std::size_t>(rows)),
      basis_(3 * static_cast<std::size_t>(rows) * static_cast<std::size_t>(rows), 0.0),
      row_(3 * static_cast<std::size_t>(rows), 0.0) {}

void IndependentRows::clear() {
  const auto stride = 3 * static_cast<std::size_t>(capacity_);
  std::fill(basis_.begin(), basis_.begin() + static_cast<std::ptrdiff_t>(stride) * rows_, 0.0);
  rows_ = 0;
  columns_ = 0;
}

bool IndependentRows::add(std::span<const int> vertices, std::span<const double> weights,
                          double threshold) {
  if (rows_ == capacity_) return false;
  const auto stride = 3 * static_cast<std::size_t>(capacity_);
  std::fill(row_.begin(), row_.end(), 0.0);
  int columns = columns_;
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    const int v = vertices[i];
    if (v < 0 || weights[i] == 0) continue;  // fixed: no unknown
    int c = 0;
    while (c < columns && column_vertex_[static_cast<std::size_t>(c)] != v) ++c;
    if (c == columns) {
      if (columns == static_cast<int>(stride)) return false;
      column_vertex_[static_cast<std::size_t>(columns++)] = v;
    }
    row_[static_cast<std::size_t>(c)] += weights[i];
  }
  // Gram–Schmidt, twice (the second pass removes the first's round-off).
  for (int pass = 0; pass < 2; ++pass)
    for (int q = 0; q < rows_; ++q) {
      const double* basis = &basis_[stride * static_cast<std::size_t>(q)];
      double dot = 0;
      for (int c = 0; c < columns; ++c) dot += basis[c] * row_[static_cast<std::size_t>(c)];
      for (int c = 0; c < columns; ++c) row_[static_cast<std::size_t>(c)] -= dot * basis[c];
    }
  double norm2 = 0;
  for (int c = 0; c < columns; ++c)
    norm2 += row_[static_cast<std::size_t>(c)] * row_[static_cast<std::size_t>(c)];
  const double norm = std::sqrt(norm2);
  if (!(norm >= threshold)) return false;
  double* basis = &basis_[stride * static_cast<std::size_t>(rows_++)];
  for (int c = 0; c < columns; ++c) basis[c] = row_[static_cast<std::size_t>(c)] / norm;
  columns_ = columns;
  return true;
}

namespace {

// Points on each jaw face: along the jaw, across it.
constexpr int kAlong = 4, kAcross = 2;
// A held point's row must keep this much of its weight vector outside the
// span of the rows already held (a full row has a norm of 1/√3 to 1). Held
// points are squeezed towards each other: two whose rows are close to
// dependent need large vertex motions for a small relative one, and the
// squeeze then pairs them with large opposite forces (0.2 gave ±50 N on the
// 12.5 mm test box); 0.5 keeps them about a vertex apart in weight space.
constexpr double kIndependence = 0.5;
// Points closer than this (× the tip's radius) to a held one add nothing.
constexpr double kSpacing = 0.1;

}  // namespace

JawGrasp::JawGrasp(int capacity, int compliance_count)
    : compliance_count_(compliance_count), rows_(capacity) {
  held_positions_.reserve(static_cast<std::size_t>(capacity));
}

bool JawGrasp::between(const JawsAtClosing& jaws, const Vector3d& x, double angle,
                       double beyond_m) {
  const ToolGeometry& g = *jaws.geometry;
  if (g.jaw_length_m <= 0) return false;
  const Vector3d local = jaws.rotation.transpose() * (x - jaws.hinge);
  return local.z() >= 0 && local.z() <= g.jaw_length_m + beyond_m &&
         std::abs(local.y()) <= 0.5 * g.jaw_width_m + g.tip_radius_m &&
         std::abs(local.x()) <= local.z() * std::tan(0.5 * angle) + g.tip_radius_m;
}

bool JawGrasp::keep(const JawsAtClosing& jaws, HeldPoint point, const Vector3d& deformed,
                    bool touched, std::vector<HeldPoint>& held, int capacity) {
  const ToolGeometry& g = *jaws.geometry;
  if (static_cast<int>(held.size()) >= capacity) return false;
  // Under a face, or at the closed jaws' rounded end (the tip's radius
  // beyond them); what the tip pressed is held wherever it is.
  if (!touched && !between(jaws, deformed, jaws.opening_rad, g.tip_radius_m)) return false;
  const double spacing2 = kSpacing * kSpacing * g.tip_radius_m * g.tip_radius_m;
  for (const Vector3d& x : held_positions_)
    if ((x - deformed).squaredNorm() < spacing2) return false;
  std::array<int, 3> unknown{};
  for (int i = 0; i < point.count; ++i) {
    const int v = point.vertices[static_cast<std::size_t>(i)];
    unknown[static_cast<std::size_t>(i)] = v < compliance_count_ ? v : -1;
  }
  if (!rows_.add({unknown.data(), static_cast<std::size_t>(point.count)},
                 {point.weights.data(), static_cast<std::size_t>(point.count)}, kIndependence))
    return false;
  Vector3d local = jaws.rotation.transpose() * (deformed - jaws.hinge);
  point.side = local.x() >= 0 ? 1.0 : -1.0;
  local.z() = std::clamp(local.z(), 0.0, g.jaw_length_m);
  point.local = local;
  held.push_back(point);
  held_positions_.push_back(deformed);
  return true;
}

int JawGrasp::choose(const JawsAtClosing& jaws, std::span<const int> triangles,
                     std::span<const Vector3d> corners, std::span<const int> triangle_vertices,
                     std::span<const Vector3d> rest, std::span<const HeldPoint> touched,
                     std::vector<HeldPoint>& held, int capacity) {
  const ToolGeometry& g = *jaws.geometry;
  const std::size_t before = held.size();
  rows_.clear();
  held_positions_.clear();
  // What the tip pressed: certainly between the jaws' faces now.
  for (const HeldPoint& point : touched) {
    Vector3d deformed = Vector3d::Zero();
    bool found = false;
    for (std::size_t k = 0; k < triangles.size() && !found; ++k) {
      if (triangles[k] != point.triangle) continue;
      // Barycentric weights are on the point's non-zero vertices; find each
      // among the triangle's corners.
      for (int i = 0; i < point.count; ++i)
        for (int c = 0; c < 3; ++c)
          if (triangle_vertices[3 * static_cast<std::size_t>(point.triangle) +
                                static_cast<std::size_t>(c)] ==
              point.vertices[static_cast<std::size_t>(i)])
            deformed += point.weights[static_cast<std::size_t>(i)] *
                        corners[3 * k + static_cast<std::size_t>(c)];
      found = true;
    }
    if (found) keep(jaws, point, deformed, true, held, capacity);
  }
  // The tissue under each face as it was open: the nearest surface point to
  // a grid on the face, the two faces alternating.
  const double slope = std::tan(0.5 * jaws.opening_rad);
  for (int a = 0; a < kAlong; ++a)
    for (int b = 0; b < kAcross; ++b)
      for (const double side : {1.0, -1.0}) {
        const double z = g.jaw_length_m * (a + 0.5) / kAlong;
        const double y = g.jaw_width_m * ((b + 0.5) / kAcross - 0.5);
        const Vector3d on_face = jaws.hinge + jaws.rotation * Vector3d(side * z * slope, y, z);
        double best = INFINITY;
        std::size_t best_k = 0;
        TrianglePoint nearest{Vector3d::Zero(), {}};
        for (std::size_t k = 0; k < triangles.size(); ++k) {
          const TrianglePoint p =
              closest_on_triangle(on_face, corners[3 * k], corners[3 * k + 1], corners[3 * k + 2]);
          const double d2 = (p.point - on_face).squaredNorm();
          if (d2 < best) best = d2, best_k = k, nearest = p;
        }
        if (!(best < INFINITY)) continue;
        HeldPoint point;
        point.triangle = triangles[best_k];
        for (int c = 0; c < 3; ++c) {
          const double w = nearest.weights[static_cast<std::size_t>(c)];
          if (w == 0) continue;
          const int v = triangle_vertices[3 * static_cast<std::size_t>(point.triangle) +
                                          static_cast<std::size_t>(c)];
          point.vertices[static_cast<std::size_t>(point.count)] = v;
          point.weights[static_cast<std::size_t>(point.count)] = w;
          point.rest += w * rest[static_cast<std::size_t>(v)];
          ++point.count;
        }
        keep(jaws, point, nearest.point, false, held, capacity);
      }
  // Squeezed between the closing faces onto one plane x = const: the
  // middle of the held tissue, so that the squeeze itself is balanced (a
  // flap centred between the jaws goes to their mid-plane; a strip of a
  // broad surface is pinched about its own middle, not dragged sideways).
  if (held.size() > before) {
    double low = INFINITY, high = -INFINITY;
    for (std::size_t i = before; i < held.size(); ++i) {
      low = std::min(low, held[i].local.x());
      high = std::max(high, held[i].local.x());
    }
    for (std::size_t i = before; i < held.size(); ++i) held[i].local.x() = 0.5 * (low + high);
  }
  return static_cast<int>(held.size() - before);
}

}  // namespace palpate::detail
