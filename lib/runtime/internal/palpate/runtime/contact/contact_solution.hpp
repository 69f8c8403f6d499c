#pragma once
/// @file
/// The last successful solve of a contact engine (internal to the runtime;
/// the end of the engine's step 4, docs/tools.md "One tick"): every tool's
/// contact points and their forces, the same forces as loads on the
/// surface's vertices (f_S = Hᵀ f_C, what deforms the surface for the next
/// tick and what the surface field needs), each tool's raw wrench (before
/// the device's limits), the triangles the tips touched (for the next
/// tick's hysteresis shell), and the two bounds the next tick's search
/// takes from them.

#include <Eigen/Core>
#include <span>
#include <vector>

#include "palpate/runtime/contact/background_loads.hpp"
#include "palpate/runtime/contact/contact_rows.hpp"
#include "palpate/runtime/contact_point.hpp"
#include "palpate/runtime/solve/active_set.hpp"

namespace palpate::detail {

/// The points, loads and raw wrenches of the last successful solve, stored
/// row by row (ContactRows) from the active set: begin(), add() for each
/// active row, then gather_loads(). Forces on the organ in N (a warped
/// engine's loads and material forces f̂ in the material frame, its points'
/// forces in the world's), positions in m, model frame. Allocates nothing
/// after construction.
class ContactSolution {
 public:
  /// A tool's raw contact wrench: what the organ pushes it back with, before
  /// the device's limits (FeedbackLimits).
  struct RawWrench {
    Eigen::Vector3d force_n = Eigen::Vector3d::Zero();    ///< −Σ f, on the tool, N
    Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();  ///< Σ (p − hinge) × −f, N·m
    double grip_n = 0;  ///< Σ over held points of ½ |f · x_tool| (each face's squeeze), N
    int contacts = 0;   ///< its points, tip and held
  };

  /// Room for @p max_points points of @p tools tools (≥ 1) on a surface of
  /// @p triangles triangles whose vertices from @p compliance_count on are
  /// fixed (allocates). Empty at first.
  ContactSolution(int tools, int max_points, int compliance_count, int triangles);

  /// Starts storing a new solution: the last one's points and wrenches are
  /// forgotten (and which triangles its tips touched).
  void begin();
  /// Stores row @p b of @p rows (kActive), as @p solve solved it, as the
  /// next point: its world force and position (@p background's
  /// displacement of the point added: linear engines), the energy and the
  /// largest displacement, and its tool's wrench about @p hinge_m (the
  /// tool's frame → model frame: @p tool_rotation, whose x the grip is
  /// along). @returns the point stored.
  const ContactPoint& add(const ActiveSet& solve, const ContactRows& rows, int b,
                          const Eigen::Vector3d& hinge_m, const Eigen::Matrix3d& tool_rotation,
                          BackgroundLoads& background);
  /// After the last add(): the points' forces as loads on their vertices,
  /// f_S = Hᵀ f_C (material), tool by tool (a vertex two tools load
  /// appears once for each; fixed vertices take none: the attachment does).
  void gather_loads();

  int count() const { return count_; }
  std::span<const ContactPoint> points() const {
    return {points_.data(), static_cast<std::size_t>(count_)};
  }
  /// Point @p c's force as the solve has it (f̂: material when warped), N.
  const Eigen::Vector3d& material_force(int c) const {
    return material_force_[static_cast<std::size_t>(c)];
  }
  const RawWrench& wrench(int tool) const { return wrench_[static_cast<std::size_t>(tool)]; }
  /// The loads: a compliance vertex each, its force (3 per load), its tool.
  int load_count() const { return load_count_; }
  std::span<const int> load_indices() const {
    return {load_index_.data(), static_cast<std::size_t>(load_count_)};
  }
  std::span<const double> load_forces() const {
    return {load_force_.data(), 3 * static_cast<std::size_t>(load_count_)};
  }
  std::span<const int> load_tools() const {
    return {load_tool_.data(), static_cast<std::size_t>(load_count_)};
  }
  /// The largest displacement of a point, m (the next tick's search reaches
  /// this much farther).
  double max_displacement_m() const { return max_displacement_; }
  /// fᵀ G f of the loads, J (f_Cᵀ u_C over the points, material): with
  /// ‖G^{vv}‖, it bounds every vertex's displacement (DeformedSurface::far_from).
  double load_energy_j() const { return load_energy_; }
  /// Per drawn triangle: the tool whose tip touched it in this solution, or −1.
  std::span<const int> triangle_owner() const { return triangle_owner_; }

 private:
  int compliance_count_;
  int count_ = 0;
  std::vector<ContactPoint> points_;
  std::vector<Eigen::Vector3d> material_force_;  // per point
  std::vector<RawWrench> wrench_;                // per tool
  int load_count_ = 0;
  std::vector<int> load_index_;     // compliance vertex per load
  std::vector<int> load_tool_;      // tool per load
  std::vector<double> load_force_;  // 3 per load, N
  std::vector<int> load_slot_;      // per compliance vertex: its load this tool, or -1
  double max_displacement_ = 0;
  double load_energy_ = 0;
  std::vector<int> triangle_owner_;
};

}  // namespace palpate::detail
