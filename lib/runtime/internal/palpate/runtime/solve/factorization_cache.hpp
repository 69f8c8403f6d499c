#pragma once
/// @file
/// The factorizations of ConstraintSolver's reduced systems, kept for reuse
/// (internal to the runtime; docs/model/requests.md, "The reduced system of
/// a request").

#include <cstdint>
#include <vector>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/request_status.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace palpate::detail {

/// What a factorization depends on: the structure of a request's k
/// constraints, borrowed from ConstraintSolver for one call. Per constraint
/// j < count: its point's point_count[j] (1 to 3) compliance vertices
/// point_index[3j + i] with barycentric weights point_weight[3j + i], its
/// kind[j], and its unit normal normal[3j … 3j + 2] (read for a normal
/// displacement only).
struct ConstraintStructure {
  int count = 0;                         ///< k
  const int* point_count = nullptr;      ///< k
  const int* point_index = nullptr;      ///< 3k, compliance indices
  const double* point_weight = nullptr;  ///< 3k
  const ConstraintKind* kind = nullptr;  ///< k
  const double* normal = nullptr;        ///< 3k, unit
};

/// One cached factorization: the structure it was built for (points, kinds,
/// normals), G Hᵀ on the points' distinct vertices U and the Cholesky factor
/// of Bᵀ P B. P = H G Hᵀ itself is never formed: H is three weights per
/// point, so P x = H (G Hᵀ x) and Bᵀ P B is read off G Hᵀ B. Column-major
/// arrays sized for the solver's max_constraints at construction.
struct CachedFactorization {
  bool valid = false;
  std::uint64_t last_used = 0;
  int count = 0;                     // k
  int unknowns = 0;                  // m
  std::vector<int> point_count;      // k
  std::vector<int> point_index;      // 3k
  std::vector<double> point_weight;  // 3k
  std::vector<ConstraintKind> kind;  // k
  std::vector<double> normal;        // 3k
  std::vector<int> unknown_vertex;   // m: which constraint an unknown belongs to
  std::vector<int> unknown_value;    // m: where its prescribed displacement is in the values
  std::vector<double> unknown_dir;   // 3m: its unit direction (a column of B)
  int used = 0;                      // u, the distinct vertices of the points
  std::vector<int> point_slot;       // 3k: each point vertex's place in U
  std::vector<double> GHt;           // 3u × 3k, column-major: G_U· Hᵀ, m/N
  std::vector<double> L;             // m × m, Cholesky factor of Bᵀ G_CC B (lower)
  std::vector<double> work;          // 3m for dpocon
  std::vector<int> iwork;            // m
  double condition = 1;              // 1-norm condition estimate of Bᵀ P B

  explicit CachedFactorization(int max_constraints);
};

/// The factorizations of the last few constraint structures a solver saw
/// (limits.cache_slots of them), so that a tool holding tissue pays two
/// triangular solves per request instead of reading G and factoring again.
///
/// find_or_build() returns the slot built for the request's structure (same
/// points, weights, kinds and normals, compared exactly), or rebuilds the
/// least recently used one: U, the distinct vertices of the points, and
/// G_UU (each 3×3 block of G read once); G Hᵀ (3u × 3k); B, one unit column
/// per unknown force component (three per imposed displacement, the normal
/// per imposed normal displacement); Bᵀ P B = (H (G Hᵀ B)) at the unknowns'
/// directions (m × m, m/N), factored by LAPACK dpotrf, its 1-norm condition
/// estimated by dpocon. A slot whose factorization fails, or whose
/// condition estimate exceeds limits.max_condition, is returned invalid.
///
/// Allocates everything in its constructor (per slot about 36k² doubles for
/// k = limits.max_constraints, and 108k² of scratch); find_or_build() is
/// allocation-free. @p model must outlive it.
class FactorizationCache {
 public:
  FactorizationCache(const SurfaceModel& model, const SolverLimits& limits);

  /// The factorization of @p request's structure, reused or built (see the
  /// class). Valid until the next call.
  const CachedFactorization& find_or_build(const ConstraintStructure& request);
  /// Whether the last find_or_build() reused a slot (false before the first).
  bool reused() const { return reused_; }

 private:
  void assemble_point_compliance(CachedFactorization& slot, const ConstraintStructure& request);

  const SurfaceModel& model_;
  double max_condition_ = 1e12;
  std::vector<CachedFactorization> slots_;
  std::uint64_t clock_ = 0;
  bool reused_ = false;
  // The distinct vertices of the points: per compliance vertex, the epoch it
  // was last numbered in and its number; G among them (3u × 3u) and, while
  // a slot is built, G Hᵀ B (3u × m).
  std::vector<std::uint32_t> used_epoch_;
  std::vector<int> used_slot_;
  std::uint32_t used_clock_ = 0;
  std::vector<int> used_index_;
  std::vector<double> G_UU_, GHt_;
};

}  // namespace palpate::detail
