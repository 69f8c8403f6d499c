#include "palpate/runtime/region/region_implicit_step.hpp"

#include <cblas.h>
#include <fmt/format.h>
#include <lapacke.h>

#include <Eigen/OrderingMethods>
#include <algorithm>
#include <chrono>
#include <utility>

#include "palpate/core/error.hpp"
#include "palpate/runtime/region/vertex_block_factor.hpp"

namespace palpate::detail {

using Eigen::Index;
using Eigen::Matrix3d;
using Eigen::VectorXd;

namespace {
constexpr const char* kImplicitStepWhat = "cut region (implicit step)";
// The update may grow to this many times the bound while the worker
// factors: a cut waits for the worker only past it (the capacitance's
// refactorization, O(rank³) per cut, is then about 2 ms at 48 × 4).
constexpr int kWaitFactor = 4;
}  // namespace

namespace {
// y = A x for a symmetric @p a, reading its lower half (BLAS dsymv: several
// times Eigen's own on this machine). Allocates nothing.
void symmetric_product(const Eigen::MatrixXd& a, CRef<VectorXd> x, Eigen::Ref<VectorXd> y) {
  PALPATE_DEMAND(a.rows() == a.cols() && x.size() == a.rows() && y.size() == a.rows() &&
                 x.innerStride() == 1 && y.innerStride() == 1);
  const int n = static_cast<int>(a.rows());
  if (n > 0)
    cblas_dsymv(CblasColMajor, CblasLower, n, 1.0, a.data(), n, x.data(), 1, 0.0, y.data(), 1);
}
}  // namespace

struct RegionFactorization {
  SparseMatrixd a;  // A − S, ordered DOFs (interior, then Γ), both halves
  Eigen::SparseMatrix<double, Eigen::RowMajor, int> gamma_rows;  // its Γ rows
  SparseMatrixd a_ig;                                            // its block (interior, Γ)
  // A_II's Cholesky factor by vertex blocks: the interior DOFs are in a
  // fill-reducing order already (the constructor's), so it is sparse.
  VertexBlockFactor interior;
  // Z⁻¹, Z = A_ΓΓ + S − A_ΓI A_II⁻¹ A_IΓ: one symmetric product by it per
  // tick (BLAS dsymv, its lower half) costs less than Z's two triangular
  // solves (BENCHMARKS.md, "The implicit step").
  Eigen::MatrixXd schur_inverse;
  double seconds = 0;  // what make() took

  // A with S on Γ, factored: the interior's sparse Cholesky (for the
  // ticks), and Z⁻¹ from the same block dense, by LAPACK and BLAS-3:
  // A_II = L Lᵀ, W = L⁻¹ A_IΓ, Z = A_ΓΓ + S − Wᵀ W, then Z⁻¹ (its lower
  // half). Reads only its arguments (a worker thread's).
  static std::unique_ptr<RegionFactorization> make(SparseMatrixd a, const Eigen::MatrixXd& s,
                                                   Index interior_dofs) {
    const auto start = std::chrono::steady_clock::now();
    auto f = std::make_unique<RegionFactorization>();
    f->a = std::move(a);
    const Index ni = interior_dofs, ng = f->a.rows() - interior_dofs;
    f->gamma_rows = f->a.bottomRows(ng);
    Eigen::MatrixXd z = s;
    z += Eigen::MatrixXd(f->a.bottomRightCorner(ng, ng));
    const int n_i = static_cast<int>(ni), n_g = static_cast<int>(ng);
    // LAPACKE's _work routines, column-major: LAPACK itself, no NaN scan.
    lapack_int info = 0;
    if (ni > 0) {
      Eigen::MatrixXd l(f->a.topLeftCorner(ni, ni));
      info = LAPACKE_dpotrf_work(LAPACK_COL_MAJOR, 'L', n_i, l.data(), n_i);
      PALPATE_DEMAND(info >= 0);
      if (info != 0)
        throw InputError(fmt::format(
            "{}: the step matrix of the region's {} interior DOFs is not positive definite; "
            "element stiffnesses precompute wrote (positive semi-definite) are accepted",
            kImplicitStepWhat, ni));
      f->interior = VertexBlockFactor(l);
      f->a_ig = f->a.block(0, ni, ni, ng);
      if (ng > 0) {
        Eigen::MatrixXd w(f->a_ig);
        cblas_dtrsm(CblasColMajor, CblasLeft, CblasLower, CblasNoTrans, CblasNonUnit, n_i, n_g, 1.0,
                    l.data(), n_i, w.data(), n_i);
        cblas_dsyrk(CblasColMajor, CblasLower, CblasTrans, n_g, n_i, -1.0, w.data(), n_i, 1.0,
                    z.data(), n_g);
      }
    }
    if (ng > 0) {
      info = LAPACKE_dpotrf_work(LAPACK_COL_MAJOR, 'L', n_g, z.data(), n_g);
      if (info == 0) info = LAPACKE_dpotri_work(LAPACK_COL_MAJOR, 'L', n_g, z.data(), n_g);
      PALPATE_DEMAND(info >= 0);
      if (info != 0)
        throw InputError(fmt::format(
            "{}: the step matrix on the region's boundary Γ ({} DOFs) is not positive definite; "
            "a compliance file precompute wrote and checked is accepted",
            kImplicitStepWhat, ng));
    }
    f->schur_inverse = std::move(z);  // its lower half
    f->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return f;
  }
};

void SolveScratch::size(Index interior_dofs, Index gamma_dofs) {
  interior = VectorXd::Zero(interior_dofs);
  gamma = VectorXd::Zero(gamma_dofs);
}

namespace {

// x = A₀⁻¹ x in place (ordered DOFs) with factorization @p f: y = A_II⁻¹ b_I,
// x_Γ = Z⁻¹ (b_Γ − A_ΓI y), x_I = A_II⁻¹ (b_I − A_IΓ x_Γ). Allocates nothing.
void base_solve(const RegionFactorization& f, Index ni, Eigen::Ref<VectorXd> x, SolveScratch& w) {
  const Index ng = x.size() - ni;
  if (ni > 0) {
    w.interior = x.head(ni);
    f.interior.solve_in_place(w.interior);
    if (ng > 0) x.tail(ng).noalias() -= f.a_ig.transpose() * w.interior;
  }
  if (ng > 0) {
    symmetric_product(f.schur_inverse, x.tail(ng), w.gamma);
    x.tail(ng) = w.gamma;
  }
  if (ni > 0) {
    w.interior = x.head(ni);
    if (ng > 0) w.interior.noalias() -= f.a_ig * w.gamma;
    f.interior.solve_in_place(w.interior);
    x.head(ni) = w.interior;
  }
}

}  // namespace

// What the worker hands over: the factorization and Y's columns for the
// vertices it took from the queue (each vertex's three DOFs in a row).
struct RegionRefactor {
  std::unique_ptr<RegionFactorization> factor;
  std::vector<Index> dofs;
  Eigen::MatrixXd y;
};

namespace {
// The interior's vertices (neither fixed nor on Γ) in a minimum-degree
// order of their graph (AMD), which keeps A_II's Cholesky factor sparse.
// The order is the mesh's: a cut removes edges only, so fill never grows.
std::vector<int> interior_elimination_order(const TensorMassModel& model,
                                            const std::vector<char>& on_gamma) {
  const int nv = model.vertex_count();
  std::vector<int> slot(static_cast<std::size_t>(nv), -1), vertex;
  for (int v = 0; v < nv; ++v)
    if (!model.is_fixed(v) && on_gamma[v] == 0) {
      slot[v] = static_cast<int>(vertex.size());
      vertex.push_back(v);
    }
  const auto n = static_cast<Index>(vertex.size());
  std::vector<Eigen::Triplet<double>> pattern;
  for (Index k = 0; k < n; ++k) pattern.emplace_back(k, k, 1.0);
  for (const auto& [i, j] : model.edges())
    if (slot[i] >= 0 && slot[j] >= 0) pattern.emplace_back(slot[i], slot[j], 1.0);
  SparseMatrixd graph(n, n);
  graph.setFromTriplets(pattern.begin(), pattern.end());
  // AMD of graph + graphᵀ; indices()[k] is the k-th vertex to eliminate.
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> order;
  Eigen::AMDOrdering<int>()(graph, order);
  std::vector<int> ordered(vertex.size());
  for (Index k = 0; k < n; ++k) ordered[static_cast<std::size_t>(k)] = vertex[order.indices()[k]];
  return ordered;
}
}  // namespace

ImplicitRegionStep::ImplicitRegionStep(const TensorMassModel& model, std::span<const int> interface,
                                       const Eigen::MatrixXd& coupling,
                                       const ImplicitStepCoefficients& coefficients,
                                       const std::vector<char>& on_skin, int refactor_rank)
    : model_(model),
      coupling_(coupling),
      coefficients_(coefficients),
      refactor_rank_(refactor_rank),
      gamma_(interface.begin(), interface.end()) {
  PALPATE_DEMAND(coupling.rows() == 3 * static_cast<Index>(gamma_.size()) &&
                 coupling.cols() == coupling.rows() && refactor_rank >= 3);
  const int nv = model.vertex_count();
  on_gamma_.assign(static_cast<std::size_t>(nv), 0);
  for (int v : gamma_) on_gamma_[v] = 1;
  interface_proximal_.assign(static_cast<std::size_t>(nv), Matrix3d::Zero());
  for (std::size_t k = 0; k < gamma_.size(); ++k)
    interface_proximal_[gamma_[k]] =
        coefficients.interface_damping * coupling.block<3, 3>(3 * k, 3 * k);
  // Interior DOFs first, in the fill-reducing order, then Γ (as loaded).
  first_dof_.assign(static_cast<std::size_t>(nv), -1);
  Index next = 0;
  double mass = 0;
  int moving = 0;
  for (int v = 0; v < nv; ++v) {
    if (model.is_fixed(v)) continue;
    if (!model.is_detached(v)) {
      mass += model.mass_kg(v);
      ++moving;
    }
  }
  for (int v : interior_elimination_order(model, on_gamma_)) {
    first_dof_[v] = static_cast<int>(next);
    next += 3;
  }
  interior_dofs_ = next;
  for (int v : gamma_) {
    first_dof_[v] = static_cast<int>(next);
    next += 3;
  }
  dofs_ = next;
  vertex_at_dof_.assign(static_cast<std::size_t>(dofs_), -1);
  for (int v = 0; v < nv; ++v)
    if (first_dof_[v] >= 0) vertex_at_dof_[static_cast<std::size_t>(first_dof_[v])] = v;
  // A held vertex weighs on A as a typical vertex's mass term does.
  hold_n_per_m_ = coefficients.mass_coefficient() * (moving > 0 ? mass / moving : 1e-6);
  dof_slot_.assign(static_cast<std::size_t>(dofs_), -1);
  ordered_ = VectorXd::Zero(dofs_);
  scratch_.size(interior_dofs_, dofs_ - interior_dofs_);
  factor_ = RegionFactorization::make(assemble(on_skin), coupling_, interior_dofs_);
  ++factorizations_;
  refresh_capacitance(on_skin);
}

// The worker_'s destructor waits for a factorization under way.
ImplicitRegionStep::~ImplicitRegionStep() = default;

Matrix3d ImplicitRegionStep::diagonal_block(int v, const std::vector<char>& on_skin) const {
  const double diagonal = coefficients_.mass_coefficient() * model_.mass_kg(v) +
                          (on_skin[v] != 0 ? coefficients_.skin_stiffness_n_per_m : 0.0) +
                          (holds(v) ? hold_n_per_m_ : 0.0);
  return model_.vertex_tensor(v) + diagonal * Matrix3d::Identity() + interface_proximal_[v];
}

SparseMatrixd ImplicitRegionStep::assemble(const std::vector<char>& on_skin) const {
  std::vector<Eigen::Triplet<double>> entries;
  const auto add = [&](int i, int j, const Matrix3d& block) {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        if (block(a, b) != 0)
          entries.emplace_back(first_dof_[i] + a, first_dof_[j] + b, block(a, b));
  };
  for (int v = 0; v < model_.vertex_count(); ++v)
    if (first_dof_[v] >= 0) add(v, v, diagonal_block(v, on_skin));
  Matrix3d k_ij;
  for (const auto& [i, j] : model_.edges())
    if (first_dof_[i] >= 0 && first_dof_[j] >= 0 && model_.edge_tensor(i, j, k_ij)) {
      add(i, j, k_ij);
      add(j, i, k_ij.transpose());
    }
  SparseMatrixd a(dofs_, dofs_);
  a.setFromTriplets(entries.begin(), entries.end());
  return a;
}

void ImplicitRegionStep::solve(CRef<VectorXd> b, Eigen::Ref<VectorXd> x) {
  PALPATE_DEMAND(b.size() == 3 * model_.vertex_count() && x.size() == b.size());
  to_ordered(b);
  solve_ordered();
  from_ordered(x);
}

void ImplicitRegionStep::solve_offset(CRef<VectorXd> b, CRef<VectorXd> gamma_offset,
                                      Eigen::Ref<VectorXd> x) {
  const Index ng = dofs_ - interior_dofs_;
  PALPATE_DEMAND(b.size() == 3 * model_.vertex_count() && x.size() == b.size() &&
                 gamma_offset.size() == ng);
  to_ordered(b);
  // − (A − S) u_Γ⁰: the base factor's sparse Γ columns, and the cuts'
  // change D on the update's Γ DOFs.
  ordered_.noalias() -= factor_->a.rightCols(ng) * gamma_offset;
  if (rank_ > 0) {
    for (int k = 0; k < rank_; ++k)
      picked_[k] =
          update_dofs_[k] >= interior_dofs_ ? gamma_offset[update_dofs_[k] - interior_dofs_] : 0.0;
    weights_.noalias() = d_ * picked_;
    for (int k = 0; k < rank_; ++k) ordered_[update_dofs_[k]] -= weights_[k];
  }
  solve_ordered();
  ordered_.tail(ng) += gamma_offset;
  from_ordered(x);
}

void ImplicitRegionStep::to_ordered(CRef<VectorXd> x) {
  for (int v = 0; v < model_.vertex_count(); ++v)
    if (first_dof_[v] >= 0) ordered_.segment<3>(first_dof_[v]) = x.segment<3>(3 * v);
}

void ImplicitRegionStep::from_ordered(Eigen::Ref<VectorXd> x) const {
  for (int v = 0; v < model_.vertex_count(); ++v)
    x.segment<3>(3 * v) = first_dof_[v] >= 0 ? Eigen::Vector3d(ordered_.segment<3>(first_dof_[v]))
                                             : Eigen::Vector3d::Zero();
}

void ImplicitRegionStep::solve_ordered() {
  base_solve(*factor_, interior_dofs_, ordered_, scratch_);
  if (rank_ > 0) {
    // Woodbury: A⁻¹ b = A₀⁻¹ b − Y (I + D Eᵀ Y)⁻¹ D Eᵀ A₀⁻¹ b.
    for (int k = 0; k < rank_; ++k) picked_[k] = ordered_[update_dofs_[k]];
    weights_.noalias() = d_ * picked_;
    picked_ = capacitance_.solve(weights_);
    // ordered −= Y w (BLAS dgemv: about twice Eigen's own here).
    const int rows = static_cast<int>(dofs_), columns = rank_, lda = static_cast<int>(y_.rows());
    cblas_dgemv(CblasColMajor, CblasNoTrans, rows, columns, -1.0, y_.data(), lda, picked_.data(), 1,
                1.0, ordered_.data(), 1);
  }
}

void ImplicitRegionStep::interface_rows(CRef<VectorXd> x, Eigen::Ref<VectorXd> out) {
  PALPATE_DEMAND(x.size() == 3 * model_.vertex_count() && out.size() == dofs_ - interior_dofs_);
  to_ordered(x);
  out.noalias() = factor_->gamma_rows * ordered_;
  if (rank_ > 0) {
    for (int k = 0; k < rank_; ++k) picked_[k] = ordered_[update_dofs_[k]];
    weights_.noalias() = d_ * picked_;
    for (int k = 0; k < rank_; ++k)
      if (update_dofs_[k] >= interior_dofs_) out[update_dofs_[k] - interior_dofs_] += weights_[k];
  }
}

void ImplicitRegionStep::add_update_dofs(std::span<const int> touched) {
  for (int v : touched) {
    if (first_dof_[v] < 0 || dof_slot_[first_dof_[v]] >= 0) continue;
    if (y_.cols() < rank_ + 3) y_.conservativeResize(dofs_, std::max<Index>(2 * y_.cols(), 48));
    for (int a = 0; a < 3; ++a) {
      const Index dof = first_dof_[v] + a;
      ordered_.setZero();
      ordered_[dof] = 1;
      base_solve(*factor_, interior_dofs_, ordered_, scratch_);
      y_.col(rank_) = ordered_;
      dof_slot_[dof] = rank_++;
      update_dofs_.push_back(dof);
    }
  }
}

// D = (A now − A₀) on the update's DOFs, which holds every change a cut
// made (a removed tetrahedron changes only the blocks among its four
// vertices, and the skin and hold flags of those); the capacitance
// I + D Eᵀ Y factored.
void ImplicitRegionStep::refresh_capacitance(const std::vector<char>& on_skin) {
  d_.setZero(rank_, rank_);
  picked_.setZero(rank_);
  weights_.setZero(rank_);
  if (rank_ == 0) return;
  // The update's vertices: each enters with its three DOFs in a row.
  std::vector<int> vertex_of(static_cast<std::size_t>(rank_ / 3));
  for (int k = 0; k < rank_; k += 3)
    vertex_of[k / 3] = vertex_at_dof_[static_cast<std::size_t>(update_dofs_[k])];
  Matrix3d now;
  for (std::size_t p = 0; p < vertex_of.size(); ++p)
    for (std::size_t q = 0; q < vertex_of.size(); ++q) {
      const int vp = vertex_of[p], vq = vertex_of[q];
      if (vp == vq)
        now = diagonal_block(vp, on_skin);
      else if (!model_.edge_tensor(vp, vq, now))
        now.setZero();
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          d_(3 * p + a, 3 * q + b) =
              now(a, b) - factor_->a.coeff(first_dof_[vp] + a, first_dof_[vq] + b);
    }
  Eigen::MatrixXd c(rank_, rank_);
  for (int k = 0; k < rank_; ++k) c.row(k) = y_.row(update_dofs_[k]).head(rank_);
  capacitance_.compute(Eigen::MatrixXd::Identity(rank_, rank_) + d_ * c);
}

void ImplicitRegionStep::adopt(std::unique_ptr<RegionRefactor> refactor,
                               const std::vector<char>& on_skin) {
  factor_ = std::move(refactor->factor);
  ++factorizations_;
  ++background_factorizations_;
  // The update starts again from the worker's columns: the vertices cut
  // since its snapshot, then those cut after it closed its queue.
  for (Index dof : update_dofs_) dof_slot_[dof] = -1;
  update_dofs_ = std::move(refactor->dofs);
  rank_ = static_cast<int>(update_dofs_.size());
  for (int k = 0; k < rank_; ++k) dof_slot_[update_dofs_[k]] = k;
  y_ = std::move(refactor->y);
  add_update_dofs(worker_.cut_after());
  refresh_capacitance(on_skin);
}

void ImplicitRegionStep::finish_background_work(const std::vector<char>& on_skin) {
  if (worker_.running()) adopt(worker_.take(), on_skin);
}

double ImplicitRegionStep::last_factorization_s() const { return factor_->seconds; }

// A snapshot of A now, factored on the worker's thread, which then computes
// Y's columns for the vertices the ticks cut meanwhile (its queue) until none
// is left, and closes the queue: the cut that adopts it has only those cut
// after that to compute.
void ImplicitRegionStep::launch_refactor(const std::vector<char>& on_skin) {
  worker_.start([a = assemble(on_skin), &s = coupling_, ni = interior_dofs_,
                 first_dof = first_dof_](CutQueue& cuts) mutable {
    auto out = std::make_unique<RegionRefactor>();
    out->factor = RegionFactorization::make(std::move(a), s, ni);
    const Index n = out->factor->a.rows();
    SolveScratch scratch;
    scratch.size(ni, n - ni);
    std::vector<char> done(first_dof.size(), 0);
    VectorXd x(n);
    std::vector<int> batch;
    while (cuts.take(batch)) {
      for (int v : batch) {
        if (first_dof[v] < 0 || done[v] != 0) continue;
        done[v] = 1;
        const auto k = static_cast<Index>(out->dofs.size());
        out->y.conservativeResize(n, k + 3);
        for (int axis = 0; axis < 3; ++axis) {
          x.setZero();
          x[first_dof[v] + axis] = 1;
          base_solve(*out->factor, ni, x, scratch);
          out->y.col(k + axis) = x;
          out->dofs.push_back(first_dof[v] + axis);
        }
      }
    }
    return out;
  });
}

void ImplicitRegionStep::update(std::span<const int> touched, const std::vector<char>& on_skin) {
  // The worker takes these vertices if its queue is still open.
  if (worker_.running()) worker_.note_cut(touched);
  if (worker_.finished()) finish_background_work(on_skin);
  add_update_dofs(touched);
  if (rank_ >= kWaitFactor * refactor_rank_) {
    // Past kWaitFactor times the bound: the worker's, if under way, else factored now.
    if (worker_.running()) {
      finish_background_work(on_skin);
    } else {
      for (Index dof : update_dofs_) dof_slot_[dof] = -1;
      update_dofs_.clear();
      rank_ = 0;
      factor_ = RegionFactorization::make(assemble(on_skin), coupling_, interior_dofs_);
      ++factorizations_;
    }
  } else if (rank_ >= refactor_rank_ && !worker_.running()) {
    launch_refactor(on_skin);
  }
  refresh_capacitance(on_skin);
}

}  // namespace palpate::detail
