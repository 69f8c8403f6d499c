#pragma once
/// @file
/// The local rotation of the surface, for warped compliance (docs/model/warped.md,
/// "Large rotations: warped compliance"). A linear operator from the
/// displacement of the compliance vertices to a rotation vector ω at each
/// of them, and the rotation matrices made from ω.

#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/drawn_surface.hpp"

namespace palpate {

/// ω = S Ω u: the infinitesimal rotation of every compliance vertex's
/// neighbourhood under a displacement u of the compliance vertices.
///
/// Ω, per vertex v: the displacement gradient A (3 × 3) fitted by least
/// squares on the edges to v's neighbours on the surface (u_j − u_v ≈
/// A (p_j − p_v)), with the condition that the normal n_v is not stretched
/// nor sheared, sym(A) n_v = 0, which a flat neighbourhood needs to fix A n_v;
/// ω_v is the axial vector of A's skew part. A rigid rotation u = θ × (p − c)
/// gives ω = θ exactly, flat or curved neighbourhood. Fixed vertices do not
/// move (u = 0 there).
///
/// S: a Gaussian average of the vertex rotations over the compliance
/// vertices within 2ρ (rest distance, weights exp(−d²/ρ²)). The surface
/// rotates over the length scale of its bending; rotations that change from
/// one vertex to the next amplify into the warped positions (p + R̃ û moves a
/// vertex by |û| per radian), so ω is taken over a neighbourhood of radius ρ
/// rather than a single ring.
class RotationField {
 public:
  /// @p surface the model's drawn surface (compliance vertices first).
  /// @p smoothing_radius_m ρ, > 0.
  RotationField(const DrawnSurface& surface, double smoothing_radius_m);

  /// ω (3 per compliance vertex, rad) from u (3 per compliance vertex, m).
  /// Allocation-free.
  void rotations(std::span<const double> u_m, std::span<double> omega) const;

  /// The compliance vertices whose displacement rotation_at(@p v) reads,
  /// appended to @p out once each (@p mark, one per compliance vertex, says
  /// which are in; the caller clears it).
  void support(int v, std::vector<char>& mark, std::vector<int>& out) const;
  /// ω at compliance vertex @p v alone, reading u (3 per compliance vertex)
  /// only on support(v): equal to rotations() there.
  Eigen::Vector3d rotation_at(int v, std::span<const double> u_m) const;

  /// The two steps of rotation_at() apart, for callers that keep what they
  /// computed (the contact engine, vertex by vertex within a tick): Ω_b u at
  /// vertex @p b, with @p u(j) the displacement of compliance vertex j; and
  /// Σ_b S_vb fitted(b) at vertex @p v.
  template <typename U>
  Eigen::Vector3d fitted_at(int b, U&& u) const {
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    for (int i = fit_start_[static_cast<std::size_t>(b)];
         i < fit_start_[static_cast<std::size_t>(b) + 1]; ++i)
      w += Eigen::Map<const Eigen::Matrix3d>(&fit_block_[9 * static_cast<std::size_t>(i)]) *
           u(fit_vertex_[static_cast<std::size_t>(i)]);
    return w;
  }
  template <typename Fitted>
  Eigen::Vector3d smoothed_at(int v, Fitted&& fitted) const {
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    for (int k = smooth_start_[static_cast<std::size_t>(v)];
         k < smooth_start_[static_cast<std::size_t>(v) + 1]; ++k)
      w += smooth_weight_[static_cast<std::size_t>(k)] *
           fitted(smooth_vertex_[static_cast<std::size_t>(k)]);
    return w;
  }

  int vertex_count() const { return n_; }
  double smoothing_radius_m() const { return radius_; }
  /// Average number of vertices in one smoothing neighbourhood.
  double mean_neighbourhood() const;

 private:
  int n_ = 0;
  double radius_ = 0;
  // Ω in compressed rows: vertex v's blocks Ω_vj (3 × 3, row-major) for the
  // compliance vertices j of its ring and v itself.
  std::vector<int> fit_start_, fit_vertex_;
  std::vector<double> fit_block_;
  // S in compressed rows: weights summing to 1.
  std::vector<int> smooth_start_, smooth_vertex_;
  std::vector<double> smooth_weight_;
  mutable std::vector<double> fitted_;  // Ω u, 3 per vertex
};

/// ρ = @p edges × the median edge of the surface's triangles among
/// compliance vertices. Requests: kRequestEdges (the flap's checks against
/// a nonlinear reference, docs/model/warped.md: 1.2 to 1.5 edges meet the 15°
/// target, larger radii average the bend away). The contact engine:
/// kToolEdges (it takes each tick's rotations from the previous tick, without
/// the requests' relaxation, and at 1.5 or 3 edges a grasped flap swung up
/// drifts sideways; at 6 it does not, docs/tools.md).
constexpr double kRequestEdges = 1.5;
constexpr double kToolEdges = 6.0;
double default_smoothing_radius(const DrawnSurface& surface, double edges = kRequestEdges);

/// exp([ω]×): the rotation by |ω| about ω/|ω|.
Eigen::Matrix3d rotation_matrix(const Eigen::Vector3d& omega);

/// R̃(ω) = ∫₀¹ exp(s[ω]×) ds = I + (1 − cos α)/α² [ω]× + (α − sin α)/α³ [ω]×²,
/// α = |ω|: the map from a material displacement û to the warped one,
/// x − p = R̃ û. For û = ω × (p − c), R̃ û = (exp([ω]×) − I)(p − c): an
/// infinitesimal rotation becomes the finite one. Invertible for α < 2π.
Eigen::Matrix3d integrated_rotation(const Eigen::Vector3d& omega);

}  // namespace palpate
