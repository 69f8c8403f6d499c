#include "palpate/runtime/solve/point_compliance.hpp"

#include <algorithm>

#include "palpate/core/error.hpp"

namespace palpate::detail {

namespace {
using Eigen::Matrix3d;
using Strided = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
}  // namespace

PointCompliance::PointCompliance(const SurfaceModel& model, int max_rows) : model_(model) {
  PALPATE_DEMAND(max_rows > 0);
  const auto k = index(max_rows);
  const auto max_used = 3 * k;
  const auto u3 = 3 * max_used;
  const auto n = index(model.compliance_vertex_count());
  used_epoch_.assign(n, 0);
  used_slot_.assign(n, 0);
  used_index_.resize(max_used);
  point_slot_.resize(3 * k);
  G_UU_.resize(u3 * u3);
  Y_.resize(u3 * 3 * k);
  has_Y_.resize(k);
  complete_.resize(max_used);
}

void PointCompliance::number(std::span<const ActiveRow> rows) {
  rows_ = rows;
  if (++used_clock_ == 0) {
    std::fill(used_epoch_.begin(), used_epoch_.end(), 0);
    used_clock_ = 1;
  }
  used_ = 0;
  // The vertices of the rows in the set first (slots 0 … pressed_), then
  // those only watched rows use.
  for (const bool pressed : {true, false})
    for (int r = 0; r < static_cast<int>(rows_.size()); ++r) {
      const ActiveRow& row = rows_[index(r)];
      if ((row.state == ActiveRow::kActive) != pressed) continue;
      int kept = 0;
      for (int i = 0; i < 3; ++i) {
        const int a = i < row.count ? row.index[index(i)] : -1;
        int& slot = point_slot_[3 * index(r) + index(i)];
        slot = -1;
        if (a < 0) continue;
        PALPATE_DEMAND(a < model_.compliance_vertex_count());
        const auto aa = index(a);
        if (used_epoch_[aa] != used_clock_) {
          used_epoch_[aa] = used_clock_;
          used_slot_[aa] = used_++;
          used_index_[index(used_slot_[aa])] = a;
        }
        slot = used_slot_[aa];
        ++kept;
      }
      PALPATE_DEMAND(kept > 0);
      has_Y_[index(r)] = 0;
    }
  // G_UU, and the Y after it, packed at the tick's size (a leading
  // dimension of the largest possible U spreads a small one over many
  // pages). G is symmetric (G^ba = (G^ab)ᵀ, the compliance of a linear
  // elastic body): one read gives both blocks. Among the watched rows'
  // own vertices nothing is read until one of them joins (complete_
  // marks the columns read in full): their gaps need G only against the
  // loaded vertices.
  int pressed = 0;
  for (int r = 0; r < static_cast<int>(rows_.size()); ++r)
    if (rows_[index(r)].state == ActiveRow::kActive)
      for (int i = 0; i < 3; ++i)
        pressed = std::max(pressed, point_slot_[3 * index(r) + index(i)] + 1);
  const int ld = 3 * used_;
  Strided G_UU(G_UU_.data(), 3 * used_, 3 * used_, Eigen::OuterStride<>(ld));
  for (int b = 0; b < used_; ++b) {
    complete_[index(b)] = b < pressed ? 1 : 0;
    for (int a = 0; a <= std::min(b, pressed - 1); ++a) {
      const Matrix3d block = model_.G_block(used_index_[index(a)], used_index_[index(b)]);
      G_UU.block<3, 3>(3 * a, 3 * b) = block;
      if (a != b) G_UU.block<3, 3>(3 * b, 3 * a) = block.transpose();
    }
  }
}

/// Reads the blocks of G_UU's column b not read yet (against the other
/// watched-only vertices whose columns are not complete).
void PointCompliance::complete_column(int b) {
  if (complete_[index(b)]) return;
  complete_[index(b)] = 1;
  const int ld = 3 * used_;
  Strided G_UU(G_UU_.data(), 3 * used_, 3 * used_, Eigen::OuterStride<>(ld));
  for (int a = 0; a < used_; ++a) {
    if (complete_[index(a)] && a != b) continue;
    const Matrix3d block = model_.G_block(used_index_[index(a)], used_index_[index(b)]);
    G_UU.block<3, 3>(3 * a, 3 * b) = block;
    if (a != b) G_UU.block<3, 3>(3 * b, 3 * a) = block.transpose();
  }
}

/// Y_r = G_UU H_rᵀ (3u × 3): the displacement of U under a unit force at row r's point.
void PointCompliance::compute_Y(int r) {
  if (has_Y_[index(r)]) return;
  has_Y_[index(r)] = 1;
  const int ld = 3 * used_;
  const int u3 = 3 * used_;
  const Strided G_UU(G_UU_.data(), u3, u3, Eigen::OuterStride<>(ld));
  Strided Y(&Y_[index(ld) * 3 * index(r)], u3, 3, Eigen::OuterStride<>(ld));
  Y.setZero();
  const ActiveRow& row = rows_[index(r)];
  for (int i = 0; i < row.count; ++i) {
    const int slot = point_slot_[3 * index(r) + index(i)];
    if (slot < 0) continue;
    complete_column(slot);
    Y.noalias() += row.weights[index(i)] * G_UU.middleCols<3>(3 * slot);
  }
}

/// P_rs = H_r G H_sᵀ = H_r Y_s (Y_s computed).
Matrix3d PointCompliance::P_block(int r, int s) {
  const int ld = 3 * used_;
  const Strided Y(&Y_[index(ld) * 3 * index(s)], 3 * used_, 3, Eigen::OuterStride<>(ld));
  const ActiveRow& row = rows_[index(r)];
  Matrix3d P = Matrix3d::Zero();
  for (int i = 0; i < row.count; ++i) {
    const int slot = point_slot_[3 * index(r) + index(i)];
    if (slot >= 0) P.noalias() += row.weights[index(i)] * Y.middleRows<3>(3 * slot);
  }
  return P;
}

std::optional<Matrix3d> PointCompliance::read_block(int a, int b) const {
  if (used_epoch_[index(a)] == used_clock_ && used_epoch_[index(b)] == used_clock_) {
    const int sa = used_slot_[index(a)], sb = used_slot_[index(b)];
    // A complete column holds every block of it (and, mirrored, of its row).
    if (complete_[index(sa)] || complete_[index(sb)]) {
      const int ld = 3 * used_;
      const Strided G_UU(const_cast<double*>(G_UU_.data()), ld, ld, Eigen::OuterStride<>(ld));
      return G_UU.block<3, 3>(3 * sa, 3 * sb);
    }
  }
  return std::nullopt;
}

}  // namespace palpate::detail
