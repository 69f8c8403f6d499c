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
/// add_tips()) and handed to ActiveSet::solve as rows(), and the pose each
/// tool had at the solve last stored (solved()), which drags its sticking
/// tip points along while it takes part in every solve. Imposed
/// displacements in m, model frame (a warped row's in its point's material
/// frame: d̂ = R̃⁻¹ d, n̂ = R̃ᵀ n / s, δ̂ = δ / s). Allocates nothing after
/// construction.
class ContactRows {
 public:
  /// A tool at this solve, as its rows need it.
  struct Tool {
    int index = 0;  ///< among the engine's tools
    const ToolGeometry* geometry = nullptr;
    Eigen::Vector3d hinge_m = Eigen::Vector3d::Zero();
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  ///< tool → model
    double scale = 1;          ///< the watchdog's ramp, 1 → 0: of every imposed displacement
    bool ramping_out = false;  ///< the watchdog ramps it out: no drag
  };

  /// Room for @p capacity rows in all (the callers' per-tool caps keep
  /// within it) of @p tools tools. @p surface (deformed by
  /// the last solve) and @p background (linear engines: loads the tools do
  /// not make) must outlive it; a warped @p surface makes warped rows.
  ContactRows(int capacity, int tools, DeformedSurface& surface, BackgroundLoads& background);

  /// The solve just stored had tool @p tool at @p hinge_m, @p rotation;
  /// @p drags: it took part (its sticking points are dragged from there by
  /// its motion until the next solve stored).
  void solved(int tool, bool drags, const Eigen::Vector3d& hinge_m,
              const Eigen::Matrix3d& rotation);
  /// Tool @p tool drags nothing from before (it resumed, or its session ended).
  void forget_drag(int tool) { drag_[static_cast<std::size_t>(tool)].drags = false; }

  /// Forgets the rows built (a new solve).
  void begin() { count_ = 0; }
  /// A row per point @p held of @p tool (in the tool frame): the point is
  /// taken to where the jaws have it, d = s (x + R l − p_rest).
  void add_held(const Tool& tool, std::span<const HeldPoint> held);
  /// A row per tip contact of @p tool, @p tips (deepest first): its target
  /// t on the tip's surface (normal n),
  ///
  ///     d = s (t − p_rest) + (I − n nᵀ)(t − w),   w = x⁻ + R⁻ Rᵀ (t − x),
  ///
  /// with friction (the drag term while the tool drags from its solved()
  /// pose x⁻, R⁻: where its motion since took the tissue at t, in the
  /// contact's plane), else the normal displacement nᵀ d without the drag;
  /// a contact not penetrating is dormant.
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

  struct Drag {  // a tool at the stored solve
    bool drags = false;
    Eigen::Vector3d hinge_m = Eigen::Vector3d::Zero();
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  };

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
  std::vector<Drag> drag_;  // per tool
};

}  // namespace palpate::detail
