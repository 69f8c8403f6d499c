#pragma once
// Private to palpate_runtime: the served region's implicit step
// (docs/model/hybrid-serving.md, "The implicit step"). One backward-Euler step per tick
// solves A u⁺ = b with
//
//   A = c M + K_R + k_s P_skin + h P_held + S on Γ,   c = 1/Δt² + γ/Δt,
//
// K_R the region's remaining tetrahedra, P_skin the region's touchable
// surface vertices (the tips' penalty, taken implicitly), P_held the
// vertices a cut left without a tetrahedron off Γ (held where they are),
// S = G_ΓΓ⁻¹ the rest condensed on Γ as loaded (a Γ vertex the cut frees
// keeps its S rows: eliminating it is the Schur complement the explicit
// step's release computes). A is factored with Γ last: a sparse Cholesky
// of the interior block and a dense Cholesky of its Schur complement on Γ.
// A cut changes A on the vertices of the tetrahedra it removed only, and
// that low-rank change is applied by the Woodbury identity; when it grows,
// A is factored again on a worker thread while the ticks go on
// (refactor_worker.hpp).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <memory>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/region/refactor_worker.hpp"
#include "palpate/runtime/tensor_mass.hpp"

namespace palpate::detail {

/// A's constant coefficients.
struct ImplicitStepCoefficients {
  double time_step_s = 1e-3;          ///< Δt
  double damping_per_s = 0;           ///< γ
  double skin_stiffness_n_per_m = 0;  ///< k_s on each touchable vertex
  /// κ: each Γ vertex's 3 × 3 block of S, times κ, as a proximal term
  /// κ S_vv (u⁺ − u) (a dashpot κ S_vv Δt at Γ; docs/model/hybrid-serving.md).
  double interface_damping = 0;
  double mass_coefficient() const {  ///< c = 1/Δt² + γ/Δt
    return 1 / (time_step_s * time_step_s) + damping_per_s / time_step_s;
  }
};

/// A factored once: the matrix it is of, and its two Cholesky factors.
struct RegionFactorization;
/// What the worker hands over: a factorization of a snapshot of A, and the
/// columns of Y it adds for the cuts made meanwhile (region_implicit_step.cpp).
struct RegionRefactor;

/// Work vectors of one solve with a factorization (one set per thread).
struct SolveScratch {
  Eigen::VectorXd interior, gamma;
  void size(Eigen::Index interior_dofs, Eigen::Index gamma_dofs);
};

class ImplicitRegionStep {
 public:
  /// @param interface Γ as loaded (region vertices, none fixed), the order
  ///        of @p coupling's 3 × 3 blocks; @p coupling S (kept by reference:
  ///        it must outlive this object and not change).
  /// @param on_skin per region vertex: touchable (gets k_s).
  /// @param refactor_rank the update's rank at which A is factored again in
  ///        the background; at four times it, factored at once (or the worker waited for).
  /// Allocates; factors A (tens of ms at 2,000 tetrahedra).
  ImplicitRegionStep(const TensorMassModel& model, std::span<const int> interface,
                     const Eigen::MatrixXd& coupling, const ImplicitStepCoefficients& coefficients,
                     const std::vector<char>& on_skin, int refactor_rank = 48);
  ~ImplicitRegionStep();
  ImplicitRegionStep(const ImplicitRegionStep&) = delete;
  ImplicitRegionStep& operator=(const ImplicitRegionStep&) = delete;

  const ImplicitStepCoefficients& coefficients() const { return coefficients_; }
  /// h, the diagonal of a vertex held off Γ (N/m).
  double hold_stiffness() const { return hold_n_per_m_; }
  /// Whether A holds vertex @p v where it is (no tetrahedron left, off Γ).
  bool holds(int v) const { return model_.is_detached(v) && !on_gamma_[v]; }
  /// κ S_vv for Γ vertex @p v (zero elsewhere), N/m.
  const Eigen::Matrix3d& interface_proximal(int v) const { return interface_proximal_[v]; }

  /// Brings A to the model's state on the vertices @p touched (those of the
  /// tetrahedra a cut removed, and any whose skin flag changed): a Woodbury
  /// update, a factorization the worker finished adopted, or a new one.
  /// Allocates.
  void update(std::span<const int> touched, const std::vector<char>& on_skin);

  /// x = A⁻¹ b, both 3#V in region vertex numbering; a fixed vertex's x is 0.
  /// Allocates nothing.
  void solve(CRef<Eigen::VectorXd> b, Eigen::Ref<Eigen::VectorXd> x);
  /// x = A⁻¹ (b + S u_Γ⁰ on Γ), @p gamma_offset u_Γ⁰ on Γ as loaded (3n_Γ),
  /// without S: with x = x' + u_Γ⁰ on Γ, A x' = b − (A − S) u_Γ⁰, a sparse
  /// product (the rest's pull S (u_Γ − u_Γ⁰) is zero at x_Γ = u_Γ⁰).
  /// Allocates nothing.
  void solve_offset(CRef<Eigen::VectorXd> b, CRef<Eigen::VectorXd> gamma_offset,
                    Eigen::Ref<Eigen::VectorXd> x);
  /// out = (A − S) x on Γ's rows as loaded (3n_Γ): what the region's
  /// tensors, mass and hold give there. Allocates nothing.
  void interface_rows(CRef<Eigen::VectorXd> x, Eigen::Ref<Eigen::VectorXd> out);

  /// The Woodbury update's rank now (DOFs), and how many times A was
  /// factored (the first one included) and in the background.
  int update_rank() const { return rank_; }
  int factorizations() const { return factorizations_; }
  int background_factorizations() const { return background_factorizations_; }
  /// How long the factorization in use took to compute (s), on whichever thread.
  double last_factorization_s() const;
  /// Waits for a background factorization under way and adopts it (tests).
  void finish_background_work(const std::vector<char>& on_skin);

 private:
  Eigen::Matrix3d diagonal_block(int v, const std::vector<char>& on_skin) const;
  SparseMatrixd assemble(const std::vector<char>& on_skin) const;
  void adopt(std::unique_ptr<RegionRefactor> refactor, const std::vector<char>& on_skin);
  void add_update_dofs(std::span<const int> touched);
  void refresh_capacitance(const std::vector<char>& on_skin);
  void launch_refactor(const std::vector<char>& on_skin);
  // ordered_ = A⁻¹ ordered_ in place (the base factor, then Woodbury).
  void solve_ordered();
  // ordered_ from @p x (3#V, region numbering), and back (a fixed vertex 0).
  void to_ordered(CRef<Eigen::VectorXd> x);
  void from_ordered(Eigen::Ref<Eigen::VectorXd> x) const;

  const TensorMassModel& model_;
  const Eigen::MatrixXd& coupling_;
  ImplicitStepCoefficients coefficients_;
  double hold_n_per_m_ = 0;
  int refactor_rank_ = 0;
  std::vector<int> gamma_;          // Γ as loaded
  std::vector<char> on_gamma_;      // per region vertex
  std::vector<int> first_dof_;      // per region vertex: its first ordered DOF, −1 if fixed
  std::vector<int> vertex_at_dof_;  // per ordered DOF: the vertex it is the first of, or −1
  std::vector<Eigen::Matrix3d> interface_proximal_;  // per region vertex: κ S_vv on Γ
  Eigen::Index interior_dofs_ = 0, dofs_ = 0;

  std::unique_ptr<RegionFactorization> factor_;
  // The worker: it factors a snapshot of A, then computes the columns of
  // the vertices cut since the snapshot until its queue is empty; those cut
  // after it closed the queue are its cut_after(), for adopt().
  RefactorWorker<std::unique_ptr<RegionRefactor>> worker_;
  int factorizations_ = 0, background_factorizations_ = 0;

  // A = A₀ + E D Eᵀ: E the update's DOFs (ordered), Y = A₀⁻¹ E, the
  // capacitance I + D Eᵀ Y.
  std::vector<Eigen::Index> update_dofs_;
  std::vector<int> dof_slot_;  // per ordered DOF: its column in Y, or −1
  int rank_ = 0;
  Eigen::MatrixXd y_, d_;
  Eigen::PartialPivLU<Eigen::MatrixXd> capacitance_;
  Eigen::VectorXd ordered_, picked_, weights_;
  SolveScratch scratch_;
};

}  // namespace palpate::detail
