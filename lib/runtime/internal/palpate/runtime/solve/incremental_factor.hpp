#pragma once
/// @file
/// An SPD matrix and its Cholesky factor, edited as unknowns join and leave
/// (internal to the runtime; the active set's kIncremental path).

#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate::detail {

/// W = L Lᵀ: the m × m SPD matrix of the active set's unknowns (W = Bᵀ P B,
/// m/N) and its lower Cholesky factor L, both column-major with leading
/// dimension max_unknowns, kept in step as unknowns join and leave, so that
/// a change of the set costs O(m²) or O(m² k) instead of a factorization
/// (O(m³)). What the unknowns are (rows, directions) is the caller's.
///
///  - append(): k unknowns join at the end. With W = [W11 W12; W21 W22]
///    and W11 = L11 L11ᵀ, L21 = W21 L11⁻ᵀ (BLAS dtrsm) and
///    L22 L22ᵀ = W22 − L21 L21ᵀ (dsyrk, then LAPACK dpotrf on k × k).
///  - remove(): unknown p leaves. Without its row, L is lower triangular but
///    for one superdiagonal from column p on; Givens rotations of columns
///    (i, i+1), i = p … m−2, clear it (they leave L Lᵀ unchanged) and leave
///    the last column zero.
///  - condition_estimate(): W's 1-norm condition estimate (dpocon).
///  - solve(): W⁻¹ B in place (dpotrs).
///
/// Allocates only in its constructor (2 max_unknowns² + 4 max_unknowns
/// numbers); every method is allocation-free (BLAS and LAPACK in place).
class IncrementalFactor {
 public:
  /// Room for up to @p max_unknowns unknowns; starts empty.
  explicit IncrementalFactor(int max_unknowns);

  int size() const { return size_; }  ///< m
  /// Forgets every unknown (the next append() factors afresh).
  void clear() { size_ = 0; }

  /// Appends @p count unknowns (m + count ≤ max_unknowns): their columns of
  /// W are entry(p, q) for q = m … m + count − 1 and p = 0 … q, called in
  /// that order (column by column, W mirrored), then L is extended. Returns
  /// dpotrf's info for the new block: 0, or the column j (1-based, from the
  /// first new unknown) at which W stopped being positive definite, the
  /// factor then unusable (clear() before the next append()).
  template <typename Entry>
  int append(int count, Entry&& entry) {
    const int first = size_;
    size_ += count;
    const int m = size_;
    Strided W(W_.data(), m, m, Eigen::OuterStride<>(ld_));
    for (int q = first; q < m; ++q)
      for (int p = 0; p <= q; ++p) W(p, q) = W(q, p) = entry(p, q);
    return extend(first);
  }

  /// Removes unknown @p p (0 ≤ p < m) from W and from L.
  void remove(int p);

  /// W's 1-norm condition estimate, ‖W‖₁ ‖W⁻¹‖₁ (infinite when dpocon
  /// finds it singular); m ≥ 1.
  double condition_estimate();

  /// B ← W⁻¹ B for @p columns right-hand sides of m numbers each, one after
  /// the other in @p b. Returns dpotrs's info (0).
  int solve(double* b, int columns) const;

 private:
  using Strided = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  int extend(int first);

  int ld_ = 0;                 // max_unknowns
  int size_ = 0;               // m
  std::vector<double> W_, L_;  // max_unknowns × max_unknowns, column-major
  std::vector<double> work_;   // 3 max_unknowns, for dpocon
  std::vector<int> iwork_;     // max_unknowns
};

}  // namespace palpate::detail
