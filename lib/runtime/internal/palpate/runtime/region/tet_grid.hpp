#pragma once
/// @file
/// The tensor-mass region's tetrahedra at rest in a uniform grid of cubes,
/// each tetrahedron listed in every cell its bounding box overlaps, so that
/// the tetrahedra a cutting blade may meet are found by the cells along it
/// rather than by a scan of every tetrahedron (TensorMassModel's cut
/// queries). Internal to the runtime layer; immutable once built (removed
/// tetrahedra stay listed: the caller skips them), allocation-free to query.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace palpate::detail {

class TetGrid {
 public:
  using Cell = std::array<int, 3>;

  TetGrid() = default;
  /// @p rest_m #V × 3, metres; @p tetrahedra #T × 4 indices into its rows.
  /// The cells' side is the mean over the tetrahedra of their bounding
  /// box's largest side (about the element size: a tetrahedron is listed
  /// in at most 2 × 2 × 2 cells of a structured mesh), enlarged to keep at
  /// most 2^18 cells.
  TetGrid(const Eigen::MatrixX3d& rest_m, const Eigen::MatrixX4i& tetrahedra);

  /// The cell holding @p x, each index clamped to the grid: monotone in
  /// each coordinate, so the cells from cell_of(lo) to cell_of(hi) hold
  /// every tetrahedron whose bounding box meets the box [lo, hi].
  Cell cell_of(const Eigen::Vector3d& x) const;
  /// The tetrahedra listed in @p cell, ascending.
  std::span<const int> tetrahedra_in(const Cell& cell) const;
  /// The closed box of @p cell: centre and half side (m).
  Eigen::Vector3d cell_centre(const Cell& cell) const;
  double half_side_m() const { return 0.5 / inverse_cell_; }
  /// The grid's box, the rest bounding box of the vertices the tetrahedra use.
  const Eigen::Vector3d& lower_m() const { return origin_; }
  const Eigen::Vector3d& upper_m() const { return upper_; }
  std::int64_t cell_count() const { return std::int64_t{dims_[0]} * dims_[1] * dims_[2]; }
  const Cell& dims() const { return dims_; }  ///< cells along x, y, z
  /// Entries of the cell lists (about 8 per tetrahedron on a structured mesh).
  std::size_t entry_count() const { return tets_.size(); }

 private:
  std::size_t flat(const Cell& cell) const {
    return static_cast<std::size_t>(cell[0]) +
           static_cast<std::size_t>(dims_[0]) *
               (static_cast<std::size_t>(cell[1]) +
                static_cast<std::size_t>(dims_[1]) * static_cast<std::size_t>(cell[2]));
  }
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero(), upper_ = Eigen::Vector3d::Zero();
  double inverse_cell_ = 1;  // 1 / the cells' side, 1/m
  Cell dims_{1, 1, 1};
  std::vector<int> begin_{0, 0};  // CSR: per cell, into tets_; one more at the end
  std::vector<int> tets_;
};

}  // namespace palpate::detail
