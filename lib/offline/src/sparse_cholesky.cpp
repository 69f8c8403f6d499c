#include "palpate/offline/sparse_cholesky.hpp"

#include <cholmod.h>
#include <fmt/format.h>

#include <chrono>
#include <cstring>

#include "palpate/core/detail/stopwatch.hpp"

namespace palpate {

namespace {

struct Common {
  cholmod_common c{};
  Common() {
    cholmod_start(&c);
    c.print = 0;
    c.error_handler = nullptr;  // status is checked after every call
    c.supernodal = CHOLMOD_SUPERNODAL;
  }
  ~Common() { cholmod_finish(&c); }
  Common(const Common&) = delete;
  Common& operator=(const Common&) = delete;

  void check(const char* what) const {
    if (c.status == CHOLMOD_OUT_OF_MEMORY)
      throw ResourceError(fmt::format("CHOLMOD ran out of memory in {}", what));
    if (c.status < CHOLMOD_OK)
      throw SystemError(fmt::format("CHOLMOD failed in {} (status {})", what, c.status));
  }
};

// A CHOLMOD view of an Eigen sparse matrix's upper triangle (no copy).
cholmod_sparse view_upper(const SparseMatrixd& A) {
  PALPATE_DEMAND(A.isCompressed() && A.rows() == A.cols());
  cholmod_sparse s{};
  s.nrow = static_cast<size_t>(A.rows());
  s.ncol = static_cast<size_t>(A.cols());
  s.nzmax = static_cast<size_t>(A.nonZeros());
  s.p = const_cast<int*>(A.outerIndexPtr());
  s.i = const_cast<int*>(A.innerIndexPtr());
  s.x = const_cast<double*>(A.valuePtr());
  s.stype = 1;
  s.itype = CHOLMOD_INT;
  s.xtype = CHOLMOD_REAL;
  s.dtype = CHOLMOD_DOUBLE;
  s.sorted = 1;
  s.packed = 1;
  return s;
}

cholmod_dense view_dense(const double* data, Eigen::Index rows, Eigen::Index cols) {
  cholmod_dense d{};
  d.nrow = static_cast<size_t>(rows);
  d.ncol = static_cast<size_t>(cols);
  d.nzmax = d.nrow * d.ncol;
  d.d = d.nrow;
  d.x = const_cast<double*>(data);
  d.xtype = CHOLMOD_REAL;
  d.dtype = CHOLMOD_DOUBLE;
  return d;
}

const char* ordering_name(int ordering) {
  switch (ordering) {
    case CHOLMOD_NATURAL:
      return "natural";
    case CHOLMOD_GIVEN:
      return "given";
    case CHOLMOD_AMD:
      return "amd";
    case CHOLMOD_METIS:
      return "metis";
    case CHOLMOD_NESDIS:
      return "nesdis";
    case CHOLMOD_COLAMD:
      return "colamd";
    case CHOLMOD_POSTORDERED:
      return "postordered";
    default:
      return "unknown";
  }
}

// Symbolic analysis: CHOLMOD's fill-reducing ordering, or exactly the given
// elimination order (no postordering) when one is given.
cholmod_factor* analyze(cholmod_sparse* A, std::span<const int> permutation, Common& common) {
  auto& c = common.c;
  cholmod_factor* L = nullptr;
  if (!permutation.empty()) {
    PALPATE_DEMAND(permutation.size() == A->nrow);
    c.nmethods = 1;
    c.method[0].ordering = CHOLMOD_GIVEN;
    c.postorder = 0;
    L = cholmod_analyze_p(A, const_cast<int*>(permutation.data()), nullptr, 0, &c);
  } else {
    L = cholmod_analyze(A, &c);
  }
  common.check("cholmod_analyze");
  return L;
}

using detail::seconds_since;

}  // namespace

struct SparseCholesky::Impl {
  Common common;
  cholmod_factor* L = nullptr;
  FactorInfo info;
  ~Impl() { cholmod_free_factor(&L, &common.c); }
};

// cholmod_solve2's result and scratch arrays, reused across solves, with the
// Common that allocated them (CHOLMOD's Common is not shared across threads).
class SparseCholesky::Workspace {
 public:
  Common common;
  cholmod_dense* X = nullptr;
  cholmod_dense* Y = nullptr;
  cholmod_dense* E = nullptr;
  Workspace() = default;
  ~Workspace() {
    cholmod_free_dense(&X, &common.c);
    cholmod_free_dense(&Y, &common.c);
    cholmod_free_dense(&E, &common.c);
  }
  Workspace(const Workspace&) = delete;
  Workspace& operator=(const Workspace&) = delete;
};

SparseCholesky::SparseCholesky(const SparseMatrixd& upper, std::span<const int> permutation)
    : impl_(std::make_unique<Impl>()) {
  auto& c = impl_->common.c;
  cholmod_sparse A = view_upper(upper);
  const auto t0 = std::chrono::steady_clock::now();
  impl_->L = analyze(&A, permutation, impl_->common);
  impl_->info.analyze_seconds = seconds_since(t0);
  impl_->info.ordering = ordering_name(c.method[c.selected].ordering);

  const auto t1 = std::chrono::steady_clock::now();
  cholmod_factorize(&A, impl_->L, &c);
  if (c.status == CHOLMOD_NOT_POSDEF) {
    const int* perm = static_cast<const int*>(impl_->L->Perm);
    const int column = perm ? perm[impl_->L->minor] : static_cast<int>(impl_->L->minor);
    throw NotPositiveDefinite(column, fmt::format("the matrix is not positive definite: Cholesky "
                                                  "failed at column {}",
                                                  column));
  }
  impl_->common.check("cholmod_factorize");
  impl_->info.factor_seconds = seconds_since(t1);
  impl_->info.nnz_L = c.lnz;
  impl_->info.flops = c.fl;
  impl_->info.supernodes = static_cast<int>(impl_->L->is_super ? impl_->L->nsuper : 0);
  impl_->info.bytes = impl_->L->is_super
                          ? static_cast<double>(impl_->L->xsize) * sizeof(double) +
                                static_cast<double>(impl_->L->ssize) * sizeof(int)
                          : static_cast<double>(impl_->L->nzmax) * (sizeof(double) + sizeof(int));
}

SparseCholesky::~SparseCholesky() = default;

SparseCholesky::WorkspacePtr SparseCholesky::make_workspace() const {
  return WorkspacePtr(new Workspace());
}

void SparseCholesky::WorkspaceDeleter::operator()(Workspace* w) const { delete w; }

int SparseCholesky::rows() const { return static_cast<int>(impl_->L->n); }
const FactorInfo& SparseCholesky::info() const { return impl_->info; }

void SparseCholesky::solve(CRef<Eigen::MatrixXd> B, Eigen::Ref<Eigen::MatrixXd> X) {
  if (!default_workspace_) default_workspace_ = make_workspace();
  solve(B, X, *default_workspace_);
}

void SparseCholesky::solve(CRef<Eigen::MatrixXd> B, Eigen::Ref<Eigen::MatrixXd> X,
                           Workspace& ws) const {
  PALPATE_DEMAND(B.rows() == rows() && X.rows() == B.rows() && X.cols() == B.cols());
  auto& c = ws.common.c;
  Eigen::MatrixXd contiguous;
  const double* data = B.data();
  if (B.outerStride() != B.rows()) {
    contiguous = B;
    data = contiguous.data();
  }
  cholmod_dense b = view_dense(data, B.rows(), B.cols());
  cholmod_solve2(CHOLMOD_A, impl_->L, &b, nullptr, &ws.X, nullptr, &ws.Y, &ws.E, &c);
  ws.common.check("cholmod_solve2");
  X = Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(ws.X->x), B.rows(), B.cols());
}

std::vector<int> SparseCholesky::permutation() const {
  const int* p = static_cast<const int*>(impl_->L->Perm);
  return std::vector<int>(p, p + impl_->L->n);
}

void SparseCholesky::trailing_factor_block(Eigen::Ref<Eigen::MatrixXd> out) const {
  const cholmod_factor* L = impl_->L;
  PALPATE_DEMAND(L->is_super && out.rows() == out.cols());
  const Eigen::Index n = static_cast<Eigen::Index>(L->n);
  const Eigen::Index m = out.rows();
  const Eigen::Index first = n - m;
  out.setZero();
  const int* super = static_cast<const int*>(L->super);
  const int* pi = static_cast<const int*>(L->pi);
  const int* px = static_cast<const int*>(L->px);
  const int* Ls = static_cast<const int*>(L->s);
  const double* Lx = static_cast<const double*>(L->x);
  for (size_t s = 0; s < L->nsuper; ++s) {
    const int k1 = super[s], k2 = super[s + 1];
    if (k2 <= first) continue;
    const int nsrow = pi[s + 1] - pi[s];
    for (int j = std::max<int>(k1, static_cast<int>(first)); j < k2; ++j) {
      const double* column = Lx + px[s] + static_cast<size_t>(j - k1) * nsrow;
      // Rows of the supernode's diagonal block above j hold no part of L.
      for (int r = j - k1; r < nsrow; ++r) out(Ls[pi[s] + r] - first, j - first) = column[r];
    }
  }
}

std::vector<int> SparseCholesky::fill_reducing_ordering(const SparseMatrixd& upper) {
  Common common;
  common.c.supernodal = CHOLMOD_SIMPLICIAL;  // symbolic analysis only: keep it light
  cholmod_sparse A = view_upper(upper);
  cholmod_factor* L = cholmod_analyze(&A, &common.c);
  common.check("cholmod_analyze");
  const int* p = static_cast<const int*>(L->Perm);
  std::vector<int> perm(p, p + L->n);
  cholmod_free_factor(&L, &common.c);
  return perm;
}

SparseCholesky::Estimate SparseCholesky::estimate(const SparseMatrixd& upper,
                                                  std::span<const int> permutation) {
  Common common;
  cholmod_sparse A = view_upper(upper);
  cholmod_factor* L = analyze(&A, permutation, common);
  Estimate e;
  e.bytes =
      static_cast<double>(L->xsize) * sizeof(double) + static_cast<double>(L->ssize) * sizeof(int);
  e.nnz_L = common.c.lnz;
  e.flops = common.c.fl;
  cholmod_free_factor(&L, &common.c);
  return e;
}

double SparseCholesky::estimate_factor_bytes(const SparseMatrixd& upper,
                                             std::span<const int> permutation) {
  return estimate(upper, permutation).bytes;
}

}  // namespace palpate
