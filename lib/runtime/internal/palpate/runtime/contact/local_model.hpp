#pragma once
/// @file
/// A tool's contact wrench linearized about its pose (internal to the
/// runtime): K = ∂(F, τ)/∂(x, θ) of LocalContactModel, read off the
/// factorization of the tick's settled contact set (docs/tools.md, "The
/// local model"; the derivation in docs/model/local-model.md, "The local contact model").
///
/// What K is the derivative of: the engine's tick at a pose near the
/// answered one, the surface deformed as at that pose (a settled state),
/// with the same contact set (its rows, their kinds, a tip point's
/// triangle, edge or vertex). A motion (δx, δθ) of the tool moves the axis
/// point c of a row by δc = δx + δθ × lever, and then
///  - a held point, a material point of the tissue that follows the jaws,
///    has its target moved by δc;
///  - a tip's point is found again where the moved tip meets the deformed
///    surface: it moves by δp (P δc in its triangle, P the projector on
///    the plane; along its edge; not at all on a vertex), the normal from
///    the axis to it turns by δn = P_n (δp − δc) / d (d its distance to the
///    axis; zero inside a triangle), its target c + r n moves by
///    δc + r δn (a sticking one's also by the drag, P_n (δx + δθ × (lever +
///    r n)): the tissue goes along with the tool in the contact's plane,
///    docs/tools.md "Friction"), and its barycentric weights change by the δw that move the
///    deformed point by δp: what is imposed on it changes by
///    δvalue = δc + r δn − δp, and the place where its force loads the
///    surface moves, so every row's displacement changes by
///    σ_s = H_s G Σ_r δH_rᵀ f_r, which the solve must balance. A sliding
///    point's force turns with its normal (δf ∋ φ δn, another moved load),
///    and its constraint nᵀ(p − target) = 0 gains −δnᵀ t (t its
///    tangential slip p − target).
/// Hence, per motion, δb = Bᵀ (δvalue − σ) and δf = B W⁻¹ δb
/// (ActiveSet::force_response), and the wrench on the tool changes by
/// δF = −Σ δf, δτ = −Σ (p − x) × δf − Σ δ(p − x) × f, where a point moves
/// by its target's motion (sticking or held), or (sliding) along its
/// normal as the constraint says and along the surface by δp and its
/// displacement's tangential change P δu. On a warped model each row's
/// values and forces go through its rotation R̃, frozen for the tick (the
/// rotations' own change with the loads is left out).

#include <Eigen/Core>
#include <array>
#include <span>
#include <vector>

#include "palpate/runtime/solve/active_set.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace palpate::detail {

/// What the local model needs of a row beyond its ActiveRow.
struct LocalRow {
  int tool = 0;
  bool tip = false;  ///< a tip's point, else held by the jaws
  /// A tip's point kept on its triangle next tick (a material point, docs/tools.md
  /// "Material contact points"), else found again where the tool's motion
  /// moves the closest point.
  bool material = false;
  /// How the row's target turns with the tool: δtarget = δx + δθ × lever, m.
  Eigen::Vector3d lever = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< world, unit (tip rows)
  /// R̃ of the point (warped; identity for the linear model).
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  /// Tip rows: the deformed corners with a weight, in the ActiveRow's
  /// order; the target on the tip's surface, the tip's radius r and the
  /// point's distance d to the axis at detection (world, m).
  std::array<Eigen::Vector3d, 3> corners{};
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  double radius = 0, distance = 0;
  /// After the solve, for active rows: the point on the deformed surface,
  /// its force on the organ in the world and in the solve's (material)
  /// frame.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  Eigen::Vector3d material_force = Eigen::Vector3d::Zero();
};

class LocalModel {
 public:
  using Matrix6d = Eigen::Matrix<double, 6, 6>;

  /// Scratch for up to @p max_rows rows on a model of @p compliance_vertices.
  LocalModel(int max_rows, int compliance_vertices);

  /// K of tool @p tool (hinge @p hinge_m, its contacts scaled by @p scale:
  /// the watchdog's ramp) from the settled set @p rows / @p local of the
  /// solve @p set has just made. Allocation-free.
  Matrix6d stiffness(std::span<const ActiveRow> rows, std::span<const LocalRow> local, int tool,
                     const Eigen::Vector3d& hinge_m, double scale, ActiveSet& set);

 private:
  /// The number of @p v among the vertices met (or a new one), −1 for a fixed one.
  int slot(int v);
  void forget_slots();

  using Block = Eigen::Matrix<double, 3, 6>;  // 3 components × 6 motions
  std::vector<int> slot_of_;                  // per compliance vertex, −1
  std::vector<int> vertex_;                   // per slot
  int slots_ = 0;
  std::vector<Block> shift_load_;    // per slot: Σ δw f̂ of the tool's tip points on it
  std::vector<Block> shift_disp_;    // per slot: σ, the displacement those shifts cause
  std::vector<Block> force_change_;  // per slot: Σ w δf̂ of every point on it
  std::vector<char> loaded_;         // per slot: a tip point of the tool has weight on it
  std::vector<char> moved_;          // per slot: moved_vertex_ computed
  std::vector<Block> moved_vertex_;  // per slot: δu, G Hᵀ δf̂ + σ, for the sliding points on it
  std::vector<double> in_, out_;     // 3 per row × 6 motions
  // Per row of the tool: how each motion moves its point found on the
  // surface (δp), its normal (δn) and its target (world).
  std::vector<Block> moved_point_, turned_normal_, moved_target_;
};

}  // namespace palpate::detail
