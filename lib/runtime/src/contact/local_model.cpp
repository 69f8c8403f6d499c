#include "palpate/runtime/contact/local_model.hpp"

#include <Eigen/Dense>
#include <algorithm>

#include "palpate/core/error.hpp"

namespace palpate::detail {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
constexpr int kMotions = 6;  // δx, then δθ, each along x, y, z

/// Motion c of the tool: a unit translation (c < 3) or a unit turn about
/// the hinge (c ≥ 3), as it moves a point with @p lever.
Vector3d motion(int c, const Vector3d& lever) {
  const Vector3d axis = Vector3d::Unit(c % 3);
  return c < 3 ? axis : Vector3d(axis.cross(lever));
}

}  // namespace

LocalModel::LocalModel(int max_rows, int compliance_vertices) {
  const auto k = static_cast<std::size_t>(max_rows);
  slot_of_.assign(static_cast<std::size_t>(compliance_vertices), -1);
  vertex_.resize(3 * k);
  shift_load_.resize(3 * k);
  shift_disp_.resize(3 * k);
  force_change_.resize(3 * k);
  loaded_.resize(3 * k);
  moved_.resize(3 * k);
  moved_vertex_.resize(3 * k);
  in_.resize(3 * k * kMotions);
  out_.resize(3 * k * kMotions);
  moved_point_.resize(k);
  turned_normal_.resize(k);
  moved_target_.resize(k);
}

int LocalModel::slot(int v) {
  if (v < 0) return -1;
  int& s = slot_of_[static_cast<std::size_t>(v)];
  if (s < 0) {
    s = slots_++;
    const auto ss = static_cast<std::size_t>(s);
    vertex_[ss] = v;
    shift_load_[ss].setZero();
    shift_disp_[ss].setZero();
    force_change_[ss].setZero();
    loaded_[ss] = 0;
    moved_[ss] = 0;
  }
  return s;
}

void LocalModel::forget_slots() {
  for (int s = 0; s < slots_; ++s)
    slot_of_[static_cast<std::size_t>(vertex_[static_cast<std::size_t>(s)])] = -1;
  slots_ = 0;
}

LocalModel::Matrix6d LocalModel::stiffness(std::span<const ActiveRow> rows,
                                           std::span<const LocalRow> local, int tool,
                                           const Vector3d& hinge_m, double scale, ActiveSet& set) {
  PALPATE_DEMAND(rows.size() == local.size());
  const int n = static_cast<int>(rows.size());
  const auto at = [n](int c, int r) { return 3 * static_cast<std::size_t>(c * n + r); };
  const auto sliding = [](const ActiveRow& row) {
    return row.kind == ConstraintKind::kNormalDisplacement;
  };
  Matrix6d K = Matrix6d::Zero();
  forget_slots();
  std::fill_n(in_.begin(), 3 * static_cast<std::size_t>(n) * kMotions, 0.0);
  bool any = false;

  // What each motion imposes on the tool's rows, and the loads it moves:
  // a tip point's force shifted within its triangle (δw f̂), a sliding
  // point's force turned with its normal (φ δn).
  for (int r = 0; r < n; ++r) {
    const ActiveRow& row = rows[static_cast<std::size_t>(r)];
    const LocalRow& l = local[static_cast<std::size_t>(r)];
    if (row.state != ActiveRow::kActive) continue;
    for (int i = 0; i < row.count; ++i) slot(row.index[static_cast<std::size_t>(i)]);
    if (l.tool != tool) continue;
    any = true;
    const auto rr = static_cast<std::size_t>(r);
    const Matrix3d to_material = l.rotation.inverse();
    const Matrix3d across = Matrix3d::Identity() - l.normal * l.normal.transpose();
    // The weights' change that moves the deformed point by δp in its
    // triangle (3 weights) or along its edge (2); a vertex's stays.
    Eigen::Matrix<double, 3, 2> D = Eigen::Matrix<double, 3, 2>::Zero();
    Vector3d edge = Vector3d::Zero();
    if (l.tip && row.count == 3) D << l.corners[1] - l.corners[0], l.corners[2] - l.corners[0];
    if (l.tip && row.count == 2) edge = l.corners[1] - l.corners[0];
    const auto qr = D.colPivHouseholderQr();
    // Slip of a sliding point and its force along the normal (world).
    const Vector3d slip = across * (l.position - l.target);
    const double phi = l.force.dot(l.normal);
    for (int c = 0; c < kMotions; ++c) {
      const Vector3d dc = motion(c, l.lever);
      if (!l.tip) {
        moved_target_[rr].col(c) = dc;
        Eigen::Map<Vector3d>{&in_[at(c, r)]} = scale * (to_material * dc);
        continue;
      }
      Vector3d dp = Vector3d::Zero();
      if (row.count == 3 && !l.material) dp = across * dc;
      if (row.count == 2 && !l.material && edge.squaredNorm() > 0)
        dp = edge * (edge.dot(dc) / edge.squaredNorm());
      const Vector3d dn = l.distance > 1e-9 * l.radius ? Vector3d(across * (dp - dc) / l.distance)
                                                       : Vector3d::Zero();
      // A sticking point is also taken along with the tool's motion at it,
      // in its tangent plane (the drag, docs/tools.md "Friction").
      const Vector3d drag = sliding(row)
                                ? Vector3d::Zero()
                                : Vector3d(across * motion(c, l.lever + l.radius * l.normal));
      const Vector3d dtarget = dc + l.radius * dn + drag;
      moved_point_[rr].col(c) = dp;
      turned_normal_[rr].col(c) = dn;
      moved_target_[rr].col(c) = dtarget;
      Vector3d imposed = dtarget - dp;
      if (sliding(row)) imposed -= l.normal * dn.dot(slip);
      Eigen::Map<Vector3d>{&in_[at(c, r)]} = scale * (to_material * imposed);
      std::array<double, 3> dw{};
      if (row.count == 3) {
        const Eigen::Vector2d w12 = qr.solve(dp);
        dw = {-w12(0) - w12(1), w12(0), w12(1)};
      } else if (row.count == 2 && edge.squaredNorm() > 0) {
        dw[1] = edge.dot(dp) / edge.squaredNorm();
        dw[0] = -dw[1];
      }
      const Vector3d turned =
          sliding(row) ? Vector3d(phi * (l.rotation.transpose() * dn)) : Vector3d::Zero();
      for (int i = 0; i < row.count; ++i) {
        const int s = slot(row.index[static_cast<std::size_t>(i)]);
        if (s < 0) continue;
        const Vector3d moved_load = dw[static_cast<std::size_t>(i)] * l.material_force +
                                    row.weights[static_cast<std::size_t>(i)] * turned;
        if (moved_load.squaredNorm() == 0) continue;
        loaded_[static_cast<std::size_t>(s)] = 1;
        shift_load_[static_cast<std::size_t>(s)].col(c) += scale * moved_load;
      }
    }
  }
  if (!any) return K;

  // σ = G ℓ: the displacement of every vertex met under the moved loads,
  // and each row's share, which the solve must take back.
  for (int a = 0; a < slots_; ++a)
    for (int v = 0; v < slots_; ++v)
      if (loaded_[static_cast<std::size_t>(v)])
        shift_disp_[static_cast<std::size_t>(a)].noalias() +=
            set.G_block(vertex_[static_cast<std::size_t>(a)],
                        vertex_[static_cast<std::size_t>(v)]) *
            shift_load_[static_cast<std::size_t>(v)];
  for (int r = 0; r < n; ++r) {
    const ActiveRow& row = rows[static_cast<std::size_t>(r)];
    if (row.state != ActiveRow::kActive) continue;
    for (int i = 0; i < row.count; ++i) {
      const int s = slot(row.index[static_cast<std::size_t>(i)]);
      if (s < 0) continue;
      for (int c = 0; c < kMotions; ++c)
        Eigen::Map<Vector3d>{&in_[at(c, r)]} -= row.weights[static_cast<std::size_t>(i)] *
                                                shift_disp_[static_cast<std::size_t>(s)].col(c);
    }
  }

  set.force_response(in_.data(), out_.data(), kMotions);

  // The forces' change (a sliding point's turns with its normal too), as
  // loads for the sliding points' displacements; the wrench −Σ δf and
  // −Σ (p − x) × δf; the levers' own motion below.
  bool any_sliding = false;
  for (int r = 0; r < n; ++r) {
    const ActiveRow& row = rows[static_cast<std::size_t>(r)];
    const LocalRow& l = local[static_cast<std::size_t>(r)];
    if (row.state != ActiveRow::kActive) continue;
    const auto rr = static_cast<std::size_t>(r);
    const bool turns = l.tool == tool && l.tip && sliding(row);
    any_sliding |= turns;
    const double phi = l.force.dot(l.normal);
    for (int c = 0; c < kMotions; ++c) {
      // B δφ as loads (the turn of a sliding force is a moved load: in σ).
      Eigen::Map<Vector3d> df(&out_[at(c, r)]);  // material
      for (int i = 0; i < row.count; ++i) {
        const int s = slot(row.index[static_cast<std::size_t>(i)]);
        if (s >= 0)
          force_change_[static_cast<std::size_t>(s)].col(c) +=
              row.weights[static_cast<std::size_t>(i)] * df;
      }
      if (turns) df += scale * phi * (l.rotation.transpose() * turned_normal_[rr].col(c));
    }
    if (l.tool != tool) continue;
    const Matrix3d to_world = l.rotation.transpose().inverse();
    const Vector3d arm = l.position - hinge_m;
    for (int c = 0; c < kMotions; ++c) {
      const Vector3d df = to_world * Eigen::Map<const Vector3d>(&out_[at(c, r)]);
      K.block<3, 1>(0, c) -= df;
      K.block<3, 1>(3, c) -= arm.cross(df);
      if (sliding(row)) continue;  // its point's motion needs its displacement: below
      // A held or sticking point moves with its target; the hinge by δx.
      const Vector3d dx = c < 3 ? Vector3d(Vector3d::Unit(c)) : Vector3d::Zero();
      K.block<3, 1>(3, c) -= (scale * moved_target_[rr].col(c) - dx).cross(l.force);
    }
  }
  if (!any_sliding) return K;

  // A sliding point moves along its normal as its constraint says,
  // nᵀ δp = nᵀ δtarget − δnᵀ t, and along the surface with the point found
  // (δp) and its displacement's tangential change P δu, δu = H (G Hᵀ δf̂ + σ).
  for (int r = 0; r < n; ++r) {
    const ActiveRow& row = rows[static_cast<std::size_t>(r)];
    const LocalRow& l = local[static_cast<std::size_t>(r)];
    if (row.state != ActiveRow::kActive || l.tool != tool || !l.tip || !sliding(row)) continue;
    const auto rr = static_cast<std::size_t>(r);
    Block du = Block::Zero();
    for (int i = 0; i < row.count; ++i) {
      const int a = row.index[static_cast<std::size_t>(i)];
      if (a < 0) continue;
      // A vertex's δu is the same for every row on it: computed once.
      const auto sa = static_cast<std::size_t>(slot(a));
      if (!moved_[sa]) {
        Block& at_a = moved_vertex_[sa];
        at_a = shift_disp_[sa];
        for (int v = 0; v < slots_; ++v)
          at_a.noalias() += set.G_block(a, vertex_[static_cast<std::size_t>(v)]) *
                            force_change_[static_cast<std::size_t>(v)];
        moved_[sa] = 1;
      }
      du += row.weights[static_cast<std::size_t>(i)] * moved_vertex_[sa];
    }
    const Matrix3d across = Matrix3d::Identity() - l.normal * l.normal.transpose();
    const Vector3d slip = across * (l.position - l.target);
    for (int c = 0; c < kMotions; ++c) {
      const Vector3d along_normal =
          l.normal * (l.normal.dot(moved_target_[rr].col(c)) - turned_normal_[rr].col(c).dot(slip));
      const Vector3d dp = scale * (along_normal + across * moved_point_[rr].col(c)) +
                          across * (l.rotation * du.col(c));
      const Vector3d dx = c < 3 ? Vector3d(Vector3d::Unit(c)) : Vector3d::Zero();
      K.block<3, 1>(3, c) -= (dp - dx).cross(l.force);
    }
  }
  return K;
}

}  // namespace palpate::detail
