#include "palpate/runtime/solve/factorization_cache.hpp"

#include <lapacke.h>

#include <algorithm>
#include <limits>

#include "palpate/core/error.hpp"

namespace palpate::detail {

CachedFactorization::CachedFactorization(int max_constraints) {
  const auto k = static_cast<std::size_t>(max_constraints);
  point_count.resize(k);
  point_index.resize(3 * k);
  point_weight.resize(3 * k);
  kind.resize(k);
  normal.resize(3 * k);
  unknown_vertex.resize(3 * k);
  unknown_value.resize(3 * k);
  unknown_dir.resize(9 * k);
  point_slot.resize(3 * k);
  GHt.resize(27 * k * k);
  L.resize(9 * k * k);
  work.resize(9 * k);
  iwork.resize(3 * k);
}

FactorizationCache::FactorizationCache(const SurfaceModel& model, const SolverLimits& limits)
    : model_(model), max_condition_(limits.max_condition) {
  PALPATE_DEMAND(limits.max_constraints > 0 && limits.cache_slots > 0);
  const auto k = static_cast<std::size_t>(limits.max_constraints);
  const auto n = static_cast<std::size_t>(model.compliance_vertex_count());
  used_epoch_.assign(n, 0);
  used_slot_.assign(n, 0);
  used_index_.resize(3 * k);
  G_UU_.resize(81 * k * k);
  GHt_.resize(27 * k * k);  // G Hᵀ B for the factorization (3u × m)
  slots_.reserve(static_cast<std::size_t>(limits.cache_slots));
  for (int s = 0; s < limits.cache_slots; ++s) slots_.emplace_back(limits.max_constraints);
}

const CachedFactorization& FactorizationCache::find_or_build(const ConstraintStructure& request) {
  const int k = request.count;
  const int* point_count = request.point_count;
  const int* point_index = request.point_index;
  const double* point_weight = request.point_weight;
  const ConstraintKind* kind = request.kind;
  const double* normal = request.normal;
  auto matches = [&](const CachedFactorization& slot) {
    if (!slot.valid || slot.count != k) return false;
    for (int j = 0; j < k; ++j) {
      const int c = point_count[j];
      if (slot.point_count[j] != c || slot.kind[j] != kind[j]) return false;
      if (!std::equal(&point_index[3 * j], &point_index[3 * j + c], &slot.point_index[3 * j]) ||
          !std::equal(&point_weight[3 * j], &point_weight[3 * j + c], &slot.point_weight[3 * j]))
        return false;
      if (kind[j] == ConstraintKind::kNormalDisplacement &&
          !std::equal(&normal[3 * j], &normal[3 * j + 3], &slot.normal[3 * j]))
        return false;
    }
    return true;
  };
  CachedFactorization* oldest = &slots_.front();
  for (CachedFactorization& slot : slots_) {
    if (matches(slot)) {
      reused_ = true;
      slot.last_used = ++clock_;
      return slot;
    }
    if (!slot.valid || (oldest->valid && slot.last_used < oldest->last_used)) oldest = &slot;
  }

  CachedFactorization& slot = *oldest;
  reused_ = false;
  slot.valid = false;
  slot.last_used = ++clock_;
  slot.count = k;
  std::copy_n(point_count, k, slot.point_count.begin());
  std::copy_n(point_index, 3 * k, slot.point_index.begin());
  std::copy_n(point_weight, 3 * k, slot.point_weight.begin());
  std::copy_n(kind, k, slot.kind.begin());
  std::copy_n(normal, 3 * k, slot.normal.begin());
  assemble_point_compliance(slot, request);

  // B: one unit column per unknown force component.
  const int n3 = 3 * k;
  int m = 0;
  for (int j = 0; j < k; ++j) {
    if (kind[j] == ConstraintKind::kDisplacement) {
      for (int d = 0; d < 3; ++d, ++m) {
        slot.unknown_vertex[m] = j;
        slot.unknown_value[m] = 3 * j + d;
        for (int e = 0; e < 3; ++e) slot.unknown_dir[3 * m + e] = d == e ? 1.0 : 0.0;
      }
    } else if (kind[j] == ConstraintKind::kNormalDisplacement) {
      slot.unknown_vertex[m] = j;
      slot.unknown_value[m] = 3 * j;
      std::copy_n(&normal[3 * j], 3, &slot.unknown_dir[3 * m]);
      ++m;
    }
  }
  slot.unknowns = m;
  slot.condition = 1;
  if (m == 0) {
    slot.valid = true;
    return slot;
  }

  // Y = (G Hᵀ) B, then Bᵀ P B = (H Y) read at the unknowns' directions,
  // into L, which dpotrf factors in place.
  const int u3 = 3 * slot.used;
  const Eigen::Map<const Eigen::MatrixXd> GHt(slot.GHt.data(), u3, n3);
  Eigen::Map<Eigen::MatrixXd> Y(GHt_.data(), u3, m);
  Eigen::Map<Eigen::MatrixXd> A(slot.L.data(), m, m);
  for (int p = 0; p < m; ++p) {
    const Eigen::Map<const Eigen::Vector3d> dir(&slot.unknown_dir[3 * p]);
    Y.col(p).noalias() = GHt.middleCols<3>(3 * slot.unknown_vertex[p]) * dir;
  }
  // The lower triangle (what dpotrf reads), mirrored for the 1-norm.
  for (int p = 0; p < m; ++p)
    for (int q = p; q < m; ++q) {
      const Eigen::Map<const Eigen::Vector3d> dir(&slot.unknown_dir[3 * q]);
      const int j = slot.unknown_vertex[q];
      double a = 0;
      for (int i = 0; i < point_count[j]; ++i)
        a += point_weight[3 * j + i] * dir.dot(Y.col(p).segment<3>(3 * slot.point_slot[3 * j + i]));
      A(q, p) = a;
      A(p, q) = a;
    }
  double norm1 = 0;
  for (int p = 0; p < m; ++p) norm1 = std::max(norm1, A.col(p).cwiseAbs().sum());

  // The _work routines: column-major, they call LAPACK directly, with no
  // NaN scan and no allocation (the high-level LAPACKE_dpocon allocates).
  lapack_int info = LAPACKE_dpotrf_work(LAPACK_COL_MAJOR, 'L', m, slot.L.data(), m);
  PALPATE_DEMAND(info >= 0);
  if (info != 0) {
    slot.condition = std::numeric_limits<double>::infinity();
    return slot;  // not valid: ill-conditioned
  }
  double rcond = 0;
  info = LAPACKE_dpocon_work(LAPACK_COL_MAJOR, 'L', m, slot.L.data(), m, norm1, &rcond,
                             slot.work.data(), slot.iwork.data());
  PALPATE_DEMAND(info >= 0);
  slot.condition = rcond > 0 ? 1.0 / rcond : std::numeric_limits<double>::infinity();
  slot.valid = info == 0 && slot.condition <= max_condition_;
  return slot;
}

void FactorizationCache::assemble_point_compliance(CachedFactorization& slot,
                                                   const ConstraintStructure& request) {
  const int k = request.count;
  const int* point_count = request.point_count;
  const int* point_index = request.point_index;
  const double* point_weight = request.point_weight;
  const int n3 = 3 * k;
  // Number the distinct vertices U of the points.
  if (++used_clock_ == 0) {
    std::fill(used_epoch_.begin(), used_epoch_.end(), 0);
    used_clock_ = 1;
  }
  int u = 0;
  for (int j = 0; j < k; ++j)
    for (int i = 0; i < point_count[j]; ++i) {
      const auto a = static_cast<std::size_t>(point_index[3 * j + i]);
      if (used_epoch_[a] != used_clock_) {
        used_epoch_[a] = used_clock_;
        used_slot_[a] = u;
        used_index_[static_cast<std::size_t>(u++)] = static_cast<int>(a);
      }
      slot.point_slot[3 * j + i] = used_slot_[a];
    }
  slot.used = u;
  // G_UU, each 3×3 block of G read once.
  const int u3 = 3 * u;
  Eigen::Map<Eigen::MatrixXd> G_UU(G_UU_.data(), u3, u3);
  for (int b = 0; b < u; ++b)
    for (int a = 0; a < u; ++a)
      G_UU.block<3, 3>(3 * a, 3 * b) = model_.G_block(used_index_[a], used_index_[b]);
  // G Hᵀ (3u × 3k): column block q = Σ_j w_qj G_U,a_qj. A vertex point (one
  // vertex, weight 1) copies its blocks exactly.
  Eigen::Map<Eigen::MatrixXd> GHt(slot.GHt.data(), u3, n3);
  GHt.setZero();
  for (int q = 0; q < k; ++q)
    for (int i = 0; i < point_count[q]; ++i)
      GHt.middleCols<3>(3 * q) +=
          point_weight[3 * q + i] * G_UU.middleCols<3>(3 * slot.point_slot[3 * q + i]);
}

}  // namespace palpate::detail
