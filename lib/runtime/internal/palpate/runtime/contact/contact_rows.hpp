#pragma once
/// @file
/// The constraint rows of one contact solve (internal to the runtime; the
/// engine's step 4, docs/tools.md "One tick" and "Friction"): one row per
/// held point (its target follows the jaws) and per tip contact (its point
/// put back on the tip's surface, dragged along by the tool's motion since
/// the last solve while it sticks), each over its triangle's vertices, the
/// background loads' displacement discounted, turned into its point's frame
/// on a warped model; with what the local model needs of each row.

#include <Eigen/Core>
#include <span>
#include <vector>

#include "palpate/runtime/contact/background_loads.hpp"
#include "palpate/runtime/contact/deformed_surface.hpp"
#include "palpate/runtime/contact/jaw_grasp.hpp"
#include "palpate/runtime/contact/local_model.hpp"
#include "palpate/runtime/contact/surface_point.hpp"
#include "palpate/runtime/contact/tip_contacts.hpp"
#include "palpate/runtime/request_status.hpp"
#include "palpate/runtime/solve/active_set.hpp"
#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::detail {

/// The rows of a solve, built tool by tool (begin(), add_held() and
/// add_tips()) and handed to ActiveSet::solve as rows(). Imposed
/// displacements in m, model frame (a warped row's in its point's material
/// frame: d̂ = R̃⁻¹ d, n̂ = R̃ᵀ n / s, δ̂ = δ / s). Allocates nothing after
/// construction.
class ContactRows {
 public:
  /// A tool as its rows need it: its pose at this solve, and the pose the
  /// stored solution was solved at (the friction drag).
  struct Tool {
    int index = 0;
    const ToolGeometry* geometry = nullptr;
    Eigen::Vector3d hinge_m = Eigen::Vector3d::Zero();
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  ///< tool → model
    double scale = 1;  ///< the watchdog's ramp, 1 → 0: of every imposed displacement
    /// The tool took part in every solve since the stored one and is not
    /// ramping out: a sticking tip point is dragged by its motion since.
    bool drags = false;
    Eigen::Vector3d solved_hinge_m = Eigen::Vector3d::Zero();
    Eigen::Matrix3d solved_rotation = Eigen::Matrix3d::Identity();
  };

  /// Room for @p capacity rows. @p surface (deformed by the last solve) and
  /// @p background (linear engines: loads the tools do not make) must
  /// outlive it; a warped @p surface makes warped rows.
  ContactRows(int capacity, DeformedSurface& surface, BackgroundLoads& background);

  /// Forgets the rows built (a new solve).
  void begin() { count_ = 0; }
  /// A row per point @p held of @p tool (in the tool frame): the point is
  /// taken to where the jaws have it, d = s (x + R l − p_rest).
  void add_held(const Tool& tool, std::span<const HeldPoint> held);
  /// A row per tip contact of @p tool, @p tips (deepest first): its target
  /// on the tip's surface, d = s (target − p_rest), with friction a
  /// displacement dragged in the contact's plane by the tool's motion since
  /// the solved pose, without it a normal displacement; a contact not
  /// penetrating is dormant.
  void add_tips(const Tool& tool, std::span<const TipCandidate> tips);

  int count() const { return count_; }
  /// Rows in their points' frames (a warped surface).
  bool warped() const { return surface_.warped(); }
  std::span<ActiveRow> rows() { return {rows_.data(), static_cast<std::size_t>(count_)}; }
  std::span<const ActiveRow> rows() const {
    return {rows_.data(), static_cast<std::size_t>(count_)};
  }
  const ActiveRow& row(int b) const { return rows_[static_cast<std::size_t>(b)]; }
  /// Row @p b's tool; its tip contact's index, or −1 for a held point.
  int tool(int b) const { return tool_[static_cast<std::size_t>(b)]; }
  int tip(int b) const { return tip_[static_cast<std::size_t>(b)]; }
  /// Row @p b's surface point (the caller's held point or tip contact:
  /// valid while those stay as they were when it was built).
  const SurfacePoint& point(int b) const { return *point_[static_cast<std::size_t>(b)]; }
  /// Warped: R̃ of row @p b's point (identity when linear). Its normal in the world.
  const Eigen::Matrix3d& rotation(int b) const { return rotation_[static_cast<std::size_t>(b)]; }
  const Eigen::Vector3d& world_normal(int b) const {
    return world_normal_[static_cast<std::size_t>(b)];
  }
  /// What the local model needs of each row (its solved point and force
  /// are the caller's to fill in).
  LocalRow& local(int b) { return local_[static_cast<std::size_t>(b)]; }
  std::span<const LocalRow> local_rows() const {
    return {local_.data(), static_cast<std::size_t>(count_)};
  }

 private:
  void add(const Tool& tool, int tip, const SurfacePoint& point, ConstraintKind kind,
           Eigen::Vector3d value, const Eigen::Vector3d& normal, const Eigen::Vector3d& lever,
           double depth);

  DeformedSurface& surface_;
  BackgroundLoads& background_;
  int compliance_count_;
  int count_ = 0;
  std::vector<ActiveRow> rows_;
  std::vector<int> tool_, tip_;
  std::vector<const SurfacePoint*> point_;
  std::vector<Eigen::Matrix3d> rotation_;
  std::vector<Eigen::Vector3d> world_normal_;
  std::vector<LocalRow> local_;
};

}  // namespace palpate::detail
