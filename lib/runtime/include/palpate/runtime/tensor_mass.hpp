#pragma once
/// @file
/// The tensor-mass model of a cuttable region (docs/model/tensor-mass.md, "The
/// tensor-mass model: a cuttable region"; Cotin, Delingette & Ayache, IEEE
/// TVCG 5(1), 1999): linear elasticity on P1 tetrahedra stored the lecture's
/// way, a 3 × 3 tensor K_ii on each vertex and K_ij on each edge, stepped by
/// explicit centred differences with mass-proportional damping, coupled to
/// the precomputed rest of the organ through a condensed stiffness S on the
/// interface vertices, and cut by removing tetrahedra.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "palpate/core/eigen.hpp"

namespace palpate {

namespace detail {
class TetGrid;  // the cut queries' spatial index
                // (lib/runtime/internal/palpate/runtime/region/tet_grid.hpp)
}

/// A cutting tool's blade at one instant: the segment a–b, in the region's
/// rest geometry (m).
struct Blade {
  Eigen::Vector3d a_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_m = Eigen::Vector3d::Zero();
};

/// Whether the segment a–b meets the tetrahedron @p corners (rows: its four
/// vertices, m, positively oriented), touching included to round-off
/// (10⁻¹² relative): Cyrus–Beck clipping of the segment by the four faces'
/// half-spaces. False for non-finite input. The test the model's segment
/// query applies to each candidate; public so that a caller can scan.
bool segment_meets_tetrahedron(const Eigen::Vector3d& a_m, const Eigen::Vector3d& b_m,
                               const Matrix43d& corners_m);
/// Whether the triangle p q r (any orientation, degenerate allowed: a
/// segment or a point) meets the tetrahedron @p corners (rows: its four
/// vertices, m), touching included to round-off (10⁻¹² relative): the
/// separating-axis test of two convex polytopes (Gottschalk, Lin & Manocha,
/// SIGGRAPH 1996): they are disjoint if and only if their projections are
/// disjoint on one of the tetrahedron's 4 face normals, the triangle's
/// normal, or the 18 cross products of a triangle edge with a tetrahedron
/// edge. False for non-finite input.
bool triangle_meets_tetrahedron(const Eigen::Vector3d& p_m, const Eigen::Vector3d& q_m,
                                const Eigen::Vector3d& r_m, const Matrix43d& corners_m);

/// The region's material as the dynamics see it (the elasticity is in the
/// element stiffnesses).
struct TensorMassMaterial {
  double density_kg_m3 = 1060;    ///< ρ > 0 (soft tissue: about 1,060 kg/m³)
  double mass_damping_per_s = 0;  ///< γ ≥ 0 in C = γ M (1/s)
};

/// The largest angular frequency of the undamped region and the time steps
/// it allows (docs/model/tensor-mass.md derives Δt_crit = 2/ω_max, whatever γ).
struct StableTimeStep {
  /// ω_max (rad/s) by power iteration on M^-1/2 (K + S) M^-1/2: a Rayleigh
  /// quotient, so never above the true ω_max; with `converged`, within
  /// `relative_residual` of an eigenvalue (relative).
  double omega_max_rad_s = 0;
  double critical_time_step_s = 0;  ///< 2 / omega_max_rad_s: the bound itself
  /// Gershgorin's bound on ω_max (max over rows of Σ|(K + S)_row| / m):
  /// never below the true ω_max, so its step is safe without a margin.
  double gershgorin_omega_rad_s = 0;
  double gershgorin_time_step_s = 0;  ///< 2 / gershgorin_omega_rad_s
  /// The element bound: the largest λ_max(K^t) / (ρ V_t / 4) over the
  /// tetrahedra as built (each element alone with its lumped masses), plus
  /// λ_max(S) over the least interface mass now. Never below the true ω_max;
  /// without a coupling it stays a bound after any cut.
  double element_omega_rad_s = 0;
  double element_time_step_s = 0;  ///< 2 / element_omega_rad_s
  int iterations = 0;              ///< power iterations done
  double relative_residual = 0;    ///< ‖A y − ρ y‖ / ρ at the end
  bool converged = false;          ///< relative_residual ≤ the tolerance asked
};

/// A tetrahedral region as vertex and edge tensors, lumped masses and an
/// explicit integrator. Vertex v owns the displacement DOFs 3v..3v+2 (x, y,
/// z; metres), the order of the assembled K of the same mesh.
///
/// A vertex is *fixed* (held at zero: the attachment), *detached* (no
/// remaining tetrahedron: no mass, no force, held at its last displacement
/// and left out of the step) or *moving*. The per-step functions
/// (`internal_force`, `apply_stiffness`, `add_coupling_force`, `step`,
/// `set_interface_offset`) allocate nothing, nor do a cut
/// (`remove_tetrahedron`) and the cut queries' forms that write into a
/// caller's vector of sufficient capacity.
class TensorMassModel {
 public:
  /// @param rest_positions_m #V × 3, metres, finite
  /// @param tetrahedra #T × 4 indices into the rows of @p rest_positions_m,
  ///        positively oriented (volume > 0); no face in more than two
  /// @param element_stiffness_n_per_m #T element stiffnesses, 12 × 12 in
  ///        vertex-major order (the offline layer's element_stiffness):
  ///        finite and symmetric to round-off (10⁻¹⁰ of the largest entry)
  /// @param fixed_vertices distinct vertex indices held at zero displacement
  /// Vertices no tetrahedron uses are detached from the start.
  /// @throws InputError naming the tetrahedron, vertex or value at fault.
  TensorMassModel(CRef<Eigen::MatrixX3d> rest_positions_m, CRef<Eigen::MatrixX4i> tetrahedra,
                  const std::vector<Matrix12d>& element_stiffness_n_per_m,
                  const TensorMassMaterial& material, const std::vector<int>& fixed_vertices);

  int vertex_count() const { return static_cast<int>(vertex_tensor_.size()); }
  int tetrahedron_count() const { return static_cast<int>(tet_alive_.size()); }  ///< as built
  int remaining_tetrahedra() const { return remaining_tets_; }
  bool is_removed(int tet) const { return !tet_alive_.at(tet); }
  bool is_fixed(int vertex) const { return fixed_.at(vertex) != 0; }
  bool is_detached(int vertex) const { return vertex_tet_count_.at(vertex) == 0; }
  const Eigen::MatrixX3d& rest_positions_m() const { return rest_m_; }
  const Eigen::MatrixX4i& tetrahedra() const { return tets_; }

  /// K_vv (N/m): the sum of the diagonal blocks of the vertex's remaining
  /// tetrahedra; zero for a detached vertex.
  const Eigen::Matrix3d& vertex_tensor(int vertex) const { return vertex_tensor_.at(vertex); }
  /// The remaining edges, (i, j) with i < j, in no particular order.
  std::vector<std::array<int, 2>> edges() const;
  int edge_count() const { return static_cast<int>(live_edges_.size()); }
  /// K_ij (N/m), the block of rows i and columns j (K_ji = K_ijᵀ); false when
  /// no remaining tetrahedron has the edge (i, j), in either order.
  bool edge_tensor(int i, int j, Eigen::Matrix3d& k_ij) const;
  /// Remaining tetrahedra around a vertex, around an edge (0 if no edge).
  int tetrahedra_at_vertex(int vertex) const { return vertex_tet_count_.at(vertex); }
  int tetrahedra_at_edge(int i, int j) const;
  /// Lumped mass m_v = ρ Σ V_t / 4 over the vertex's remaining tetrahedra (kg).
  double mass_kg(int vertex) const { return mass_kg_.at(vertex); }

  /// The boundary: faces of exactly one remaining tetrahedron, oriented
  /// outward ((b − a) × (c − a) points out of the region), in no particular
  /// order. `boundary_version()` increments each time it changes.
  const std::vector<std::array<int, 3>>& boundary_triangles() const { return boundary_; }
  std::uint64_t boundary_version() const { return boundary_version_; }

  /// ku = K u, by one pass over the vertices and one over the edges (N from
  /// m). Sizes 3#V. Without the coupling S.
  void apply_stiffness(CRef<Eigen::VectorXd> u_m, Eigen::Ref<Eigen::VectorXd> ku_n) const;
  /// f = −K u: the elastic force on every vertex (N). Without the coupling.
  void internal_force(CRef<Eigen::VectorXd> u_m, Eigen::Ref<Eigen::VectorXd> f_n) const;

  /// The rest of the organ condensed on the interface Γ: a symmetric
  /// positive semi-definite stiffness S (3n_Γ × 3n_Γ, N/m; DOF 3k+a is axis a
  /// of interface_vertices[k]) adding −S (u_Γ − u_Γ⁰) to the force. Replaces
  /// any previous coupling; the offset u_Γ⁰ starts at zero.
  /// @throws InputError for a vertex out of range, repeated or fixed, a size
  ///         that does not match, a non-finite, non-symmetric or indefinite S.
  void set_interface_coupling(const std::vector<int>& interface_vertices,
                              CRef<Eigen::MatrixXd> stiffness_n_per_m);
  /// u_Γ⁰ (m, 3n_Γ): where the interface would be under the rest of the
  /// organ's own loads alone (u_Γ⁰ = G_ΓS f_S). Set it every step.
  void set_interface_offset(CRef<Eigen::VectorXd> offset_m);
  const std::vector<int>& interface_vertices() const { return interface_; }
  /// f += −S (u_Γ − u_Γ⁰) on the interface vertices (nothing without a coupling).
  /// Not const: it uses the model's scratch vectors.
  void add_coupling_force(CRef<Eigen::VectorXd> u_m, Eigen::Ref<Eigen::VectorXd> f_n);

  /// One explicit step of M ü + γ M u̇ + K u = f_ext (+ the coupling), centred
  /// differences, per moving vertex:
  ///   (1/Δt² + γ/(2Δt)) m u⁺ = f_ext − K u − S(u_Γ − u_Γ⁰) + (2/Δt²) m u
  ///                            − (1/Δt² − γ/(2Δt)) m u⁻
  /// @param external_force_n 3#V (N); ignored on fixed and detached vertices.
  /// Stable for Δt < 2/ω_max (stable_time_step()).
  void step(double time_step_s, CRef<Eigen::VectorXd> external_force_n);
  const Eigen::VectorXd& displacement_m() const { return u_; }                    ///< u at t
  const Eigen::VectorXd& previous_displacement_m() const { return u_previous_; }  ///< at t − Δt
  /// Sets u at t and t − Δt (zero velocity when equal); fixed vertices are
  /// held at zero whatever is given.
  void set_state(CRef<Eigen::VectorXd> u_m, CRef<Eigen::VectorXd> u_previous_m);

  /// ω_max of M⁻¹ (K + S) on the moving DOFs by power iteration from a fixed
  /// start, stopped when ‖A y − ρ y‖ ≤ @p tolerance · ρ or after
  /// @p max_iterations; and Gershgorin's bound. Allocates; call it after a
  /// cut too (a cut can raise ω_max: docs/model/tensor-mass.md). When nothing moves
  /// (every tetrahedron cut, say) the ω are 0 and the steps infinite.
  StableTimeStep stable_time_step(double tolerance = 1e-6, int max_iterations = 100000) const;

  /// Cuts tetrahedron @p tet out: re-sums its 4 vertex and 6 edge tensors and
  /// the 4 masses from the remaining tetrahedra, drops the edges none uses,
  /// detaches vertices left without one, updates the boundary. Allocates
  /// nothing.
  /// @throws InputError (no change) if @p tet is out of range or already removed.
  void remove_tetrahedron(int tet);

  /// The remaining tetrahedra that the segment a–b (rest geometry, metres)
  /// meets, boundary contact included, in increasing index
  /// (segment_meets_tetrahedron on the candidates of the spatial index: the
  /// same answer as a scan of every tetrahedron). Nothing for non-finite
  /// input.
  std::vector<int> tetrahedra_crossed_by_segment(const Eigen::Vector3d& a_m,
                                                 const Eigen::Vector3d& b_m) const;
  /// The same into @p out (cleared first): allocates nothing when
  /// out.capacity() is at least the count (tetrahedron_count() always is).
  void tetrahedra_crossed_by_segment(const Eigen::Vector3d& a_m, const Eigen::Vector3d& b_m,
                                     std::vector<int>& out) const;

  /// The remaining tetrahedra that the triangle p q r (rest geometry, m)
  /// meets, touching included, in increasing index
  /// (triangle_meets_tetrahedron on the index's candidates). Nothing for
  /// non-finite input. The second form writes into @p out (cleared first)
  /// and allocates nothing when its capacity suffices.
  std::vector<int> tetrahedra_met_by_triangle(const Eigen::Vector3d& p_m,
                                              const Eigen::Vector3d& q_m,
                                              const Eigen::Vector3d& r_m) const;
  void tetrahedra_met_by_triangle(const Eigen::Vector3d& p_m, const Eigen::Vector3d& q_m,
                                  const Eigen::Vector3d& r_m, std::vector<int>& out) const;

  /// The remaining tetrahedra that a blade meets while it moves from
  /// @p before to @p after during one tick: those met by the quadrilateral
  /// (before.a, before.b, after.b, after.a) as the two triangles
  /// (before.a, before.b, after.b) and (before.a, after.b, after.a), in
  /// increasing index, each once (a planar quadrilateral exactly; a twisted
  /// one by these two triangles rather than the bilinear surface a blade
  /// moving linearly sweeps). A blade that did not move gives its segment's
  /// tetrahedra. Nothing for non-finite input. The second form writes into
  /// @p out (cleared first) and allocates nothing when out.capacity() ≥ the
  /// count (reserve tetrahedron_count() once: the haptic tick's form).
  /// Not to be called on one model from two threads at once (a
  /// per-tetrahedron stamp in the model dedupes the candidates).
  std::vector<int> tetrahedra_swept_by_blade(const Blade& before, const Blade& after) const;
  void tetrahedra_swept_by_blade(const Blade& before, const Blade& after,
                                 std::vector<int>& out) const;
  /// One tick's cut: removes every tetrahedron tetrahedra_swept_by_blade
  /// returns (remove_tetrahedron on each) and leaves them in @p removed
  /// (increasing index); returns their count. Allocates nothing when
  /// removed.capacity() ≥ the count.
  int cut_swept_blade(const Blade& before, const Blade& after, std::vector<int>& removed);

  /// The face-connected components of the remaining tetrahedra (two
  /// remaining tetrahedra are connected when they share a face): 0 when
  /// none remains. Allocates (not for the tick). Parts meeting only at an
  /// edge or a vertex count as two here, though the shared vertex still
  /// carries force between them.
  int connected_parts() const;
  /// Per tetrahedron as built: its part, 0 .. connected_parts() − 1,
  /// numbered in the order of each part's least tetrahedron; −1 if removed.
  std::vector<int> part_labels() const;

 private:
  struct LiveEdge {
    int i = 0, j = 0;  // i < j
    Eigen::Matrix3d k_ij = Eigen::Matrix3d::Zero();
  };
  void add_stiffness_product(CRef<Eigen::VectorXd> u, Eigen::Ref<Eigen::VectorXd> out,
                             double sign) const;
  void build_topology();  // tensor_mass_cut.cpp, with what a cut changes
  void resum_vertex(int v);
  void resum_edge(int edge);
  int find_edge(int i, int j) const;
  void add_boundary_face(int face, int tet);
  void drop_boundary_face(int face);
  Matrix43d rest_corners(int tet) const;
  // The remaining tetrahedra of the index's cells in the box [lo, hi] that
  // cell_meets (centre, half side) keeps, for which tet_meets (corners) is
  // true: each tested once, into out, sorted (tensor_mass_query.cpp).
  template <class CellTest, class TetTest>
  void collect(const Eigen::Vector3d& lo_m, const Eigen::Vector3d& hi_m, CellTest cell_meets,
               TetTest tet_meets, std::vector<int>& out) const;

  Eigen::MatrixX3d rest_m_;
  Eigen::MatrixX4i tets_;
  std::vector<Matrix12d> element_k_;
  std::vector<double> tet_volume_m3_;
  std::vector<char> tet_alive_;
  int remaining_tets_ = 0;
  double density_kg_m3_ = 0, damping_per_s_ = 0;
  double element_omega2_max_ = 0;  // max over the tetrahedra as built (1/s²)
  double coupling_eigen_max_ = 0;  // λ_max(S), N/m

  std::vector<char> fixed_;
  std::vector<Eigen::Matrix3d> vertex_tensor_;
  std::vector<double> mass_kg_;
  std::vector<int> vertex_tet_count_;
  std::vector<int> vertex_tets_begin_, vertex_tets_;  // CSR vertex → tetrahedra

  std::vector<std::array<int, 2>> edge_vertices_;  // by edge id, sorted (i < j)
  std::vector<std::array<int, 6>> tet_edges_;
  std::vector<int> edge_tets_begin_, edge_tets_;  // CSR edge → tetrahedra
  std::vector<int> edge_tet_count_;
  std::vector<LiveEdge> live_edges_;  // what the force pass reads, compact
  std::vector<int> live_edge_id_, edge_slot_;

  std::vector<std::array<int, 2>> face_tets_;  // by face id; second −1 on the hull
  std::vector<std::array<int, 4>> tet_faces_;  // face opposite local vertex k
  std::vector<std::array<int, 3>> boundary_;   // reserved for every face: no reallocation
  std::vector<int> boundary_face_id_, face_slot_;
  std::uint64_t boundary_version_ = 0;

  std::vector<int> interface_;
  Eigen::MatrixXd coupling_;
  Eigen::VectorXd offset_m_;
  Eigen::VectorXd gap_m_, coupling_force_n_;  // scratch of add_coupling_force

  Eigen::VectorXd u_, u_previous_, force_;

  // The cut queries' index: immutable once built, so copies share it.
  std::shared_ptr<const detail::TetGrid> grid_;
  mutable std::vector<std::uint32_t> tet_stamp_;  // == stamp_: already tested by this query
  mutable std::uint32_t stamp_ = 0;
};

}  // namespace palpate
