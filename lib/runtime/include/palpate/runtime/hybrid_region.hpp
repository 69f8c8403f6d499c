#pragma once
/// @file
/// The hybrid model as served (docs/model/hybrid-serving.md, "The hybrid model as served"):
/// a compliance file's cuttable region (/cut_region) stepped by the
/// tensor-mass model inside each tool tick, coupled to the precomputed rest
/// of the organ both ways through the file's own G:
///
///  - the rest's loads f_S (the tools' contacts on it) reach the region as
///    u_Γ⁰ = G_ΓS f_S, where Γ would go if the region pushed nothing;
///  - the region pushes on the rest with f_Γ = S (u_Γ − u_Γ⁰), S = G_ΓΓ⁻¹,
///    which moves the rest's surface by G_SΓ f_Γ;
///  - tool tips press the region's surface vertices off Γ (a penalty
///    force; on Γ the rest's triangles take the contact);
///  - a blade removes the region's tetrahedra it crosses (a cut), and the
///    faces the rest shares with a removed tetrahedron are uncovered.
///
/// Every time is in seconds, every length in metres, every force in newtons,
/// in the model frame (the compliance file's).

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tensor_mass.hpp"

namespace palpate {

namespace detail {
class ImplicitRegionStep;  // lib/runtime/internal/palpate/runtime/region/region_implicit_step.hpp
}

/// How the region's dynamics are integrated (docs/model/hybrid-serving.md, "The implicit
/// step" and "Substeps").
enum class RegionIntegrator {
  /// One backward-Euler step of implicit_step_s per tick (stable whatever
  /// the step; A factored once, cuts by low-rank updates).
  kImplicit,
  /// Explicit centred differences in substeps under the proven stable bound.
  kExplicit,
};

/// How the served region is stepped and touched.
struct HybridRegionSettings {
  RegionIntegrator integrator = RegionIntegrator::kImplicit;
  /// The implicit step Δt (s): the haptic tick; a tick of another length
  /// takes the whole steps nearest to it (the remainder carried over).
  double implicit_step_s = 1e-3;
  /// The implicit step's update rank (DOFs) at which A is factored again
  /// on a worker thread (at four times it, at once).
  int refactor_rank = 48;
  /// κ ≥ 0: the implicit step's dashpot at Γ, κ S_vv Δt per Γ vertex (S_vv
  /// its 3 × 3 block of S), against the negative damping of the rest's
  /// one-tick-late view of the region's push (docs/model/hybrid-serving.md).
  double interface_damping = 1;
  /// The explicit substep is this fraction of the stable step's proven bound
  /// (docs/model/hybrid-serving.md: the element bound, the coupling and the contacts).
  double step_safety = 0.9;
  /// Stiffness of a tip's push on one region surface vertex (N/m): the
  /// force is k (r − d) along the normal from the tip's axis, d the vertex's
  /// distance to the axis. It enters the stable step as k / m per tip.
  double contact_stiffness_n_per_m = 200;
  /// Tips that may press at once (sizes the buffers and the step bound).
  int max_tips = 4;
  /// γ (1/s) of the mass-proportional damping; negative: the file's.
  double damping_per_s = -1;
};

/// A tool tip as the region sees it: a capsule of radius r around the
/// segment base → end (a sphere when they are equal), model frame.
struct RegionTip {
  Eigen::Vector3d base_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d end_m = Eigen::Vector3d::Zero();
  double radius_m = 0;
};

/// A served model's cuttable region, stepped and coupled. Not thread-safe:
/// the caller serializes advance(), cut() and the readers. advance()
/// allocates nothing.
class HybridRegion {
 public:
  /// @param model a loaded compliance file with a cut region; must outlive
  ///        this object. G may be double or float32.
  /// @throws InputError when the model has no cut region, G_ΓΓ is not
  ///         positive definite, or a setting is out of range (what is accepted).
  explicit HybridRegion(const SurfaceModel& model, const HybridRegionSettings& settings = {});
  ~HybridRegion();
  HybridRegion(const HybridRegion&) = delete;
  HybridRegion& operator=(const HybridRegion&) = delete;

  /// Steps the region over @p tick_s (> 0, at most 10 ms of it) in steps
  /// of substep_s(): implicit, the whole steps nearest to the tick and the
  /// last tick's remainder; explicit, as many whole substeps as they hold
  /// (none when a tick is shorter than one: the last forces
  /// stand), under the rest's loads (compliance indices and 3
  /// forces each, the tool on the organ: ToolContactEngine::contact_indices
  /// and contact_forces) and at most max_tips tips pressing the region.
  /// Afterwards tip_force_n(t) is what the region pushes tip t with,
  /// averaged over the substeps, and interface_force_n() the region's push
  /// on the rest.
  /// @throws InputError for a tick that is not > 0, more tips than
  ///         max_tips, a force count other than 3 per rest load, or a rest
  ///         load on a vertex outside the compliance vertices.
  void advance(double tick_s, std::span<const int> rest_indices,
               std::span<const double> rest_forces_n, std::span<const RegionTip> tips);

  /// The force on tip @p tip from the region in the last advance() (N), and
  /// its torque about the tip's base (N·m), averaged over the substeps.
  const Eigen::Vector3d& tip_force_n(int tip) const { return tip_force_n_.at(tip); }
  const Eigen::Vector3d& tip_torque_nm(int tip) const { return tip_torque_nm_.at(tip); }
  /// Region surface vertices the tips pressed at the last substep.
  int pressed_vertices() const { return pressed_vertices_; }
  /// f_Γ = S (u_Γ − u_Γ⁰) (3n_Γ, N): the region's push on the rest at Γ,
  /// in the order of interface_vertices().
  const Eigen::VectorXd& interface_force_n() const { return interface_force_n_; }
  /// f_Γᵀ G_ΓΓ f_Γ = f_Γ · (u_Γ − u_Γ⁰) (J, ≥ 0 to round-off): the energy
  /// ToolContactEngine::set_background_loads takes with f_Γ.
  double interface_energy_j() const { return std::max(0.0, interface_force_n_.dot(gamma_u_m_)); }
  /// u_Γ − u_Γ⁰ = G_ΓΓ f_Γ (3n_Γ, m): what the push alone moves Γ by, in
  /// the order of interface_force_n() (ToolContactEngine::set_background_loads
  /// takes it to bound how far the push's changes move the surface).
  const Eigen::VectorXd& interface_displacement_m() const { return gamma_u_m_; }
  /// u += G_SΓ f_Γ: what the region's push adds to a displacement field of
  /// the rest's compliance vertices (3N_S, compliance order).
  void add_rest_displacement(Eigen::Ref<Eigen::VectorXd> u_m) const;
  /// The last external force on the region's vertices (3#R, N): the tips'.
  const Eigen::VectorXd& region_load_n() const { return region_load_n_; }

  /// Removes every remaining tetrahedron the blade a–b meets (rest geometry:
  /// the blade as it would lie on the undeformed organ). @returns how many.
  int cut(const Eigen::Vector3d& blade_a_m, const Eigen::Vector3d& blade_b_m);
  /// Removes every remaining tetrahedron the blade swept from @p before to
  /// @p after (rest geometry; TensorMassModel::tetrahedra_swept_by_blade):
  /// one tick of a moving edge. The query allocates nothing. @returns how many.
  int cut(const Blade& before, const Blade& after);

  /// The explicit step's proven stable bound now, step_safety × 2/ω bound
  /// (it can shrink after a cut: docs/model/hybrid-serving.md); the step (implicit:
  /// implicit_step_s; explicit: the bound as loaded, or as shortened by a
  /// cut); the steps the last advance() took.
  double substep_bound_s() const { return substep_bound_s_; }
  double substep_s() const { return substep_s_; }
  int substeps() const { return substeps_; }
  RegionIntegrator integrator() const { return settings_.integrator; }
  /// The implicit step's Woodbury update rank now (DOFs; 0 explicit), and
  /// how many times it factored A (the first time and the worker's included).
  int update_rank() const;
  int factorizations() const;
  /// How long the implicit step's factorization in use took (s; 0 explicit).
  double last_factorization_s() const;
  /// Waits for a factorization under way on the worker and adopts it (for
  /// tests and benchmarks; the ticks adopt it when it is done).
  void finish_background_work();

  const TensorMassModel& tensor_mass() const { return model_; }
  /// The Γ vertices the region still holds (region numbering; a cut that
  /// leaves one without a tetrahedron releases it), and their compliance
  /// indices in the rest's G.
  const std::vector<int>& interface_vertices() const { return interface_; }
  const std::vector<int>& interface_compliance_indices() const { return interface_compliance_; }
  /// Region vertex v's position now (rest + u), m.
  Eigen::Vector3d position_m(int vertex) const;
  /// Where point @p x_m of the deformed region was at rest, to first order:
  /// x minus the displacement of the region's vertex nearest to it (a scan
  /// of the remaining vertices; x itself when none remains). For placing a
  /// blade given in the world on the rest geometry cut() takes.
  Eigen::Vector3d rest_point_of(const Eigen::Vector3d& x_m) const;
  /// Increments with every change of the region's surface (cuts).
  std::uint64_t topology_version() const { return model_.boundary_version(); }
  /// The region's surface to draw and touch (region vertex numbering,
  /// outward): its boundary without the faces it shares with the rest. No
  /// allocation when @p out has room for every face (4 per tetrahedron).
  void visible_triangles(std::vector<std::array<int, 3>>& out) const;
  /// True when drawn triangle @p triangle of the rest (SurfaceModel::surface)
  /// lies against a remaining region tetrahedron: inside the organ, neither
  /// drawn nor touched. Rest faces of removed tetrahedra are uncovered.
  bool covers_rest_triangle(int triangle) const;
  /// Writes the rest's drawn triangles the region covers now into @p out
  /// (room for interface_face_count()); @returns how many.
  int covered_rest_triangles(std::span<std::uint32_t> out) const;
  /// The rest's drawn triangles the region covered as loaded (the faces Γ).
  int interface_face_count() const { return static_cast<int>(interface_faces_.size()); }

 private:
  struct InterfaceFace {
    std::array<int, 3> region_sorted{};  // region vertices, increasing
    int rest_triangle = -1;              // drawn triangle of the rest
    int region_tet = -1;                 // the region tetrahedron behind it
  };
  void update_after_topology_change();
  void release_detached_interface();
  void add_coupling_force();
  int after_cut(int removed);
  void update_coupling_row_sums();
  bool is_interface_face(const std::array<int, 3>& triangle) const;
  void add_tip_forces(std::span<const RegionTip> tips, bool accumulate);
  // hybrid_region_step.cpp: the time stepping.
  void update_explicit_bound();
  void retime_explicit_step();
  void advance_explicit(std::span<const RegionTip> tips);
  void advance_implicit(std::span<const RegionTip> tips);
  void offset_from_rest_loads(std::span<const int> rest_indices,
                              std::span<const double> rest_forces_n);

  const SurfaceModel& model_ref_;
  HybridRegionSettings settings_;
  TensorMassModel model_;
  std::vector<int> interface_;             // region vertices, CutRegionData's order
  std::vector<int> interface_compliance_;  // their compliance indices
  // Γ as loaded, and each held vertex's place in it (implicit: S stays the
  // loaded one; a released vertex keeps its rows with no region behind).
  std::vector<int> loaded_interface_, loaded_compliance_, held_slot_;
  Eigen::MatrixXd coupling_;       // S = G_ΓΓ⁻¹ (explicit: condensed on the held Γ)
  double coupling_eigen_max_ = 0;  // λ_max(S)
  double element_omega2_ = 0;      // the element bound alone, 1/s²

  std::vector<InterfaceFace> interface_faces_;  // sorted by region_sorted
  std::vector<int> rest_triangle_face_;         // per rest drawn triangle: interface face or −1
  std::vector<int> skin_;                       // moving vertices of the visible surface
  std::vector<char> on_skin_;
  std::vector<std::array<int, 3>> visible_;
  std::vector<int> removed_;  // cut()'s, capacity: every tetrahedron

  double substep_bound_s_ = 0, substep_s_ = 0, pending_s_ = 0;
  int substeps_ = 0, pressed_vertices_ = 0;
  Eigen::VectorXd offset_m_, interface_force_n_, gamma_u_m_;
  Eigen::VectorXd region_load_n_, step_force_n_, retimed_m_;
  Eigen::VectorXd coupling_row_sum_;  // Σ_w |S_vw| per Γ DOF
  // The implicit step: the factored A, its right-hand side, u⁺, u_Γ⁰ and
  // the push on the loaded Γ, its rows of A − S.
  std::unique_ptr<detail::ImplicitRegionStep> implicit_;
  Eigen::VectorXd rhs_n_, next_m_, loaded_offset_m_, loaded_push_n_, loaded_rows_n_;
  std::vector<char> skin_before_;
  std::vector<int> touched_;
  std::vector<Eigen::Vector3d> tip_force_n_, tip_force_step_n_, tip_torque_nm_, tip_torque_step_nm_;
};

}  // namespace palpate
