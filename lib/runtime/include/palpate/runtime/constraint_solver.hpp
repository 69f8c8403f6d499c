#pragma once
/// @file
/// The run-time algebra of the precomputed model (docs/model.md, "The reduced system of a
/// request"): constraints on a few surface vertices in, forces and displacements out, by a small
/// dense SPD solve on the compliance G. Allocation-free after construction, no exceptions: every
/// failure is a RequestStatus.

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/request_status.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/surface_product.hpp"

namespace palpate {

/// Limits of one solver, from the daemon's configuration.
struct SolverLimits {
  int max_constraints = 64;     ///< constrained vertices per request
  int cache_slots = 8;          ///< factorizations kept for reuse
  double max_condition = 1e12;  ///< 1-norm condition estimate above which a system is refused
  int surface_threads =
      1;  ///< 1, or 2: the surface field split over two cores (SplitSurfaceProduct)
  /// Bounds on what a request may give (palpated sets them for requests, not
  /// for its tools): an imposed displacement longer than this is refused
  /// (kDisplacementTooLarge), m; a given force larger than max_force_n
  /// (kForceTooLarge), N. Infinite: no bound.
  double max_displacement_m = std::numeric_limits<double>::infinity();
  double max_force_n = std::numeric_limits<double>::infinity();
};

/// Solves constraint sets on one model. One instance per model and thread.
///
/// A request is `begin(k)`, k × `add(...)`, `solve()`. With C the k
/// constrained vertices, the unknowns are the forces the request does not
/// give: three per imposed displacement, one (along the normal) per imposed
/// normal displacement. Writing f_C = f_known + B φ, where the columns of B
/// are the unit directions of the unknowns, the conditions Bᵀ u_C = b with
/// u_C = G_CC f_C give the m × m SPD system
///
///     (Bᵀ G_CC B) φ = b − (G_CC B)ᵀ f_known,
///
/// m ≤ 3k (docs/model.md, "The reduced system of a request": B = I when every
/// vertex has a full imposed displacement). The Cholesky factor of Bᵀ G_CC B
/// depends only on the vertices, their kinds and normals; it is kept in one
/// of `cache_slots` slots and reused while they stay the same, so that a tool
/// holding tissue pays two triangular solves per request.
class ConstraintSolver {
 public:
  /// Preallocates everything for up to `limits.max_constraints` vertices.
  /// @p model must outlive the solver.
  ConstraintSolver(const SurfaceModel& model, const SolverLimits& limits);
  ~ConstraintSolver();
  ConstraintSolver(const ConstraintSolver&) = delete;
  ConstraintSolver& operator=(const ConstraintSolver&) = delete;

  /// Starts a request of @p count constraints.
  RequestStatus begin(std::size_t count);
  /// Adds constraint j (in order): checks the vertex id, duplicates and
  /// values. @p kind is a ConstraintKind number; @p value, @p normal are 3 doubles.
  RequestStatus add(std::uint32_t vertex_id, std::int32_t kind, const double* value,
                    const double* normal);
  /// Solves the request built by begin/add.
  RequestStatus solve();

  /// Explanation of the last status other than kOk (what, which vertex, what
  /// is accepted); empty after success.
  const char* message() const { return message_.data(); }

  int size() const { return count_; }  ///< k
  std::span<const int> indices() const { return {index_.data(), static_cast<std::size_t>(count_)}; }
  /// Force on each constrained vertex, 3k, N (the force the tool exerts).
  Eigen::Map<const Eigen::VectorXd> forces() const { return {force_.data(), 3 * count_}; }
  /// Displacement of each constrained vertex, 3k, m.
  Eigen::Map<const Eigen::VectorXd> displacements() const {
    return {displacement_.data(), 3 * count_};
  }
  Eigen::Vector3d total_force() const;                      ///< Σ forces, N
  double condition_estimate() const { return condition_; }  ///< of Bᵀ G_CC B (1 when m = 0)
  bool reused_factorization() const { return reused_; }

  /// Displacement of every compliance vertex after the last successful solve,
  /// 3N_S, m; on two threads when `limits.surface_threads` is 2.
  void surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const;

  const SurfaceModel& model() const { return model_; }

 private:
  struct Slot;
  Slot& find_or_build_slot();

  const SurfaceModel& model_;
  SolverLimits limits_;
  int count_ = 0;
  int added_ = 0;
  std::vector<int> index_;  // compliance index per constraint
  std::vector<ConstraintKind> kind_;
  std::vector<double> value_;        // 3 per constraint
  std::vector<double> normal_;       // 3 per constraint, unit
  std::vector<std::uint32_t> seen_;  // per compliance vertex: epoch of the request naming it
  std::uint32_t epoch_ = 0;
  std::vector<Slot> slots_;
  std::uint64_t clock_ = 0;
  std::vector<double> force_, displacement_, rhs_;
  double condition_ = 1;
  bool reused_ = false;
  bool solved_ = false;
  std::array<char, 256> message_{};
  std::unique_ptr<SplitSurfaceProduct> split_;  // when surface_threads is 2
};

/// u_S = G_SC f_C: the displacement of every compliance vertex under forces
/// on the vertices @p indices (docs/model.md, "The surface field"). 3N_S × 3k flops × 2.
/// @param forces_n 3 per index, N
/// @param u_m receives 3N_S displacements, m
void surface_displacement(const Eigen::MatrixXd& G, std::span<const int> indices,
                          const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m);
/// The same from the model's G, float64 or float32.
void surface_displacement(const SurfaceModel& model, std::span<const int> indices,
                          const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m);

}  // namespace palpate
