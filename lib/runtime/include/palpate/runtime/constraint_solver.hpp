#pragma once
/// @file
/// The run-time algebra of the precomputed model (docs/model/requests.md, "The reduced system of a
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

/// Constraints at points of surface triangles (add_point, add_surface_point):
/// for code that builds against several versions (bench/contact_feel.cpp).
#define PALPATE_HAS_SURFACE_POINTS 1

namespace palpate {

namespace detail {
class FactorizationCache;
struct CachedFactorization;
}  // namespace detail

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
/// A request is `begin(k)`, k × `add(...)` or `add_point(...)`, `solve()`.
/// Each constraint acts at a surface point: a vertex (`add`), or a point of a
/// surface triangle or edge given by its vertices and barycentric weights
/// (`add_point`). The point's displacement is u_p = Σ_i w_i u_{a_i} and a
/// force f_p on it loads each vertex a_i with w_i f_p (the same weights, so
/// that the work is the same); stacked, u_C = H u_S and f_S = Hᵀ f_C, and the
/// points' own compliance is
///
///     P = H G Hᵀ,   P^pq = Σ_i Σ_j w_pi w_qj G^{a_pi a_qj}
///
/// (P = G_CC when every point is a vertex: H picks rows). The unknowns are
/// the forces the request does not give: three per imposed displacement, one
/// (along the normal) per imposed normal displacement. Writing
/// f_C = f_known + B φ, where the columns of B are the unit directions of
/// the unknowns, the conditions Bᵀ u_C = b with u_C = P f_C give the m × m
/// SPD system
///
///     (Bᵀ P B) φ = b − (P B)ᵀ f_known,
///
/// m ≤ 3k (docs/model/requests.md, "The reduced system of a request"). The Cholesky
/// factor of Bᵀ P B depends only on the points (vertices and weights), their
/// kinds and normals; it is kept in one of `cache_slots` slots and reused
/// while they stay the same, so that a tool holding tissue pays two
/// triangular solves per request. G is read once per 3×3 block among the
/// distinct vertices U the points use; P itself is never formed (H has three
/// weights per point): Bᵀ P B is read off G_UU Hᵀ B, and P f = H (G_UU Hᵀ f).
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
  /// Adds constraint j at a point of a surface triangle (3 vertices), of a
  /// surface edge (2) or at a vertex (1): @p vertex_ids are mesh vertex ids,
  /// @p weights their barycentric weights (each in [0, 1], summing to 1).
  /// Fixed vertices may be among them (their share goes to the attachment);
  /// not all of them. The vertices must be a triangle or an edge of the
  /// model's surface.
  RequestStatus add_point(std::span<const std::uint32_t> vertex_ids,
                          std::span<const double> weights, std::int32_t kind, const double* value,
                          const double* normal);
  /// The contact engine's path: a point given by @p count compliance indices
  /// (−1 for a fixed vertex) and weights it has built itself on the surface;
  /// only the values are checked. @p normal must be unit for a normal
  /// displacement.
  RequestStatus add_surface_point(const int* compliance_indices, const double* weights, int count,
                                  ConstraintKind kind, const double* value, const double* normal);
  /// Solves the request built by begin/add.
  RequestStatus solve();

  /// Explanation of the last status other than kOk (what, which vertex, what
  /// is accepted); empty after success.
  const char* message() const { return message_.data(); }

  int size() const { return count_; }  ///< k
  /// Force at each constraint's point, 3k, N (the force the tool exerts).
  Eigen::Map<const Eigen::VectorXd> forces() const { return {force_.data(), 3 * count_}; }
  /// The same forces as loads on vertices, f_S = Hᵀ f_C, after a successful
  /// solve: the distinct compliance vertices they load (in order of first
  /// use; for vertex constraints, the constraints' own order) and the force
  /// on each, 3 per vertex, N.
  std::span<const int> load_indices() const {
    return {load_index_.data(), static_cast<std::size_t>(load_count_)};
  }
  std::span<const double> load_forces() const {
    return {load_force_.data(), 3 * static_cast<std::size_t>(load_count_)};
  }
  /// Displacement of each constraint's point, 3k, m.
  Eigen::Map<const Eigen::VectorXd> displacements() const {
    return {displacement_.data(), 3 * count_};
  }
  Eigen::Vector3d total_force() const;  ///< Σ forces, N

  /// Most columns force_response() takes at once.
  static constexpr int kMaxResponseColumns = 6;
  /// How the last successful solve's forces change with its imposed
  /// displacements, the points, kinds, normals and given forces staying: for
  /// each of @p columns changes δvalue of the values (3 per constraint, m,
  /// one column after the other; a normal displacement takes nᵀ δvalue, a
  /// given force ignores its), the change of every constraint's force,
  ///
  ///     δf_C = B (Bᵀ P B)⁻¹ Bᵀ δvalue,
  ///
  /// 3 per constraint, N, into @p dforce (same layout). Exact, since a solve
  /// is linear in its values; two triangular solves per column on the kept
  /// factor. At most kMaxResponseColumns; allocation-free.
  void force_response(const double* dvalue, double* dforce, int columns);
  double condition_estimate() const { return condition_; }  ///< of Bᵀ G_CC B (1 when m = 0)
  /// Whether the last solve reused a kept factorization (the same points,
  /// kinds and normals as one of the last `cache_slots` structures).
  bool reused_factorization() const;

  /// Displacement of every compliance vertex after the last successful solve
  /// (u_S = G f_S with the loads above), 3N_S, m; on two threads when
  /// `limits.surface_threads` is 2.
  void surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const;

  const SurfaceModel& model() const { return model_; }

 private:
  void points_of(const detail::CachedFactorization& slot, const double* z, double* x) const;
  void gather_loads();
  RequestStatus check_values(int j, std::uint32_t vertex_id, std::int32_t kind, const double* value,
                             const double* normal);
  bool on_surface(std::span<const std::uint32_t> vertex_ids) const;

  const SurfaceModel& model_;
  SolverLimits limits_;
  int count_ = 0;
  int added_ = 0;
  // Per constraint: its point, 1 to 3 compliance vertices and their weights
  // (a fixed vertex of a triangle is left out: it does not move).
  std::vector<int> point_count_;
  std::vector<int> point_index_;      // 3 per constraint
  std::vector<double> point_weight_;  // 3 per constraint
  std::vector<ConstraintKind> kind_;
  std::vector<double> value_;        // 3 per constraint
  std::vector<double> normal_;       // 3 per constraint, unit
  std::vector<std::uint32_t> seen_;  // per compliance vertex: epoch of the request naming it
  std::uint32_t epoch_ = 0;
  // The loads' distinct vertices (gather_loads): per compliance vertex, the
  // epoch it was last numbered in and its number.
  std::vector<std::uint32_t> used_epoch_;
  std::vector<int> used_slot_;
  std::uint32_t used_clock_ = 0;
  std::vector<double> z_;  // G Hᵀ f, 3 per distinct vertex of the points
  int load_count_ = 0;
  std::vector<int> load_index_;                                  // up to 3k
  std::vector<double> load_force_;                               // 3 per load
  std::vector<std::array<std::uint32_t, 3>> surface_triangles_;  // sorted ids, sorted list
  std::vector<std::array<std::uint32_t, 2>> surface_edges_;
  // The factorizations kept for reuse (palpate/runtime/solve/factorization_cache.hpp).
  std::unique_ptr<detail::FactorizationCache> cache_;
  std::vector<double> force_, displacement_, rhs_;
  // The factor of the last successful solve.
  const detail::CachedFactorization* solved_slot_ = nullptr;
  std::vector<double> response_;  // m × kMaxResponseColumns
  double condition_ = 1;
  bool solved_ = false;
  std::array<char, 256> message_{};
  std::unique_ptr<SplitSurfaceProduct> split_;  // when surface_threads is 2
};

/// u_S = G_SC f_C: the displacement of every compliance vertex under forces
/// on the vertices @p indices (docs/model/surface-field.md). 3N_S × 3k flops × 2.
/// @param forces_n 3 per index, N
/// @param u_m receives 3N_S displacements, m
void surface_displacement(const Eigen::MatrixXd& G, std::span<const int> indices,
                          const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m);
/// The same from the model's G, float64 or float32.
void surface_displacement(const SurfaceModel& model, std::span<const int> indices,
                          const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m);

}  // namespace palpate
