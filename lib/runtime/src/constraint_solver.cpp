#include "palpate/runtime/constraint_solver.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "palpate/core/error.hpp"

extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void dpotrs_(const char* uplo, const int* n, const int* nrhs, const double* a, const int* lda,
             double* b, const int* ldb, int* info);
void dpocon_(const char* uplo, const int* n, const double* a, const int* lda, const double* anorm,
             double* rcond, double* work, int* iwork, int* info);
}

namespace palpate {

namespace {

/// Explains a refused request in @p message (truncated to its size, never
/// allocating) and returns @p status.
template <typename... Args>
RequestStatus fail(std::array<char, 256>& message, RequestStatus status,
                   fmt::format_string<Args...> format, Args&&... args) {
  const auto end =
      fmt::format_to_n(message.data(), message.size() - 1, format, std::forward<Args>(args)...);
  *end.out = '\0';
  return status;
}

}  // namespace

/// One cached factorization: the structure it was built for (vertices, kinds,
/// normals) and G_CC, G_CC B and the Cholesky factor of Bᵀ G_CC B.
struct ConstraintSolver::Slot {
  bool valid = false;
  std::uint64_t last_used = 0;
  int count = 0;                     // k
  int unknowns = 0;                  // m
  std::vector<int> index;            // k
  std::vector<ConstraintKind> kind;  // k
  std::vector<double> normal;        // 3k
  std::vector<int> unknown_vertex;   // m: which constraint an unknown belongs to
  std::vector<int> unknown_value;    // m: where its prescribed displacement is in value_
  std::vector<double> unknown_dir;   // 3m: its unit direction (a column of B)
  std::vector<double> G_CC;          // 3k × 3k, column-major
  std::vector<double> GB;            // 3k × m, column-major: G_CC B
  std::vector<double> L;             // m × m, Cholesky factor of Bᵀ G_CC B (lower)
  std::vector<double> work;          // 3m for dpocon
  std::vector<int> iwork;            // m
  double condition = 1;

  explicit Slot(int max_constraints) {
    const auto k = static_cast<std::size_t>(max_constraints);
    index.resize(k);
    kind.resize(k);
    normal.resize(3 * k);
    unknown_vertex.resize(3 * k);
    unknown_value.resize(3 * k);
    unknown_dir.resize(9 * k);
    G_CC.resize(9 * k * k);
    GB.resize(9 * k * k);
    L.resize(9 * k * k);
    work.resize(9 * k);
    iwork.resize(3 * k);
  }
};

ConstraintSolver::ConstraintSolver(const SurfaceModel& model, const SolverLimits& limits)
    : model_(model), limits_(limits) {
  PALPATE_DEMAND(limits.max_constraints > 0 && limits.cache_slots > 0);
  PALPATE_DEMAND(limits.surface_threads == 1 || limits.surface_threads == 2);
  if (limits.surface_threads == 2) split_ = std::make_unique<SplitSurfaceProduct>();
  const auto k = static_cast<std::size_t>(limits.max_constraints);
  index_.resize(k);
  kind_.resize(k);
  value_.resize(3 * k);
  normal_.resize(3 * k);
  force_.resize(3 * k);
  displacement_.resize(3 * k);
  rhs_.resize(3 * k);
  seen_.assign(static_cast<std::size_t>(model.compliance_vertex_count()), 0);
  slots_.reserve(static_cast<std::size_t>(limits.cache_slots));
  for (int s = 0; s < limits.cache_slots; ++s) slots_.emplace_back(limits.max_constraints);
}

ConstraintSolver::~ConstraintSolver() = default;

RequestStatus ConstraintSolver::begin(std::size_t count) {
  message_[0] = '\0';
  solved_ = false;
  condition_ = 1;
  count_ = 0;
  added_ = 0;
  if (count > static_cast<std::size_t>(limits_.max_constraints))
    return fail(message_, RequestStatus::kTooManyConstraints,
                "{} constraints in one request; at most {} are accepted", count,
                limits_.max_constraints);
  count_ = static_cast<int>(count);
  // A new epoch marks the vertices of this request without clearing seen_.
  if (++epoch_ == 0) {
    std::fill(seen_.begin(), seen_.end(), 0);
    epoch_ = 1;
  }
  return RequestStatus::kOk;
}

RequestStatus ConstraintSolver::add(std::uint32_t vertex_id, std::int32_t kind, const double* value,
                                    const double* normal) {
  PALPATE_DEMAND(added_ < count_);
  const int j = added_;
  if (vertex_id >= model_.mesh_vertex_count())
    return fail(message_, RequestStatus::kVertexOutOfRange,
                "constraint {}: vertex {} is not a vertex of model '{}' (ids are 0..{})", j,
                vertex_id, model_.id, model_.mesh_vertex_count() - 1);
  const std::int32_t index = model_.compliance_index_of_vertex[vertex_id];
  if (index == static_cast<std::int32_t>(VertexRole::kFixed))
    return fail(
        message_, RequestStatus::kVertexFixed,
        "constraint {}: vertex {} of model '{}' is fixed (attached); only free surface vertices "
        "(ModelDescription.vertex_ids, first compliance_vertex_count) can be constrained",
        j, vertex_id, model_.id);
  if (index < 0)
    return fail(
        message_, RequestStatus::kVertexNotOnSurface,
        "constraint {}: vertex {} of model '{}' is inside the organ; only free surface vertices "
        "(ModelDescription.vertex_ids, first compliance_vertex_count) can be constrained",
        j, vertex_id, model_.id);
  if (seen_[static_cast<std::size_t>(index)] == epoch_)
    return fail(message_, RequestStatus::kDuplicateVertex,
                "constraint {}: vertex {} appears twice; each vertex at most once", j, vertex_id);
  seen_[static_cast<std::size_t>(index)] = epoch_;

  if (kind < 0 || kind > 2)
    return fail(message_, RequestStatus::kBadConstraint,
                "constraint {} (vertex {}): unknown kind {}; accepted: 0 force, "
                "1 displacement, 2 normal displacement",
                j, vertex_id, kind);
  const auto k = static_cast<ConstraintKind>(kind);
  const bool uses_normal = k == ConstraintKind::kNormalDisplacement;
  const int value_count = uses_normal ? 1 : 3;
  for (int d = 0; d < value_count; ++d)
    if (!std::isfinite(value[d]))
      return fail(message_, RequestStatus::kNonFiniteValue,
                  "constraint {} (vertex {}): value[{}] is {:g}; finite numbers "
                  "only",
                  j, vertex_id, d, value[d]);
  // A value a request could not mean for this organ: a displacement longer
  // than the model's bound (mm typed as m), a force beyond any tool's.
  const double magnitude =  // hypot: 1e308 stays 1e308, not inf
      uses_normal ? std::abs(value[0]) : std::hypot(value[0], value[1], value[2]);
  if (k != ConstraintKind::kForce && magnitude > limits_.max_displacement_m)
    return fail(message_, RequestStatus::kDisplacementTooLarge,
                "constraint {} (vertex {}): a displacement of {:.4g} m is larger than model "
                "'{}' accepts ({:.4g} m, limits.max_displacement_fraction of its size); give "
                "displacements in metres",
                j, vertex_id, magnitude, model_.id, limits_.max_displacement_m);
  if (k == ConstraintKind::kForce && magnitude > limits_.max_force_n)
    return fail(message_, RequestStatus::kForceTooLarge,
                "constraint {} (vertex {}): a force of {:.4g} N is larger than accepted "
                "({:.4g} N, limits.max_force_n); give forces in newtons",
                j, vertex_id, magnitude, limits_.max_force_n);
  double* n = &normal_[3 * static_cast<std::size_t>(j)];
  if (uses_normal) {
    for (int d = 0; d < 3; ++d)
      if (!std::isfinite(normal[d]))
        return fail(message_, RequestStatus::kNonFiniteValue,
                    "constraint {} (vertex {}): normal[{}] is {:g}; finite "
                    "numbers only",
                    j, vertex_id, d, normal[d]);
    const double length =
        std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    // Below this a direction is noise; the solve would divide by it.
    if (!(length > 1e-12))
      return fail(message_, RequestStatus::kBadConstraint,
                  "constraint {} (vertex {}): normal ({:g}, {:g}, {:g}) has no direction; "
                  "a normal displacement needs a non-zero normal",
                  j, vertex_id, normal[0], normal[1], normal[2]);
    for (int d = 0; d < 3; ++d) n[d] = normal[d] / length;
  } else {
    n[0] = n[1] = n[2] = 0;
  }
  index_[static_cast<std::size_t>(j)] = index;
  kind_[static_cast<std::size_t>(j)] = k;
  for (int d = 0; d < 3; ++d)
    value_[3 * static_cast<std::size_t>(j) + static_cast<std::size_t>(d)] =
        d < value_count ? value[d] : 0.0;
  ++added_;
  return RequestStatus::kOk;
}

ConstraintSolver::Slot& ConstraintSolver::find_or_build_slot() {
  const int k = count_;
  auto matches = [&](const Slot& slot) {
    if (!slot.valid || slot.count != k) return false;
    for (int j = 0; j < k; ++j) {
      if (slot.index[j] != index_[j] || slot.kind[j] != kind_[j]) return false;
      if (kind_[j] == ConstraintKind::kNormalDisplacement &&
          !std::equal(&normal_[3 * j], &normal_[3 * j + 3], &slot.normal[3 * j]))
        return false;
    }
    return true;
  };
  Slot* oldest = &slots_.front();
  for (Slot& slot : slots_) {
    if (matches(slot)) {
      reused_ = true;
      slot.last_used = ++clock_;
      return slot;
    }
    if (!slot.valid || (oldest->valid && slot.last_used < oldest->last_used)) oldest = &slot;
  }

  Slot& slot = *oldest;
  reused_ = false;
  slot.valid = false;
  slot.last_used = ++clock_;
  slot.count = k;
  std::copy_n(index_.begin(), k, slot.index.begin());
  std::copy_n(kind_.begin(), k, slot.kind.begin());
  std::copy_n(normal_.begin(), 3 * k, slot.normal.begin());

  // G_CC: the 3×3 blocks G^ab of the constrained vertices.
  const int n3 = 3 * k;
  Eigen::Map<Eigen::MatrixXd> G_CC(slot.G_CC.data(), n3, n3);
  for (int b = 0; b < k; ++b)
    for (int a = 0; a < k; ++a)
      G_CC.block<3, 3>(3 * a, 3 * b) = model_.G_block(index_[a], index_[b]);

  // B: one unit column per unknown force component.
  int m = 0;
  for (int j = 0; j < k; ++j) {
    if (kind_[j] == ConstraintKind::kDisplacement) {
      for (int d = 0; d < 3; ++d, ++m) {
        slot.unknown_vertex[m] = j;
        slot.unknown_value[m] = 3 * j + d;
        for (int e = 0; e < 3; ++e) slot.unknown_dir[3 * m + e] = d == e ? 1.0 : 0.0;
      }
    } else if (kind_[j] == ConstraintKind::kNormalDisplacement) {
      slot.unknown_vertex[m] = j;
      slot.unknown_value[m] = 3 * j;
      std::copy_n(&normal_[3 * j], 3, &slot.unknown_dir[3 * m]);
      ++m;
    }
  }
  slot.unknowns = m;
  slot.condition = 1;
  if (m == 0) {
    slot.valid = true;
    return slot;
  }

  // G_CC B, then Bᵀ (G_CC B) into L, which dpotrf factors in place.
  Eigen::Map<Eigen::MatrixXd> GB(slot.GB.data(), n3, m);
  Eigen::Map<Eigen::MatrixXd> A(slot.L.data(), m, m);
  for (int p = 0; p < m; ++p) {
    const Eigen::Map<const Eigen::Vector3d> dir(&slot.unknown_dir[3 * p]);
    GB.col(p).noalias() = G_CC.middleCols<3>(3 * slot.unknown_vertex[p]) * dir;
  }
  for (int p = 0; p < m; ++p)
    for (int q = 0; q < m; ++q) {
      const Eigen::Map<const Eigen::Vector3d> dir(&slot.unknown_dir[3 * q]);
      A(q, p) = dir.dot(GB.col(p).segment<3>(3 * slot.unknown_vertex[q]));
    }
  double norm1 = 0;
  for (int p = 0; p < m; ++p) norm1 = std::max(norm1, A.col(p).cwiseAbs().sum());

  int info = 0;
  dpotrf_("L", &m, slot.L.data(), &m, &info);
  if (info != 0) {
    slot.condition = std::numeric_limits<double>::infinity();
    return slot;  // not valid: ill-conditioned
  }
  double rcond = 0;
  dpocon_("L", &m, slot.L.data(), &m, &norm1, &rcond, slot.work.data(), slot.iwork.data(), &info);
  slot.condition = rcond > 0 ? 1.0 / rcond : std::numeric_limits<double>::infinity();
  slot.valid = info == 0 && slot.condition <= limits_.max_condition;
  return slot;
}

RequestStatus ConstraintSolver::solve() {
  solved_ = false;
  if (added_ != count_)
    return fail(message_, RequestStatus::kInternalError, "solve() after {} of {} constraints",
                added_, count_);
  const int k = count_;
  const Slot& slot = find_or_build_slot();
  condition_ = slot.condition;
  if (!slot.valid)
    return fail(
        message_, RequestStatus::kIllConditioned,
        "the {} × {} system of the imposed displacements has condition estimate {:.3g}, above the "
        "limit "
        "{:.3g}: constrained vertices too close together, or normals nearly parallel on "
        "neighbours; "
        "constrain fewer vertices or give forces instead",
        slot.unknowns, slot.unknowns, condition_, limits_.max_condition);

  const int n3 = 3 * k;
  const int m = slot.unknowns;
  Eigen::Map<Eigen::VectorXd> f(force_.data(), n3);
  bool any_known_force = false;
  for (int j = 0; j < k; ++j) {
    const bool known = kind_[j] == ConstraintKind::kForce;
    any_known_force |= known;
    for (int d = 0; d < 3; ++d) f(3 * j + d) = known ? value_[3 * j + d] : 0.0;
  }

  if (m > 0) {
    // rhs = b − (G_CC B)ᵀ f_known; then φ = (Bᵀ G_CC B)⁻¹ rhs.
    Eigen::Map<Eigen::VectorXd> rhs(rhs_.data(), m);
    for (int p = 0; p < m; ++p) rhs(p) = value_[slot.unknown_value[p]];
    if (any_known_force) {
      const Eigen::Map<const Eigen::MatrixXd> GB(slot.GB.data(), n3, m);
      rhs.noalias() -= GB.transpose() * f;
    }
    int info = 0;
    const int one = 1;
    dpotrs_("L", &m, &one, slot.L.data(), &m, rhs.data(), &m, &info);
    if (info != 0)
      return fail(message_, RequestStatus::kInternalError, "dpotrs failed with info {}", info);
    for (int p = 0; p < m; ++p) {
      const int j = slot.unknown_vertex[p];
      for (int d = 0; d < 3; ++d) f(3 * j + d) += rhs(p) * slot.unknown_dir[3 * p + d];
    }
  }

  // u_C = G_CC f_C.
  const Eigen::Map<const Eigen::MatrixXd> G_CC(slot.G_CC.data(), n3, n3);
  Eigen::Map<Eigen::VectorXd> u(displacement_.data(), n3);
  u.noalias() = G_CC * f;
  // Finite values can still overflow (a displacement of 1e300 m needs an
  // infinite force): no reply carries an infinity or a NaN.
  if (!f.allFinite() || !u.allFinite() || !total_force().allFinite())
    return fail(message_, RequestStatus::kNonFiniteValue,
                "the solution overflows (a force or displacement is not finite): the values are "
                "too large for this model; give displacements in metres and forces in newtons");
  solved_ = true;
  return RequestStatus::kOk;
}

Eigen::Vector3d ConstraintSolver::total_force() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int j = 0; j < count_; ++j) sum += Eigen::Map<const Eigen::Vector3d>(&force_[3 * j]);
  return sum;
}

void ConstraintSolver::surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const {
  PALPATE_DEMAND(solved_);
  if (split_ && model_.float32())
    (*split_)(model_.G32, indices(), force_.data(), u_m);
  else if (split_)
    (*split_)(model_.G, indices(), force_.data(), u_m);
  else
    palpate::surface_displacement(model_, indices(), force_.data(), u_m);
}

void surface_displacement(const Eigen::MatrixXd& G, std::span<const int> indices,
                          const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m) {
  PALPATE_DEMAND(u_m.size() == G.rows() && u_m.innerStride() == 1);
  surface_displacement_rows(G, indices, forces_n, 0, G.rows(), u_m.data());
}

void surface_displacement(const SurfaceModel& model, std::span<const int> indices,
                          const double* forces_n, Eigen::Ref<Eigen::VectorXd> u_m) {
  if (!model.float32()) return surface_displacement(model.G, indices, forces_n, u_m);
  PALPATE_DEMAND(u_m.size() == model.G32.rows() && u_m.innerStride() == 1);
  surface_displacement_rows(model.G32, indices, forces_n, 0, model.G32.rows(), u_m.data());
}

}  // namespace palpate
