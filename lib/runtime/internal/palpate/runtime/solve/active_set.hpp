#pragma once
/// @file
/// The contact engine's active-set iteration (internal to the runtime).
///
/// What it solves: the tick's candidate contacts are rows at points of
/// surface triangles, u_p = Σ_i w_pi u_{a_pi}, with the points' compliance
/// P = H G Hᵀ (docs/model/requests.md, "The reduced system of a request"). Held
/// points and sticking tip points impose their three displacement
/// components (three unknown force components each); sliding tip points
/// impose their normal displacement only (one unknown, the force along the
/// normal, no tangential force). With B the unknowns' unit directions, one
/// solve is the SPD system
///
///     W φ = b,   W = Bᵀ P B,   f_C = B φ,
///
/// and the active set (docs/tools.md, "Tip contacts") repeats it until the
/// set settles, at most max_iterations solves:
///  - Signorini: a sliding tip point whose normal force pulls (nᵀf < 0)
///    leaves; a watched (dormant) point whose linearized gap the solve made
///    negative, nᵀu_p < b_n − tol, joins;
///  - Coulomb, once the set stands (no point joined or left at the last
///    solve): a sticking tip point outside the cone, |f_t| > μ nᵀf with
///    f_t = f − (nᵀf) n, slips: its imposed displacement moves in its
///    tangent plane, by a t + b s (t = f_t/|f_t|, s = n × t), so that its
///    force is on the cone's edge along t, all such points together from
///    the responses of the forces to their targets moved along t and s
///    (force_response, two columns a point; one small LU): kinetic
///    friction, the tissue following the tool as far as the cone allows
///    (Coulomb's return). One that pulls, nᵀf < 0, slides (its three rows
///    become the normal row);
///  - a singular W first makes every sticking tip point slide, then drops
///    the shallowest tip point until it solves.
///
/// Two ways to solve, equal to round-off (tests/runtime/solve/active_set_test.cpp):
/// `kRefactor` builds and factors W from scratch at every solve (through
/// ConstraintSolver); `kIncremental` factors W = L Lᵀ once and then edits
/// the factor: an unknown that leaves is removed from L by Givens rotations
/// (O(m²)), unknowns that join are appended by one block forward solve and
/// a small Cholesky of their Schur complement (O(m² k)); sliding is the
/// point's three columns leaving and its normal column joining. G is read
/// once per tick, on the distinct vertices of every candidate point. A set
/// of held points only (nothing can change) is solved by ConstraintSolver
/// either way, whose cache keeps a still grasp's factorization. The factor
/// and its edits are IncrementalFactor's (incremental_factor.hpp), G on the
/// candidates' vertices PointCompliance's (point_compliance.hpp).
/// Allocation-free after construction.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/request_status.hpp"
#include "palpate/runtime/solve/active_row.hpp"
#include "palpate/runtime/solve/incremental_factor.hpp"
#include "palpate/runtime/solve/point_compliance.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace palpate::detail {

/// How the active set solves its systems.
enum class ActiveSetMethod { kIncremental, kRefactor };

class ActiveSet {
 public:
  /// Preallocates for up to limits.max_constraints rows. @p model must outlive it.
  ActiveSet(const SurfaceModel& model, const SolverLimits& limits);
  ~ActiveSet();
  ActiveSet(const ActiveSet&) = delete;
  ActiveSet& operator=(const ActiveSet&) = delete;

  /// Runs the iteration on @p rows (their kind, value and state change as
  /// the set settles). On kOk, force(r) and displacement(r) are the last
  /// solve's for every row that is kActive; on failure message() says why.
  RequestStatus solve(std::span<ActiveRow> rows, int max_iterations, ActiveSetMethod method);

  /// Force on row @p r's point, N, and its displacement, m (last solve).
  Eigen::Map<const Eigen::Vector3d> force(int r) const {
    return Eigen::Map<const Eigen::Vector3d>(&force_[3 * index(r)]);
  }
  Eigen::Map<const Eigen::Vector3d> displacement(int r) const {
    return Eigen::Map<const Eigen::Vector3d>(&displacement_[3 * index(r)]);
  }
  const char* message() const { return message_.data(); }

  /// How the settled set's forces change with its rows' imposed
  /// displacements, the set itself (rows, kinds, normals) staying: for each
  /// of @p columns changes δvalue (3 per row, m, one column after the other;
  /// a sliding row takes nᵀ δvalue, a row not in the set is ignored), the
  /// change of every row's force, δf_C = B W⁻¹ Bᵀ δvalue (3 per row, N; zero
  /// for rows not in the set) into @p dforce. From the factor the last solve
  /// used: exact for the set, no solve of the problem again
  /// (docs/tools.md, "The local model"). Valid after solve() returned kOk;
  /// at most ConstraintSolver::kMaxResponseColumns columns; allocation-free.
  void force_response(const double* dvalue, double* dforce, int columns);

  /// G^{ab} (3 × 3) between compliance vertices @p a and @p b: from the
  /// blocks the last solve read when it read that one, else from the model.
  Eigen::Matrix3d G_block(int a, int b) const;

  std::uint64_t solves() const { return solves_; }
  /// Wall time of the first solve of each call and of the later ones, s.
  double first_seconds() const { return first_s_; }
  double later_seconds() const { return later_s_; }
  std::uint64_t later_solves() const { return later_; }

 private:
  static std::size_t index(int r) { return static_cast<std::size_t>(r); }
  RequestStatus solve_refactor();
  RequestStatus solve_incremental();
  RequestStatus append_pending();
  void remove_unknown(int p);
  RequestStatus check_condition();
  RequestStatus check_values();
  RequestStatus finish_incremental();
  bool slip_onto_cones();
  Eigen::Vector3d displacement_from_solver_loads(const ActiveRow& row) const;

  const SurfaceModel& model_;
  SolverLimits limits_;
  ConstraintSolver solver_;  // the kRefactor path
  std::span<ActiveRow> rows_;
  std::uint64_t solves_ = 0, later_ = 0;
  double first_s_ = 0, later_s_ = 0;
  std::array<char, 256> message_{};
  std::vector<double> force_, displacement_;  // 3 per row

  // kIncremental: the distinct vertices U of every row, G_UU, and per row
  // Y_r = G_UU H_rᵀ (3u × 3), computed when the row first enters W.
  int max_rows_ = 0, max_unknowns_ = 0, max_used_ = 0;
  PointCompliance compliance_;
  // W's unknowns in order (as many as factor_.size()): row, unit direction;
  // W itself and its factor L.
  std::vector<int> unknown_row_;
  std::vector<double> unknown_dir_;  // 3 per unknown
  std::vector<int> columns_of_;      // per row: its unknowns in W now (0, 1 or 3)
  std::vector<ConstraintKind> kind_in_W_;
  IncrementalFactor factor_;
  std::vector<double> rhs_, z_;
  bool factored_ = false;  // factor_ holds W's factor; else the next solve factors afresh
  // How the last successful call solved: its factor is the incremental
  // path's L or the solver's (for force_response), and the rows in it.
  bool last_incremental_ = false;
  bool last_ok_ = false;
  std::vector<double> response_in_, response_out_;  // 3 per active row × columns
  // slip_onto_cones: the sticking points outside their cones (row, the
  // direction t of their tangential force, s = n × t, and t − μ n, whose
  // product with the force is zero on the cone's edge along t), the
  // responses to their targets moved along t and s, and the system of
  // their return (2 per point, column-major), its right-hand side then
  // solution, pivots.
  struct Slip {
    int row = 0;
    Eigen::Vector3d t = Eigen::Vector3d::Zero(), s = Eigen::Vector3d::Zero();
    Eigen::Vector3d along = Eigen::Vector3d::Zero();
  };
  std::vector<Slip> slips_;
  std::vector<double> slip_in_, slip_out_;  // 3 per row × columns
  std::vector<double> slip_matrix_, slip_step_;
  std::vector<int> slip_pivots_;
};

}  // namespace palpate::detail
