#pragma once
/// @file
/// The organ's surface near the tools as the last solve's loads deform it
/// (internal to the runtime; the contact engine's, docs/tools.md "One
/// tick", step 1): the drawn surface at rest (compliance vertices first,
/// then the fixed ones) with its triangles around each vertex and a grid
/// of its vertices; the loads of the last solve, f_S = Hᵀ f_C; and the
/// deformed position of a drawn vertex,
///
///     x_v = p_v + u_v,   u_v = Σ_l G^{v l} f_l      (a fixed vertex stays),
///
/// or p_v + R̃(ω_v) û_v on a warped model (docs/model/warped.md, "Large rotations:
/// warped compliance"), computed once per epoch (the loads change at each
/// solve). Which vertices and triangles lie near a tool's segment, and a
/// bound that leaves a triangle out before its corners are deformed.
/// Allocation-free after construction.

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/runtime/contact/background_loads.hpp"
#include "palpate/runtime/contact/surface_point.hpp"
#include "palpate/runtime/model/vertex_grid.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/warp/warped_rotations.hpp"

namespace palpate::detail {

/// Closest point to @p x on the segment [a, a + length·axis] (axis unit).
inline Eigen::Vector3d closest_on_segment(const Eigen::Vector3d& a, const Eigen::Vector3d& axis,
                                          double length, const Eigen::Vector3d& x) {
  const double t = std::clamp((x - a).dot(axis), 0.0, length);
  return a + t * axis;
}

class DeformedSurface {
 public:
  /// @p model (and @p warping when given) must outlive it; null: linear.
  DeformedSurface(const SurfaceModel& model, const RotationField* warping);

  int compliance_count() const { return compliance_count_; }
  bool warped() const { return warping_ != nullptr; }
  /// The drawn vertices at rest, m; the corners of every triangle (3 each).
  const std::vector<Eigen::Vector3d>& rest() const { return rest_; }
  const Eigen::Vector3d& rest(int v) const { return rest_[static_cast<std::size_t>(v)]; }
  const std::vector<int>& triangle_vertices() const { return triangle_vertices_; }
  const int* corners(int triangle) const {
    return &triangle_vertices_[3 * static_cast<std::size_t>(triangle)];
  }
  /// The outward, area-weighted normal of a triangle's first compliance
  /// corner (z when all are fixed): where a degenerate triangle pushes.
  Eigen::Vector3d vertex_normal_of(const int* corner) const;
  /// The box of the surface at rest, m.
  const Eigen::Vector3d& box_min() const { return box_min_; }
  const Eigen::Vector3d& box_max() const { return box_max_; }

  /// The last solve's loads (views of the caller's arrays, which must stay
  /// as they are until the next call): @p count compliance vertices
  /// @p index and their forces @p force (3 each, N, material when warped),
  /// and fᵀ G f (J), which bounds every vertex's displacement.
  void set_loads(int count, const int* index, const double* force, double energy);
  /// Loads that are not the tools' (the engine's background loads, linear
  /// model only), read as they are when a position is computed; null: none.
  /// They move every vertex by u_b (BackgroundLoads::at) besides the loads'.
  void set_background(BackgroundLoads* background) { background_ = background; }
  /// Forgets the deformed positions (the loads changed).
  void next_epoch();
  /// A new tick of a warped engine (its rotation memo's clock).
  void next_tick() {
    if (rotations_) rotations_->next_tick();
  }

  /// u_v = Σ_l G^{v l} f_l of compliance vertex @p v (û when warped), the
  /// background's u_b not included.
  Eigen::Vector3d load_displacement(int v) const;
  /// Deformed position of drawn vertex @p v, once per epoch.
  const Eigen::Vector3d& deformed(int v);
  /// The deformed positions of the corners of @p triangles not computed
  /// in this epoch, as deformed() computes them (the same sums in the same
  /// order), load by load (linear model; the warped one: nothing).
  void deform_corners(std::span<const int> triangles);
  /// Warped: ω of compliance vertex @p v; R̃ of a point of a triangle from
  /// the weighted mean of its vertices' ω.
  const Eigen::Vector3d& rotation_vector(int v);
  Eigen::Matrix3d point_rotation(const SurfacePoint& point) {
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    for (int i = 0; i < point.count; ++i) {
      const int v = point.vertices[static_cast<std::size_t>(i)];
      if (v < compliance_count_)
        w += point.weights[static_cast<std::size_t>(i)] * rotation_vector(v);
    }
    return integrated_rotation(w);
  }

  /// The drawn vertices whose rest position lies within @p radius of the
  /// segment [hinge, hinge + length·axis], ascending (a view of scratch,
  /// valid until the next call).
  std::span<const int> vertices_near(const Eigen::Vector3d& hinge, const Eigen::Vector3d& axis,
                                     double length, double radius);
  /// The distinct triangles around @p vertices, in the order met, hidden
  /// ones left out (a view of scratch the caller may rewrite, valid until
  /// the next call).
  std::span<int> triangles_around(std::span<const int> vertices);
  /// A hidden triangle is inside the organ (a served cut region covers it):
  /// never found by triangles_around. None is, at first.
  void set_hidden(int triangle, bool hidden) {
    triangle_hidden_.at(static_cast<std::size_t>(triangle)) = hidden ? 1 : 0;
  }
  bool hidden(int triangle) const {
    return triangle_hidden_[static_cast<std::size_t>(triangle)] != 0;
  }

  /// (1 + 1e-6) √(fᵀ G f): far_from()'s spread of the loads' displacements.
  double spread() const;
  /// The largest √‖G^{vv}‖ over every triangle's compliance corners, √(m/N).
  double max_softness() const { return max_softness_; }
  /// True when no point of triangle @p tri, deformed under the loads, can
  /// come within @p reach of the segment [hinge, hinge + length·axis]; from
  /// the triangle at rest and @p spread (spread()): a vertex moves at most
  /// √(‖G^{vv}‖ fᵀ G f) (docs/tools.md, "One tick"). The background's u_b
  /// is bounded from each corner's last known u_b and its drift since when
  /// every corner has one, else from its energy likewise. Linear model only
  /// (false on a warped one).
  bool far_from(int tri, const Eigen::Vector3d& hinge, const Eigen::Vector3d& axis, double length,
                double reach, double spread) const;

 private:
  const SurfaceModel& model_;
  const RotationField* warping_;
  int compliance_count_ = 0;
  std::vector<Eigen::Vector3d> rest_;                           // per drawn vertex
  std::vector<Eigen::Vector3d> vertex_normal_;                  // per compliance vertex, outward
  std::vector<int> triangle_vertices_;                          // 3 per triangle
  std::vector<int> vertex_triangles_begin_, vertex_triangles_;  // triangles around each vertex
  std::vector<Eigen::Vector3d> triangle_centre_;  // per triangle, its corners' centre at rest
  std::vector<double> triangle_radius_;           // per triangle: farthest corner from it, m
  std::vector<double> triangle_softness_;  // per triangle: max √‖G^{vv}‖ of its corners
  double max_softness_ = 0;
  Eigen::Vector3d box_min_, box_max_;
  VertexGrid grid_;
  BackgroundLoads* background_ = nullptr;
  // The loads (views) and the deformed positions of this epoch.
  int load_count_ = 0;
  const int* load_index_ = nullptr;
  const double* load_force_ = nullptr;
  double load_energy_ = 0;
  std::uint32_t epoch_ = 0;
  std::vector<std::uint32_t> position_seen_;  // per drawn vertex: the epoch of position_
  std::vector<Eigen::Vector3d> position_;
  std::optional<WarpedRotations> rotations_;  // warped: û and ω met this tick
  // Scratch.
  std::vector<int> near_vertices_;
  std::vector<std::uint64_t> near_bits_;  // per drawn vertex
  std::uint32_t triangle_epoch_ = 0;
  std::vector<std::uint32_t> triangle_seen_;
  std::vector<char> triangle_hidden_;
  std::vector<int> near_triangles_;
  std::vector<std::uint64_t> wanted_bits_;  // per compliance vertex
  std::vector<int> wanted_;
  std::vector<Eigen::Vector3d> wanted_u_;
};

}  // namespace palpate::detail
