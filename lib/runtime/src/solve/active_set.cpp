#include "palpate/runtime/solve/active_set.hpp"

#include <fmt/format.h>
#include <lapacke.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include "palpate/core/error.hpp"
#include "palpate/runtime/solve/request_failure.hpp"

namespace palpate::detail {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Kind = ConstraintKind;

/// A sticking point starts to slide: its three rows become the normal one,
/// b_n = nᵀ b, and its tangential force is zero.
void slide(ActiveRow& row) {
  row.slipped = true;
  row.kind = Kind::kNormalDisplacement;
  row.value = Vector3d(row.normal.dot(row.value), 0, 0);
}

int unknowns_of(const ActiveRow& row) {
  if (row.state != ActiveRow::kActive) return 0;
  return row.kind == Kind::kDisplacement ? 3 : 1;
}

}  // namespace

ActiveSet::ActiveSet(const SurfaceModel& model, const SolverLimits& limits)
    : model_(model),
      limits_(limits),
      solver_(model, limits),
      compliance_(model, limits.max_constraints),
      factor_(3 * limits.max_constraints) {
  max_rows_ = limits.max_constraints;
  max_unknowns_ = 3 * max_rows_;
  max_used_ = 3 * max_rows_;
  const auto k = index(max_rows_);
  const auto m = index(max_unknowns_);
  const auto u3 = 3 * index(max_used_);
  force_.resize(3 * k);
  displacement_.resize(3 * k);
  unknown_row_.resize(m);
  unknown_dir_.resize(3 * m);
  columns_of_.resize(k);
  kind_in_W_.resize(k);
  rhs_.resize(m);
  z_.resize(u3);
  const auto columns = index(ConstraintSolver::kMaxResponseColumns);
  response_in_.resize(3 * k * columns);
  response_out_.resize(std::max(3 * k, m) * columns);
  slip_in_.assign(3 * k * columns, 0.0);
  slip_out_.resize(3 * k * columns);
  slips_.resize(k);
  slip_matrix_.resize(4 * k * k);
  slip_step_.resize(2 * k);
  slip_pivots_.resize(2 * k);
}

ActiveSet::~ActiveSet() = default;

RequestStatus ActiveSet::solve(std::span<ActiveRow> rows, int max_iterations,
                               ActiveSetMethod method) {
  PALPATE_DEMAND(rows.size() <= static_cast<std::size_t>(max_rows_));
  const auto call_start = std::chrono::steady_clock::now();
  rows_ = rows;
  message_[0] = '\0';
  last_ok_ = false;
  // Held points alone never change: one solve, through the solver and its
  // cache of factorizations (a grasp held still reuses it from tick to tick).
  const bool incremental =
      method == ActiveSetMethod::kIncremental &&
      std::any_of(rows.begin(), rows.end(), [](const ActiveRow& row) { return row.tip; });
  const int n = static_cast<int>(rows.size());
  RequestStatus status = RequestStatus::kOk;
  if (incremental) {
    status = check_values();
    if (status != RequestStatus::kOk) {
      ++solves_;
      return status;
    }
    compliance_.number(rows_);
    factored_ = false;  // the first solve_incremental starts W (and columns_of_) afresh
  }
  bool softened = false;
  const std::uint64_t first_solve = solves_;
  const int iterations = std::max(1, max_iterations);
  for (int iteration = 0; iteration < iterations; ++iteration) {
    // The first solve's time includes reading G for the tick (above).
    const auto start = solves_ == first_solve ? call_start : std::chrono::steady_clock::now();
    status = incremental ? solve_incremental() : solve_refactor();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    (solves_ == first_solve ? first_s_ : later_s_) += seconds;
    later_ += solves_ == first_solve ? 0 : 1;
    ++solves_;
    // Sticking points fix three components each: more of them than their
    // triangles' vertices can move (a tip in a dip meets several triangles
    // around the same vertices) is a singular system. They slide instead:
    // one row each, the normal.
    if (status == RequestStatus::kIllConditioned && !softened) {
      softened = true;
      bool any_stick = false;
      for (ActiveRow& row : rows_) {
        if (!row.tip || row.kind != Kind::kDisplacement) continue;
        slide(row);
        any_stick = true;
      }
      if (any_stick) {
        --iteration;  // the same iteration, on rows that can be solved
        continue;
      }
    }
    // Still singular (more rows than their vertices can take: points on
    // edges and corners of the same few vertices, or on triangles whose
    // other corners are fixed): the shallowest tip contact goes, and the
    // rest is solved again, within the same iteration.
    if (status == RequestStatus::kIllConditioned && softened) {
      int shallowest = -1;
      double depth = INFINITY;
      for (int r = 0; r < n; ++r) {
        const ActiveRow& row = rows_[index(r)];
        if (!row.tip || row.state != ActiveRow::kActive) continue;
        if (row.depth < depth) depth = row.depth, shallowest = r;
      }
      if (shallowest >= 0) {
        rows_[index(shallowest)].state = ActiveRow::kReleased;
        --iteration;
        continue;
      }
    }
    if (status != RequestStatus::kOk) break;
    // The last allowed solve stands as solved: the contacts stored are
    // exactly its constraints, and their forces its forces (changing the
    // set now would pair each force with another point).
    if (iteration + 1 == iterations) break;
    // Adhesion: a tip contact whose force pulls the tissue towards the
    // tool lets go; a sticking one slides first.
    bool any = false;
    for (int r = 0; r < n; ++r) {
      ActiveRow& row = rows_[index(r)];
      if (row.state != ActiveRow::kActive || !row.tip) continue;
      if (force(r).dot(row.normal) >= 0) continue;
      if (row.kind == Kind::kDisplacement)
        slide(row);
      else
        row.state = ActiveRow::kReleased;
      any = true;
    }
    // Signorini on the watched triangles: one the solve pushed into the
    // tip (its linearized gap now negative) joins the set.
    for (int r = 0; r < n; ++r) {
      ActiveRow& row = rows_[index(r)];
      if (row.state != ActiveRow::kDormant) continue;
      const double wanted =
          row.kind == Kind::kNormalDisplacement ? row.value.x() : row.normal.dot(row.value);
      if (row.normal.dot(displacement(r)) < wanted - row.join_gap_m) {
        row.state = ActiveRow::kActive;
        any = true;
      }
    }
    // Friction, once the set stands (no point joined or left: a set in
    // the middle of changing can have forces that mean nothing yet): the
    // sticking points outside their cones slip back onto the edges, their
    // targets moving in their tangent planes (the set stays).
    if (!any) {
      last_incremental_ = incremental;
      last_ok_ = true;
      any = slip_onto_cones();
    }
    if (!any) break;
  }
  last_incremental_ = incremental;
  last_ok_ = status == RequestStatus::kOk;
  return status;
}

bool ActiveSet::slip_onto_cones() {
  const int n = static_cast<int>(rows_.size());
  // The sticking points outside their cones beyond 0.1 % of the edge (a
  // point put on the edge is there but for the round-off of its return).
  int count = 0;
  for (int r = 0; r < n; ++r) {
    const ActiveRow& row = rows_[index(r)];
    if (row.state != ActiveRow::kActive || !row.tip || row.kind != Kind::kDisplacement) continue;
    const Vector3d f = force(r);
    const double normal_force = f.dot(row.normal);
    const Vector3d tangential = f - normal_force * row.normal;
    const double edge = row.friction * normal_force;
    const double magnitude = tangential.norm();
    if (!(magnitude > edge + 1e-3 * edge + 1e-12)) continue;
    Slip& slip = slips_[index(count++)];
    slip.row = r;
    slip.t = tangential / magnitude;
    slip.s = row.normal.cross(slip.t);
    slip.along = slip.t - row.friction * row.normal;
  }
  if (count == 0) return false;
  // Coulomb's return, for all of them together: each one's target moves
  // in its tangent plane by a_j t_j + b_j s_j (the other rows' targets
  // staying), which changes every force by Σ_j a_j δf^{t_j} + b_j δf^{s_j}
  // (the responses B W⁻¹ Bᵀ e, two columns a point from the solve's
  // factor), so that each is on its cone's edge along its t:
  //   (t_i − μ n_i)ᵀ (f_i + Σ_j …) = 0,   s_iᵀ (f_i + Σ_j …) = 0.
  // Exact for the set (the normal forces' change included); t_i stays.
  const int unknowns = 2 * count;
  const int batch = ConstraintSolver::kMaxResponseColumns;
  for (int first = 0; first < unknowns; first += batch) {
    const int columns = std::min(batch, unknowns - first);
    for (int c = 0; c < columns; ++c) {
      const Slip& slip = slips_[index((first + c) / 2)];
      Eigen::Map<Vector3d>{&slip_in_[3 * index(c * n + slip.row)]} =
          (first + c) % 2 == 0 ? slip.t : slip.s;
    }
    force_response(slip_in_.data(), slip_out_.data(), columns);
    for (int c = 0; c < columns; ++c) {
      Eigen::Map<Vector3d>{&slip_in_[3 * index(c * n + slips_[index((first + c) / 2)].row)]}
          .setZero();
      double* column = &slip_matrix_[index(first + c) * index(unknowns)];
      for (int i = 0; i < count; ++i) {
        const Slip& slip = slips_[index(i)];
        const Eigen::Map<const Vector3d> df(&slip_out_[3 * index(c * n + slip.row)]);
        column[2 * i] = slip.along.dot(df);
        column[2 * i + 1] = slip.s.dot(df);
      }
    }
  }
  for (int i = 0; i < count; ++i) {
    const Slip& slip = slips_[index(i)];
    slip_step_[index(2 * i)] = -slip.along.dot(force(slip.row));
    slip_step_[index(2 * i + 1)] = -slip.s.dot(force(slip.row));
  }
  // The _work routines of LAPACKE, column-major, call LAPACK directly: no
  // NaN scan, no allocation.
  const lapack_int info =
      LAPACKE_dgesv_work(LAPACK_COL_MAJOR, unknowns, 1, slip_matrix_.data(), unknowns,
                         slip_pivots_.data(), slip_step_.data(), unknowns);
  PALPATE_DEMAND(info >= 0);
  for (int i = 0; i < count; ++i) {
    const Slip& slip = slips_[index(i)];
    ActiveRow& row = rows_[index(slip.row)];
    const double a = slip_step_[index(2 * i)], b = slip_step_[index(2 * i + 1)];
    if (info == 0 && std::isfinite(a) && std::isfinite(b)) {
      row.value += a * slip.t + b * slip.s;
      row.slipped = true;
    } else
      slide(row);  // no such targets (never met): they slide, their tangential force zero
  }
  return true;
}

void ActiveSet::force_response(const double* dvalue, double* dforce, int columns) {
  PALPATE_DEMAND(last_ok_);
  PALPATE_DEMAND(columns >= 0 && columns <= ConstraintSolver::kMaxResponseColumns);
  const int n = static_cast<int>(rows_.size());
  std::fill_n(dforce, 3 * index(n) * index(columns), 0.0);
  if (!last_incremental_) {
    // The solver's constraints are the active rows, in order.
    int k = 0;
    for (int r = 0; r < n; ++r) k += rows_[index(r)].state == ActiveRow::kActive ? 1 : 0;
    for (int c = 0; c < columns; ++c)
      for (int r = 0, j = 0; r < n; ++r)
        if (rows_[index(r)].state == ActiveRow::kActive)
          std::copy_n(&dvalue[3 * index(c * n + r)], 3, &response_in_[3 * index(c * k + j++)]);
    solver_.force_response(response_in_.data(), response_out_.data(), columns);
    for (int c = 0; c < columns; ++c)
      for (int r = 0, j = 0; r < n; ++r)
        if (rows_[index(r)].state == ActiveRow::kActive)
          std::copy_n(&response_out_[3 * index(c * k + j++)], 3, &dforce[3 * index(c * n + r)]);
    return;
  }
  // δb_p = d_pᵀ δvalue_r (a sliding row's d is its normal), δφ = W⁻¹ δb from
  // the factor, δf_r = Σ_p δφ_p d_p over the row's unknowns.
  const int m = factor_.size();
  if (m == 0 || columns == 0) return;
  for (int c = 0; c < columns; ++c)
    for (int p = 0; p < m; ++p)
      response_out_[index(c * m + p)] =
          Eigen::Map<const Vector3d>(&unknown_dir_[3 * index(p)])
              .dot(Eigen::Map<const Vector3d>(&dvalue[3 * index(c * n + unknown_row_[index(p)])]));
  const int info = factor_.solve(response_out_.data(), columns);
  PALPATE_DEMAND(info == 0);
  for (int c = 0; c < columns; ++c)
    for (int p = 0; p < m; ++p)
      Eigen::Map<Vector3d>(&dforce[3 * index(c * n + unknown_row_[index(p)])]) +=
          response_out_[index(c * m + p)] * Eigen::Map<const Vector3d>(&unknown_dir_[3 * index(p)]);
}

Matrix3d ActiveSet::G_block(int a, int b) const {
  if (last_incremental_)
    if (const std::optional<Matrix3d> block = compliance_.read_block(a, b)) return *block;
  return model_.G_block(a, b);
}

// ---- the reference path: every solve from scratch ---------------------------------

RequestStatus ActiveSet::solve_refactor() {
  const int n = static_cast<int>(rows_.size());
  int k = 0;
  for (const ActiveRow& row : rows_) k += row.state == ActiveRow::kActive ? 1 : 0;
  RequestStatus status = solver_.begin(static_cast<std::size_t>(k));
  for (int r = 0; r < n && status == RequestStatus::kOk; ++r) {
    const ActiveRow& row = rows_[index(r)];
    if (row.state != ActiveRow::kActive) continue;
    status = solver_.add_surface_point(row.index.data(), row.weights.data(), row.count, row.kind,
                                       row.value.data(), row.normal.data());
  }
  if (status == RequestStatus::kOk) status = solver_.solve();
  if (status != RequestStatus::kOk) {
    const std::size_t length = strnlen(solver_.message(), message_.size() - 1);
    std::copy_n(solver_.message(), length, message_.data());
    message_[length] = '\0';
    return status;
  }
  const auto f = solver_.forces();
  const auto u = solver_.displacements();
  int j = 0;
  for (int r = 0; r < n; ++r) {
    const ActiveRow& row = rows_[index(r)];
    Eigen::Map<Vector3d> fr(&force_[3 * index(r)]), ur(&displacement_[3 * index(r)]);
    if (row.state == ActiveRow::kActive) {
      fr = f.segment<3>(3 * j);
      ur = u.segment<3>(3 * j);
      ++j;
    } else {
      fr.setZero();
      ur =
          row.state == ActiveRow::kDormant ? displacement_from_solver_loads(row) : Vector3d::Zero();
    }
  }
  return RequestStatus::kOk;
}

/// Σ_i w_i Σ_l G_{a_i l} f_l over the solver's loads: a dormant point's
/// displacement under the solve just made.
Vector3d ActiveSet::displacement_from_solver_loads(const ActiveRow& row) const {
  const auto loads = solver_.load_indices();
  const auto forces = solver_.load_forces();
  Vector3d u = Vector3d::Zero();
  for (int i = 0; i < row.count; ++i) {
    const int v = row.index[index(i)];
    if (v < 0) continue;
    Vector3d u_v = Vector3d::Zero();
    for (std::size_t l = 0; l < loads.size(); ++l)
      u_v.noalias() += model_.G_block(v, loads[l]) * Eigen::Map<const Vector3d>(&forces[3 * l]);
    u += row.weights[index(i)] * u_v;
  }
  return u;
}

// ---- the incremental path -------------------------------------------------------

RequestStatus ActiveSet::check_values() {
  for (int r = 0; r < static_cast<int>(rows_.size()); ++r) {
    ActiveRow& row = rows_[index(r)];
    PALPATE_DEMAND(row.kind == Kind::kDisplacement || row.kind == Kind::kNormalDisplacement);
    const bool normal_only = row.kind == Kind::kNormalDisplacement;
    const double magnitude = normal_only ? std::abs(row.value.x()) : row.value.norm();
    if (!std::isfinite(magnitude) || !row.normal.allFinite())
      return fail(message_, RequestStatus::kNonFiniteValue,
                  "contact {}: its displacement or normal is not finite; finite numbers only", r);
    if (magnitude > limits_.max_displacement_m)
      return fail(message_, RequestStatus::kDisplacementTooLarge,
                  "contact {}: a displacement of {:.4g} m is larger than model '{}' accepts "
                  "({:.4g} m)",
                  r, magnitude, model_.id, limits_.max_displacement_m);
    if (row.tip) {
      const double length = row.normal.norm();
      if (!(length > 1e-12))
        return fail(message_, RequestStatus::kBadConstraint,
                    "contact {}: normal ({:g}, {:g}, {:g}) has no direction", r, row.normal.x(),
                    row.normal.y(), row.normal.z());
      row.normal /= length;
    }
  }
  return RequestStatus::kOk;
}

/// Appends the unknowns of every active row not yet in W, their columns of
/// W = Bᵀ P B, and extends the factor (IncrementalFactor::append).
RequestStatus ActiveSet::append_pending() {
  const int first = factor_.size();
  int m = first;
  for (int r = 0; r < static_cast<int>(rows_.size()); ++r) {
    const ActiveRow& row = rows_[index(r)];
    const int count = unknowns_of(row);
    if (count == 0 || columns_of_[index(r)] > 0) continue;
    compliance_.compute_Y(r);
    for (int c = 0; c < count; ++c) {
      const auto p = index(m++);
      unknown_row_[p] = r;
      Eigen::Map<Vector3d>{&unknown_dir_[3 * p]} =
          row.kind == Kind::kDisplacement ? Vector3d(Vector3d::Unit(c)) : row.normal;
    }
    columns_of_[index(r)] = count;
    kind_in_W_[index(r)] = row.kind;
  }
  const int k = m - first;
  if (k == 0) return RequestStatus::kOk;
  // Column q of W among rows p ≤ q: d_pᵀ H_r (Y_s d_q); a row's unknowns
  // are adjacent, so H_r Y_s is formed once per pair of rows.
  int last_r = -1, last_s = -1;
  Matrix3d P = Matrix3d::Zero();
  const int info = factor_.append(k, [&](int p, int q) {
    const int s = unknown_row_[index(q)];
    const Eigen::Map<const Vector3d> dq(&unknown_dir_[3 * index(q)]);
    const int r = unknown_row_[index(p)];
    if (r != last_r || s != last_s) P = compliance_.P_block(r, s), last_r = r, last_s = s;
    return Eigen::Map<const Vector3d>(&unknown_dir_[3 * index(p)]).dot(P * dq);
  });
  if (info != 0)
    return fail(message_, RequestStatus::kIllConditioned,
                "the {} × {} system of the contacts is singular (column {}): points too close "
                "together or too many on the same vertices",
                m, m, first + info);
  return check_condition();
}

/// Refuses W when its 1-norm condition estimate exceeds the limit.
RequestStatus ActiveSet::check_condition() {
  const int m = factor_.size();
  if (m == 0) return RequestStatus::kOk;
  const double condition = factor_.condition_estimate();
  if (!(condition <= limits_.max_condition))
    return fail(message_, RequestStatus::kIllConditioned,
                "the {} × {} system of the contacts has condition estimate {:.3g}, above the "
                "limit {:.3g}: points too close together, or normals nearly parallel on "
                "neighbours",
                m, m, condition, limits_.max_condition);
  return RequestStatus::kOk;
}

/// Removes unknown p from W and its factor, and from the unknowns' list.
void ActiveSet::remove_unknown(int p) {
  const int m = factor_.size();
  factor_.remove(p);
  --columns_of_[index(unknown_row_[index(p)])];
  for (int q = p; q + 1 < m; ++q) {
    unknown_row_[index(q)] = unknown_row_[index(q) + 1];
    std::copy_n(&unknown_dir_[3 * index(q) + 3], 3, &unknown_dir_[3 * index(q)]);
  }
}

RequestStatus ActiveSet::solve_incremental() {
  RequestStatus status = RequestStatus::kOk;
  if (factored_) {
    // Unknowns of rows that left, or that slide now, leave W first (removing
    // rows of an SPD matrix cannot worsen its condition); then the rows that
    // joined, and the sliding rows' normals, are appended.
    for (int p = factor_.size() - 1; p >= 0; --p) {
      const int r = unknown_row_[index(p)];
      const ActiveRow& row = rows_[index(r)];
      if (row.state != ActiveRow::kActive || row.kind != kind_in_W_[index(r)]) remove_unknown(p);
    }
  } else {
    factor_.clear();
    for (std::size_t r = 0; r < rows_.size(); ++r) columns_of_[r] = 0;
  }
  status = append_pending();
  if (status != RequestStatus::kOk) {
    factored_ = false;
    return status;
  }
  factored_ = true;
  return finish_incremental();
}

/// φ = W⁻¹ b from the factor, f_C = B φ, and every row's displacement
/// u_p = H_p G_UU Hᵀ f_C (the dormant rows' too, for their gaps).
RequestStatus ActiveSet::finish_incremental() {
  const int m = factor_.size();
  for (int p = 0; p < m; ++p) {
    const ActiveRow& row = rows_[index(unknown_row_[index(p)])];
    rhs_[index(p)] = row.kind == Kind::kNormalDisplacement
                         ? row.value.x()
                         : Eigen::Map<const Vector3d>(&unknown_dir_[3 * index(p)]).dot(row.value);
  }
  if (m > 0) {
    const int info = factor_.solve(rhs_.data(), 1);
    if (info != 0)
      return fail(message_, RequestStatus::kInternalError, "dpotrs failed with info {}", info);
  }
  const int n = static_cast<int>(rows_.size());
  std::fill_n(force_.begin(), 3 * index(n), 0.0);
  for (int p = 0; p < m; ++p)
    Eigen::Map<Vector3d>(&force_[3 * index(unknown_row_[index(p)])]) +=
        rhs_[index(p)] * Eigen::Map<const Vector3d>(&unknown_dir_[3 * index(p)]);
  // z = G_UU Hᵀ f_C = Σ_r Y_r f_r over the rows in W: 9u flops per row,
  // not 9u² (U holds every candidate's vertices, most of them unloaded).
  const int u3 = 3 * compliance_.used();
  Eigen::Map<Eigen::VectorXd> z(z_.data(), u3);
  z.setZero();
  bool finite = true;
  for (int r = 0; r < n; ++r) {
    if (columns_of_[index(r)] == 0) continue;
    finite = finite && force(r).allFinite();
    z.noalias() += compliance_.Y(r) * force(r);
  }
  for (int r = 0; r < n; ++r) {
    Eigen::Map<Vector3d> u(&displacement_[3 * index(r)]);
    u.setZero();
    if (rows_[index(r)].state == ActiveRow::kReleased) continue;
    for (int i = 0; i < rows_[index(r)].count; ++i)
      if (const int slot = compliance_.slot(r, i); slot >= 0)
        u += rows_[index(r)].weights[index(i)] * z.segment<3>(3 * slot);
    finite = finite && u.allFinite() && force(r).allFinite();
  }
  // Finite values can still overflow (a displacement of 1e300 m needs an
  // infinite force): no reply carries an infinity or a NaN.
  if (!finite)
    return fail(message_, RequestStatus::kNonFiniteValue,
                "the solution overflows (a force or displacement is not finite): the values are "
                "too large for this model");
  return RequestStatus::kOk;
}

}  // namespace palpate::detail
