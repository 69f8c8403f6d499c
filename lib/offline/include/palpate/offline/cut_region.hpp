#pragma once
/// @file
/// The hybrid model's offline building block (issue 20): a cuttable region
/// of the organ, simulated at run time by a tensor-mass model, and the
/// precomputed compliance of the rest of the organ (the "outside") on its
/// boundary, the interface Γ with the region and its part of the organ's
/// surface (docs/model/hybrid-region.md, "The hybrid model: a cuttable region and the
/// precomputed rest"; S. Cotin, H. Delingette & N. Ayache, "A hybrid elastic
/// model for real-time cutting, deformations and force feedback for surgery
/// training and simulation", The Visual Computer 16(8), 2000).

#include <string>
#include <vector>

#include "palpate/core/eigen.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh.hpp"

namespace palpate {

/// Where the cuttable region is. A tetrahedron belongs to the region when its
/// centroid is inside the box or the ball (boundaries included), or when its
/// 3-D physical group is the named one. The centroid rule puts every
/// tetrahedron on exactly one side whatever the shape's size against the
/// mesh's; a vertex rule (all four vertices inside) would leave regions
/// smaller than an element empty and make the side of a tetrahedron cut by
/// the shape depend on a choice of "all" or "any".
struct RegionSpec {
  enum class Kind { box, sphere, group };
  Kind kind = Kind::box;
  Eigen::Vector3d min_m = Eigen::Vector3d::Zero();     ///< box: lower corner, metres
  Eigen::Vector3d max_m = Eigen::Vector3d::Zero();     ///< box: upper corner, metres
  Eigen::Vector3d center_m = Eigen::Vector3d::Zero();  ///< sphere: centre, metres
  double radius_m = 0;                                 ///< sphere: radius, metres
  std::string group;  ///< group: a 3-D physical group name of the mesh (or "#tag")

  static RegionSpec box(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m);
  static RegionSpec sphere(const Eigen::Vector3d& center_m, double radius_m);
  static RegionSpec physical_group(const std::string& name);
  /// "box (x, y, z) to (x, y, z) m", "sphere at (x, y, z) m of radius r m",
  /// "physical group 'name'": how messages name the region.
  std::string describe() const;
};

/// Regions with more tetrahedra than this take over half of a 1 ms haptic
/// tick as a tensor-mass model on one core (docs/benchmarks-history.md, "The tensor-mass
/// region: one explicit step": a coupled step costs about 11 ns per tetrahedron, and a 4 mm
/// liver mesh needs about 10 steps per millisecond, so 4,000 tetrahedra are
/// about 0.45 ms; 8,000 took the whole tick): split_region() warns, it does
/// not refuse.
inline constexpr int kRegionTetrahedraAt1kHz = 4'000;
/// Free interface vertices beyond which the coupling force S (u_Γ − u_Γ⁰), a
/// dense 3n_Γ × 3n_Γ product (9 n_Γ² multiply-adds), takes a large part of a
/// 1 ms step: split_region() warns.
inline constexpr int kInterfaceVerticesAt1kHz = 300;
/// A region holding more than this fraction of the organ's tetrahedra is
/// warned about: the precomputed part is then the small one.
inline constexpr double kRegionFractionWarning = 0.2;

/// A mesh split into the cuttable region and the outside (the rest).
/// Vertex lists are sorted and in the mesh's numbering unless said otherwise.
struct RegionSplit {
  std::vector<int> region_tets;   ///< mesh tetrahedra of the region, increasing
  std::vector<int> outside_tets;  ///< mesh tetrahedra of the outside, increasing
  /// The outside as a mesh of its own: its vertices are the mesh vertices its
  /// tetrahedra use, in increasing mesh order; tetrahedron i is
  /// outside_tets[i], with its group kept.
  TetMesh outside;
  std::vector<int> outside_to_mesh;  ///< outside vertex → mesh vertex
  std::vector<int> mesh_to_outside;  ///< #V: mesh vertex → outside vertex, or −1
  /// Γ: the vertices used by both a region and an outside tetrahedron
  /// (fixed ones included).
  std::vector<int> interface_vertices;
  std::vector<int> region_vertices;    ///< vertices used by a region tetrahedron
  std::vector<int> fixed_outside;      ///< fixed vertices an outside tetrahedron uses
  std::vector<int> fixed_region;       ///< fixed vertices a region tetrahedron uses
  std::vector<bool> on_organ_surface;  ///< #V: on the whole mesh's boundary
  /// Plausible but suspicious choices (a region too large to step at 1 kHz,
  /// too many interface vertices): the caller prints them, `-q` or not.
  std::vector<std::string> warnings;
};

/// Splits a checked mesh (validate_and_compact()) into the region @p spec
/// selects and the rest.
/// @param fixed_vertices the attachment's vertices (select_fixed_vertices()), sorted
/// @throws InputError (what, where, what is accepted) for: a box with
///   min > max or a non-finite corner, a sphere whose radius is not > 0; a
///   region that holds no tetrahedron (with the mesh's extent) or every
///   tetrahedron; an unknown group (with the mesh's 3-D groups); an outside
///   that holds no fixed vertex (its stiffness would be singular), or a part
///   of it that holds none or cannot be stopped by the ones it holds; a
///   region that shares no vertex with the rest, or a part of it that
///   touches neither the rest nor the attachment.
RegionSplit split_region(const TetMesh& mesh, const RegionSpec& spec,
                         const std::vector<int>& fixed_vertices);

/// The outside's boundary, in the outside's numbering: the faces of exactly
/// one outside tetrahedron (outward), and the vertices the outside's
/// compliance is computed on, which are those faces' vertices and Γ (a Γ
/// vertex can touch the region along an edge only, on no shared face).
/// Unlike extract_boundary(), it accepts a boundary that touches itself
/// along an edge, as a region chosen by centroids can leave.
Boundary outside_boundary(const RegionSplit& split);

/// The outside's compliance on its boundary, which is Γ and its part of the
/// organ's surface.
struct OutsideCompliance {
  /// m × m, m/N, m = 3 vertices.size(): G(3a+i, 3b+j) is the displacement of
  /// vertices[a] along axis i per newton on vertices[b] along axis j, the
  /// outside alone, held at its fixed vertices, its interior force-free.
  Eigen::MatrixXd G;
  /// G's vertex order: the free vertices of the outside's boundary, in
  /// increasing mesh index (mesh numbering).
  std::vector<int> vertices;
  /// Positions in `vertices` of the free interface vertices Γ, increasing.
  std::vector<int> interface;
  /// Positions in `vertices` of the organ-surface vertices that are not on Γ
  /// (the surface S a tool can touch on the outside), increasing.
  std::vector<int> surface;
  /// G_ΓΓ: 3n_Γ × 3n_Γ, m/N, in the order of `interface`.
  Eigen::MatrixXd interface_compliance;
  /// S = G_ΓΓ⁻¹: 3n_Γ × 3n_Γ, N/m, symmetric positive definite: the stiffness
  /// the outside opposes to a displacement of Γ (its Schur complement onto Γ).
  Eigen::MatrixXd coupling_stiffness;
  ComplianceStats stats;
};

enum class OutsideMethod { solves, condensation };

/// Assembles the outside's stiffness (the attachment's vertices held) and
/// computes its compliance on its boundary by @p method (compliance.hpp),
/// then G_ΓΓ and S = G_ΓΓ⁻¹.
/// @param material_of_tet #T (whole mesh) indices into @p materials
/// @throws NotPositiveDefinite if the outside's K is not positive definite;
///   NumericalError if G_ΓΓ is not (naming the interface vertex).
OutsideCompliance outside_compliance(const RegionSplit& split,
                                     CRef<Eigen::VectorXi> material_of_tet,
                                     const std::vector<Lame>& materials, OutsideMethod method,
                                     const ComplianceOptions& options = {});

/// The 3|rows| × 3|cols| block of a vertex-blocked matrix @p G (3n × 3n) at
/// the vertex positions @p rows and @p cols (e.g. OutsideCompliance's
/// `surface` and `interface`: G_SΓ).
Eigen::MatrixXd vertex_block(CRef<Eigen::MatrixXd> G, const std::vector<int>& rows,
                             const std::vector<int>& cols);

/// What the run-time tensor-mass model of the region needs, in the region's
/// own compact vertex numbering.
struct RegionModel {
  Eigen::MatrixX3d vertices_m;  ///< #R × 3 rest positions, metres
  Eigen::MatrixX4i tetrahedra;  ///< #T_R × 4, region numbering, positively oriented
  std::vector<int> to_mesh;     ///< #R: region vertex → mesh vertex (increasing)
  std::vector<int> mesh_tets;   ///< #T_R: region tetrahedron → mesh tetrahedron
  /// #T_R element stiffnesses (fem.hpp, element_stiffness), N/m, 12 × 12.
  std::vector<Matrix12d> element_stiffness;
  /// Faces of exactly one region tetrahedron, outward from the region,
  /// region numbering: the organ's surface in the region and the faces on Γ.
  Eigen::MatrixX3i boundary_triangles;
  /// Region vertices on Γ that are free, in the order of
  /// OutsideCompliance::interface (increasing mesh index): interface[i]
  /// owns rows 3i..3i+2 of S.
  std::vector<int> interface;
  std::vector<int> fixed;  ///< region vertices held by the attachment, increasing
};

/// The region's rest geometry, elements and boundary for the tensor-mass model.
/// @param material_of_tet #T (whole mesh) indices into @p materials
RegionModel region_model(const TetMesh& mesh, const RegionSplit& split,
                         CRef<Eigen::VectorXi> material_of_tet, const std::vector<Lame>& materials);

}  // namespace palpate
