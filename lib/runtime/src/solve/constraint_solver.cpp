#include "palpate/runtime/constraint_solver.hpp"

#include <fmt/format.h>
#include <lapacke.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "palpate/core/error.hpp"
#include "palpate/runtime/solve/factorization_cache.hpp"
#include "palpate/runtime/solve/request_failure.hpp"

namespace palpate {

using detail::fail;

ConstraintSolver::ConstraintSolver(const SurfaceModel& model, const SolverLimits& limits)
    : model_(model), limits_(limits) {
  PALPATE_DEMAND(limits.max_constraints > 0 && limits.cache_slots > 0);
  PALPATE_DEMAND(limits.surface_threads == 1 || limits.surface_threads == 2);
  if (limits.surface_threads == 2) split_ = std::make_unique<SplitSurfaceProduct>();
  const auto k = static_cast<std::size_t>(limits.max_constraints);
  point_count_.resize(k);
  point_index_.resize(3 * k);
  point_weight_.resize(3 * k);
  kind_.resize(k);
  value_.resize(3 * k);
  normal_.resize(3 * k);
  force_.resize(3 * k);
  displacement_.resize(3 * k);
  rhs_.resize(3 * k);
  response_.resize(3 * k * kMaxResponseColumns);
  const auto n = static_cast<std::size_t>(model.compliance_vertex_count());
  seen_.assign(n, 0);
  used_epoch_.assign(n, 0);
  used_slot_.assign(n, 0);
  z_.resize(9 * k);  // 3 per distinct vertex of the points, u ≤ 3k
  load_index_.resize(3 * k);
  load_force_.resize(9 * k);
  // The surface's triangles and edges by mesh vertex ids, for add_point.
  const DrawnSurface& surface = model.surface;
  for (int t = 0; t < surface.triangle_count(); ++t) {
    std::array<std::uint32_t, 3> ids{};
    for (int c = 0; c < 3; ++c)
      ids[static_cast<std::size_t>(c)] =
          surface.vertex_ids[surface.triangles[3 * static_cast<std::size_t>(t) +
                                               static_cast<std::size_t>(c)]];
    std::sort(ids.begin(), ids.end());
    surface_triangles_.push_back(ids);
    surface_edges_.push_back({ids[0], ids[1]});
    surface_edges_.push_back({ids[0], ids[2]});
    surface_edges_.push_back({ids[1], ids[2]});
  }
  std::sort(surface_triangles_.begin(), surface_triangles_.end());
  std::sort(surface_edges_.begin(), surface_edges_.end());
  surface_edges_.erase(std::unique(surface_edges_.begin(), surface_edges_.end()),
                       surface_edges_.end());
  cache_ = std::make_unique<detail::FactorizationCache>(model, limits);
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
  if (const RequestStatus status = check_values(j, vertex_id, kind, value, normal);
      status != RequestStatus::kOk)
    return status;
  const auto jj = static_cast<std::size_t>(j);
  point_count_[jj] = 1;
  point_index_[3 * jj] = index;
  point_weight_[3 * jj] = 1.0;
  ++added_;
  return RequestStatus::kOk;
}

bool ConstraintSolver::on_surface(std::span<const std::uint32_t> ids) const {
  if (ids.size() == 3) {
    std::array<std::uint32_t, 3> key{ids[0], ids[1], ids[2]};
    std::sort(key.begin(), key.end());
    return std::binary_search(surface_triangles_.begin(), surface_triangles_.end(), key);
  }
  if (ids.size() == 2) {
    const std::array<std::uint32_t, 2> key{std::min(ids[0], ids[1]), std::max(ids[0], ids[1])};
    return std::binary_search(surface_edges_.begin(), surface_edges_.end(), key);
  }
  return true;
}

RequestStatus ConstraintSolver::add_point(std::span<const std::uint32_t> ids,
                                          std::span<const double> weights, std::int32_t kind,
                                          const double* value, const double* normal) {
  PALPATE_DEMAND(added_ < count_);
  const int j = added_;
  if (ids.empty() || ids.size() > 3 || weights.size() != ids.size())
    return fail(message_, RequestStatus::kBadConstraint,
                "constraint {}: a point has {} vertices and {} weights; accepted: 1 to 3 "
                "vertices (a vertex, an edge or a triangle of the surface), one weight each",
                j, ids.size(), weights.size());
  const std::uint32_t first = ids[0];
  int fixed = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const std::uint32_t id = ids[i];
    if (id >= model_.mesh_vertex_count())
      return fail(message_, RequestStatus::kVertexOutOfRange,
                  "constraint {}: vertex {} is not a vertex of model '{}' (ids are 0..{})", j, id,
                  model_.id, model_.mesh_vertex_count() - 1);
    const std::int32_t index = model_.compliance_index_of_vertex[id];
    if (index == static_cast<std::int32_t>(VertexRole::kInterior))
      return fail(message_, RequestStatus::kVertexNotOnSurface,
                  "constraint {}: vertex {} of model '{}' is inside the organ; a point's vertices "
                  "must be a triangle or an edge of the surface (ModelDescription.triangles)",
                  j, id, model_.id);
    fixed += index == static_cast<std::int32_t>(VertexRole::kFixed) ? 1 : 0;
    for (std::size_t e = 0; e < i; ++e)
      if (ids[e] == id)
        return fail(message_, RequestStatus::kDuplicateVertex,
                    "constraint {}: vertex {} appears twice in one point", j, id);
  }
  if (fixed == static_cast<int>(ids.size()))
    return fail(message_, RequestStatus::kVertexFixed,
                "constraint {}: every vertex of the point at vertex {} of model '{}' is fixed "
                "(attached); it cannot move",
                j, first, model_.id);
  if (!on_surface(ids))
    return fail(message_, RequestStatus::kBadConstraint,
                "constraint {}: vertices {}{}{}{}{} are not {} of model '{}''s surface; a point "
                "lies on a surface triangle or edge (ModelDescription.triangles)",
                j, ids[0], ids.size() > 1 ? ", " : "", ids.size() > 1 ? ids[1] : 0u,
                ids.size() > 2 ? ", " : "", ids.size() > 2 ? ids[2] : 0u,
                ids.size() == 3 ? "a triangle" : "an edge", model_.id);
  double sum = 0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    const double w = weights[i];
    // 1e-9: round-off of weights computed in double on the client's side.
    if (!std::isfinite(w) || w < -1e-9 || w > 1 + 1e-9)
      return fail(message_, RequestStatus::kBadConstraint,
                  "constraint {} (point at vertex {}): weight {} is {:g}; accepted: barycentric "
                  "weights, each in [0, 1], summing to 1",
                  j, first, i, w);
    sum += w;
  }
  if (std::abs(sum - 1) > 1e-9)
    return fail(message_, RequestStatus::kBadConstraint,
                "constraint {} (point at vertex {}): the weights sum to {:.17g}; accepted: "
                "barycentric weights summing to 1 (within 1e-9)",
                j, first, sum);
  if (const RequestStatus status = check_values(j, first, kind, value, normal);
      status != RequestStatus::kOk)
    return status;
  const auto jj = static_cast<std::size_t>(j);
  int count = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const std::int32_t index = model_.compliance_index_of_vertex[ids[i]];
    if (index < 0) continue;  // fixed: its share goes to the attachment
    point_index_[3 * jj + static_cast<std::size_t>(count)] = index;
    point_weight_[3 * jj + static_cast<std::size_t>(count)] = weights[i];
    ++count;
  }
  point_count_[jj] = count;
  ++added_;
  return RequestStatus::kOk;
}

RequestStatus ConstraintSolver::add_surface_point(const int* indices, const double* weights,
                                                  int count, ConstraintKind kind,
                                                  const double* value, const double* normal) {
  PALPATE_DEMAND(added_ < count_ && count >= 1 && count <= 3);
  const int j = added_;
  const auto jj = static_cast<std::size_t>(j);
  int kept = 0;
  for (int i = 0; i < count; ++i) {
    if (indices[i] < 0) continue;
    PALPATE_DEMAND(indices[i] < model_.compliance_vertex_count());
    point_index_[3 * jj + static_cast<std::size_t>(kept)] = indices[i];
    point_weight_[3 * jj + static_cast<std::size_t>(kept)] = weights[i];
    ++kept;
  }
  PALPATE_DEMAND(kept > 0);
  const std::uint32_t first =
      model_.surface.vertex_ids[static_cast<std::size_t>(point_index_[3 * jj])];
  if (const RequestStatus status =
          check_values(j, first, static_cast<std::int32_t>(kind), value, normal);
      status != RequestStatus::kOk)
    return status;
  point_count_[jj] = kept;
  ++added_;
  return RequestStatus::kOk;
}

RequestStatus ConstraintSolver::check_values(int j, std::uint32_t vertex_id, std::int32_t kind,
                                             const double* value, const double* normal) {
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
  kind_[static_cast<std::size_t>(j)] = k;
  for (int d = 0; d < 3; ++d)
    value_[3 * static_cast<std::size_t>(j) + static_cast<std::size_t>(d)] =
        d < value_count ? value[d] : 0.0;
  return RequestStatus::kOk;
}

/// x_C = H z: the points' values of a field z on U (3 per vertex).
void ConstraintSolver::points_of(const detail::CachedFactorization& slot, const double* z,
                                 double* x) const {
  for (int j = 0; j < count_; ++j) {
    Eigen::Map<Eigen::Vector3d> xj(x + 3 * j);
    xj.setZero();
    for (int i = 0; i < point_count_[j]; ++i)
      xj += point_weight_[3 * j + i] *
            Eigen::Map<const Eigen::Vector3d>(z + 3 * slot.point_slot[3 * j + i]);
  }
}

void ConstraintSolver::gather_loads() {
  // f_S = Hᵀ f_C on the distinct vertices, in order of first use.
  if (++used_clock_ == 0) {
    std::fill(used_epoch_.begin(), used_epoch_.end(), 0);
    used_clock_ = 1;
  }
  load_count_ = 0;
  for (int j = 0; j < count_; ++j)
    for (int i = 0; i < point_count_[j]; ++i) {
      const auto a = static_cast<std::size_t>(point_index_[3 * j + i]);
      if (used_epoch_[a] != used_clock_) {
        used_epoch_[a] = used_clock_;
        used_slot_[a] = load_count_;
        load_index_[static_cast<std::size_t>(load_count_)] = static_cast<int>(a);
        std::fill_n(&load_force_[3 * static_cast<std::size_t>(load_count_)], 3, 0.0);
        ++load_count_;
      }
      const double w = point_weight_[3 * j + i];
      double* f = &load_force_[3 * static_cast<std::size_t>(used_slot_[a])];
      for (int d = 0; d < 3; ++d) f[d] += w * force_[3 * j + d];
    }
}

RequestStatus ConstraintSolver::solve() {
  solved_ = false;
  solved_slot_ = nullptr;
  if (added_ != count_)
    return fail(message_, RequestStatus::kInternalError, "solve() after {} of {} constraints",
                added_, count_);
  const int k = count_;
  const detail::CachedFactorization& slot =
      cache_->find_or_build({.count = k,
                             .point_count = point_count_.data(),
                             .point_index = point_index_.data(),
                             .point_weight = point_weight_.data(),
                             .kind = kind_.data(),
                             .normal = normal_.data()});
  condition_ = slot.condition;
  if (!slot.valid)
    return fail(message_, RequestStatus::kIllConditioned,
                "the {} × {} system of the imposed displacements has condition estimate {:.3g}, "
                "above the limit {:.3g}: constrained points too close together, or normals nearly "
                "parallel on neighbours; constrain fewer points or give forces instead",
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
    // rhs = b − (P B)ᵀ f_known; then φ = (Bᵀ P B)⁻¹ rhs.
    Eigen::Map<Eigen::VectorXd> rhs(rhs_.data(), m);
    for (int p = 0; p < m; ++p) rhs(p) = value_[slot.unknown_value[p]];
    if (any_known_force) {
      // (P B)ᵀ f_known = Bᵀ H (G Hᵀ f_known).
      const Eigen::Map<const Eigen::MatrixXd> GHt(slot.GHt.data(), 3 * slot.used, n3);
      Eigen::Map<Eigen::VectorXd> z(z_.data(), 3 * slot.used);
      z.noalias() = GHt * f;
      points_of(slot, z.data(), displacement_.data());
      for (int p = 0; p < m; ++p)
        rhs(p) -= Eigen::Map<const Eigen::Vector3d>(&slot.unknown_dir[3 * p])
                      .dot(Eigen::Map<const Eigen::Vector3d>(
                          &displacement_[3 * static_cast<std::size_t>(slot.unknown_vertex[p])]));
    }
    const lapack_int info =
        LAPACKE_dpotrs_work(LAPACK_COL_MAJOR, 'L', m, 1, slot.L.data(), m, rhs.data(), m);
    if (info != 0)
      return fail(message_, RequestStatus::kInternalError, "dpotrs failed with info {}", info);
    for (int p = 0; p < m; ++p) {
      const int j = slot.unknown_vertex[p];
      for (int d = 0; d < 3; ++d) f(3 * j + d) += rhs(p) * slot.unknown_dir[3 * p + d];
    }
  }

  // u_C = P f_C = H (G Hᵀ f_C).
  const Eigen::Map<const Eigen::MatrixXd> GHt(slot.GHt.data(), 3 * slot.used, n3);
  Eigen::Map<Eigen::VectorXd> z(z_.data(), 3 * slot.used);
  z.noalias() = GHt * f;
  points_of(slot, z.data(), displacement_.data());
  const Eigen::Map<const Eigen::VectorXd> u(displacement_.data(), n3);
  // Finite values can still overflow (a displacement of 1e300 m needs an
  // infinite force): no reply carries an infinity or a NaN.
  if (!f.allFinite() || !u.allFinite() || !total_force().allFinite())
    return fail(message_, RequestStatus::kNonFiniteValue,
                "the solution overflows (a force or displacement is not finite): the values are "
                "too large for this model; give displacements in metres and forces in newtons");
  gather_loads();
  solved_ = true;
  solved_slot_ = &slot;
  return RequestStatus::kOk;
}

void ConstraintSolver::force_response(const double* dvalue, double* dforce, int columns) {
  PALPATE_DEMAND(solved_ && solved_slot_ != nullptr);
  PALPATE_DEMAND(columns >= 0 && columns <= kMaxResponseColumns);
  const detail::CachedFactorization& slot = *solved_slot_;
  const int n3 = 3 * count_;
  const int m = slot.unknowns;
  std::fill_n(dforce, static_cast<std::size_t>(n3) * static_cast<std::size_t>(columns), 0.0);
  if (m == 0 || columns == 0) return;
  // δb = Bᵀ δvalue, one column per change; δφ = (Bᵀ P B)⁻¹ δb; δf = B δφ.
  for (int c = 0; c < columns; ++c)
    for (int p = 0; p < m; ++p) {
      const int j = slot.unknown_vertex[p];
      response_[static_cast<std::size_t>(c * m + p)] =
          Eigen::Map<const Eigen::Vector3d>(&slot.unknown_dir[3 * p])
              .dot(Eigen::Map<const Eigen::Vector3d>(&dvalue[c * n3 + 3 * j]));
    }
  const lapack_int info =
      LAPACKE_dpotrs_work(LAPACK_COL_MAJOR, 'L', m, columns, slot.L.data(), m, response_.data(), m);
  PALPATE_DEMAND(info == 0);
  for (int c = 0; c < columns; ++c)
    for (int p = 0; p < m; ++p) {
      const int j = slot.unknown_vertex[p];
      Eigen::Map<Eigen::Vector3d>(&dforce[c * n3 + 3 * j]) +=
          response_[static_cast<std::size_t>(c * m + p)] *
          Eigen::Map<const Eigen::Vector3d>(&slot.unknown_dir[3 * p]);
    }
}

bool ConstraintSolver::reused_factorization() const { return cache_->reused(); }

Eigen::Vector3d ConstraintSolver::total_force() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int j = 0; j < count_; ++j) sum += Eigen::Map<const Eigen::Vector3d>(&force_[3 * j]);
  return sum;
}

void ConstraintSolver::surface_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const {
  PALPATE_DEMAND(solved_);
  if (split_ && model_.float32())
    (*split_)(model_.G32, load_indices(), load_force_.data(), u_m);
  else if (split_)
    (*split_)(model_.G, load_indices(), load_force_.data(), u_m);
  else
    palpate::surface_displacement(model_, load_indices(), load_force_.data(), u_m);
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
