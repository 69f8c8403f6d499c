#pragma once
/// @file
/// The compliance among a tick's candidate contact points, from G read once
/// per tick (internal to the runtime; the active set's kIncremental path).

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/runtime/solve/active_row.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace palpate::detail {

/// G on the distinct vertices U of a tick's candidate points (every row the
/// active set may solve for, in or out of the set), and per row
/// Y_r = G_UU H_rᵀ, from which the points' compliance P_rs = H_r G H_sᵀ is
/// read by 3×3 blocks (docs/model/requests.md, "The reduced system of a
/// request"; H_r: the row's barycentric weights on its vertices).
///
/// number() numbers U (the rows in the set first) and reads G_UU among the
/// vertices of the rows in the set; a column of a watched-only vertex is
/// read in full only when a Y that needs it is computed (a watched row's gap
/// needs G only against the loaded vertices). G is symmetric (the
/// compliance of a linear elastic body): one read of G^ab gives both blocks.
/// G_UU and the Y are packed at the tick's size: 3u × 3u and 3u × 3 per row,
/// column-major, m/N.
///
/// Allocates only in its constructor (for up to max_rows rows: 81 max_rows²
/// doubles for G_UU, 27 max_rows² for the Y, 8 bytes per compliance vertex);
/// every method is allocation-free. @p model must outlive it; the rows given
/// to number() must stay in place (their vertices and weights unchanged)
/// until the next number().
class PointCompliance {
 public:
  PointCompliance(const SurfaceModel& model, int max_rows);

  /// Numbers the vertices of @p rows (each row's 1 to 3 compliance indices,
  /// −1 for a fixed vertex, at least one not fixed), reads G among those of
  /// the rows in the set (ActiveRow::kActive), and forgets every Y.
  void number(std::span<const ActiveRow> rows);

  /// Computes Y_r = G_UU H_rᵀ (3u × 3, the displacement of U under a unit
  /// force at row r's point), reading the columns of G_UU it needs; nothing
  /// when it is computed already.
  void compute_Y(int r);
  /// P_rs = H_r G H_sᵀ = H_r Y_s (3 × 3, m/N); Y_s computed.
  Eigen::Matrix3d P_block(int r, int s);

  /// G^ab (3 × 3, m/N) between compliance vertices @p a and @p b when it was
  /// read (both in U, one of their columns read in full); else nothing.
  std::optional<Eigen::Matrix3d> read_block(int a, int b) const;

  int used() const { return used_; }  ///< u
  /// Row r's vertex i's place in U; −1 for a fixed vertex (or i ≥ count).
  int slot(int r, int i) const { return point_slot_[3 * index(r) + index(i)]; }
  /// Y_r (3u × 3), computed.
  Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>> Y(int r) const {
    const int ld = 3 * used_;
    return {&Y_[index(ld) * 3 * index(r)], ld, 3, Eigen::OuterStride<>(ld)};
  }

 private:
  static std::size_t index(int r) { return static_cast<std::size_t>(r); }
  void complete_column(int b);

  const SurfaceModel& model_;
  std::span<const ActiveRow> rows_;
  std::vector<std::uint32_t> used_epoch_;
  std::vector<int> used_slot_;  // per compliance vertex
  std::uint32_t used_clock_ = 0;
  int used_ = 0;
  std::vector<int> used_index_;
  std::vector<int> point_slot_;  // 3 per row: place of each vertex in U, −1 fixed
  std::vector<double> G_UU_;     // 3·max_used × 3·max_used, column-major
  std::vector<double> Y_;        // 3·max_used × 3 per row
  std::vector<char> has_Y_;
  std::vector<char> complete_;  // per slot of U: its column of G_UU read in full
};

}  // namespace palpate::detail
