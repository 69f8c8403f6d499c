#include "palpate/runtime/tool_contact.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <span>

#include "active_set.hpp"
#include "contact_geometry.hpp"
#include "jaw_grasp.hpp"
#include "local_model.hpp"
#include "palpate/core/error.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "vertex_grid.hpp"
#include "warped_rotations.hpp"

namespace palpate {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

/// Closest point to @p x on the segment [a, a + length·axis] (axis unit).
Vector3d closest_on_segment(const Vector3d& a, const Vector3d& axis, double length,
                            const Vector3d& x) {
  const double t = std::clamp((x - a).dot(axis), 0.0, length);
  return a + t * axis;
}

/// A tip contact found this tick: the deepest point of a surface triangle
/// inside the tip, on the triangle's vertices that carry a weight.
struct TipCandidate {
  int triangle;                 // drawn triangle it was found on
  int count;                    // vertices with a non-zero weight, 1 to 3
  std::array<int, 3> vertices;  // drawn vertices
  std::array<double, 3> weights;
  double depth;     // r − distance to the tip's axis, m (negative: within the hysteresis shell)
  Vector3d normal;  // unit: the direction the tip pushes the tissue (from the axis to the point)
  Vector3d target;  // the point put back on the tip's surface, m
  Vector3d rest;    // the point at rest, Σ w_i rest_i, m
  bool active;      // penetrating (or within the hysteresis shell); else a near
                    // triangle the solve may push into the tip
};

using detail::HeldPoint;

}  // namespace

struct ToolContactEngine::Impl {
  const SurfaceModel& model;
  // Warped compliance (docs/model.md, "Large rotations: warped compliance"):
  // null for the linear model.
  const RotationField* warping = nullptr;
  ContactSettings settings;
  SolverLimits limits;
  detail::ActiveSet active_set;
  int per_tool_cap = 0;

  struct Tool {
    ToolGeometry geometry;
    bool alive = false;  // a pose was taken and the watchdog has not ramped it out
    ToolPoseInput pose;
    Matrix3d rotation = Matrix3d::Identity();
    double last_pose_s = 0;
    bool has_sequence = false;
    double previous_jaw = 0;
    bool has_previous_jaw = false;
    // The widest the jaws opened since they last held anything: the faces'
    // position when they came around the tissue (line jaws closing slowly
    // pass into it; real ones stop on its surface).
    double widest_jaw = 0;
    double scale = 1;  // watchdog ramp, 1 → 0
    bool in_watchdog = false;
    std::vector<HeldPoint> held;     // by the jaws, in the tool frame
    std::vector<TipCandidate> tips;  // this tick's tip contacts, deepest first
    int tip_count = 0;
    Vector3d raw_force = Vector3d::Zero(), raw_torque = Vector3d::Zero();
    double raw_grip = 0;
    int contacts = 0;
    ToolOutput out;
    bool has_output = false;
    double last_output_s = 0;
    ToolState shown_state = ToolState::kFree;
  };
  std::vector<Tool> tools;

  // The drawn surface: compliance vertices first, then the fixed ones.
  int compliance_count = 0;
  std::vector<Vector3d> rest;           // per drawn vertex
  std::vector<Vector3d> vertex_normal;  // per compliance vertex, outward, area weighted
  std::vector<int> triangle_vertices;   // 3 per triangle
  std::vector<int> vertex_triangles_begin, vertex_triangles;  // triangles around each vertex
  std::vector<int> owner;  // per compliance vertex: tool holding it this tick, or -1
  std::vector<int> previous_triangle_owner;  // per triangle: tool whose tip touched it last tick
  std::vector<Vector3d> triangle_centre;     // per triangle: centre of its corners at rest, m
  std::vector<double> triangle_radius;       // per triangle: farthest corner from it, m
  std::vector<double> triangle_softness;  // per triangle: max √‖G^{vv}‖_F over its corners, √(m/N)
  double max_softness = 0;                // over the triangles
  std::vector<std::uint32_t> triangle_seen;  // per triangle: the last find_tips that met it
  std::uint32_t triangle_epoch = 0;
  std::vector<std::uint32_t> position_seen;  // per drawn vertex: the epoch of `position`
  std::uint32_t epoch = 0;
  std::vector<Vector3d> position;  // per drawn vertex: deformed, valid when position_seen == epoch
  // Warped: û and ω of the compliance vertices met this tick.
  std::optional<detail::WarpedRotations> rotations;
  Vector3d box_min, box_max;
  detail::VertexGrid grid;  // the drawn vertices at rest, by cell

  // Scratch, sized once.
  std::vector<int> candidates;           // drawn vertices near a tool, ascending
  std::vector<std::uint64_t> near_bits;  // per drawn vertex: near the tool (gather_candidates)
  std::vector<TipCandidate> found;
  struct Ranked {
    double depth;
    int index;  // into found
  };
  std::vector<Ranked> ranked;  // found's depths, to sort
  detail::JawGrasp grasp;
  std::vector<int> near_triangles;         // around the candidates, distinct
  std::vector<int> grasp_triangles;        // near the closing jaws
  std::vector<Vector3d> grasp_corners;     // 3 per grasp triangle, deformed
  std::vector<HeldPoint> touched;          // the tip's points at the last tick
  std::vector<std::uint64_t> wanted_bits;  // per compliance vertex: its position is wanted
  std::vector<int> wanted;                 // the wanted ones, ascending
  std::vector<Vector3d> wanted_u;          // their displacements

  // The last successful solve: every tool's contact points and their loads.
  int count = 0;
  std::vector<ContactPoint> points;
  std::vector<int> tip_of;  // per point: index into its tool's tips, or -1 for a held point
  int load_count = 0;
  std::vector<int> load_index;     // compliance vertex per load
  std::vector<int> load_tool;      // tool per load
  std::vector<double> load_force;  // 3 per load, N
  std::vector<int> load_slot;      // per compliance vertex: its load this tool, or -1
  double max_displacement = 0;     // over the points, m
  // fᵀ G f of the loads, J (f_Cᵀ u_C over the points, material): with
  // ‖G^{vv}‖, it bounds every vertex's displacement (far_from_tip).
  double load_energy = 0;
  char message[256] = {};
  mutable char problem[256] = {};  // why check() refused the last pose it refused

  /// Writes the reason for a refused pose into `problem` (cut to fit).
  template <typename... Args>
  void explain(fmt::format_string<Args...> format, Args&&... args) const {
    const auto written =
        fmt::format_to_n(problem, sizeof problem - 1, format, std::forward<Args>(args)...);
    *written.out = '\0';
  }

  // The constraint set being built: a held point (tip -1) or a tip point.
  int building = 0;
  std::vector<int> b_tool, b_tip, b_held;
  std::vector<detail::ActiveRow> rows;  // the active set's rows, one per built constraint
  // Warped: per row, R̃ of its point and its normal in the world; per point
  // of the last solve, its force in the material frame (the loads' frame).
  std::vector<Matrix3d> row_rotation;
  std::vector<Vector3d> row_world_normal, material_force;
  // Per row, what the local model needs beyond the active set's row; the
  // active set holds the factor of the stored solution when `factored`
  // (the last solve succeeded): the local model is read off it.
  std::vector<detail::LocalRow> local_rows;
  detail::LocalModel linearization;
  bool factored = false;

  Impl(const SurfaceModel& m, std::vector<ToolGeometry> geometries, const ContactSettings& s,
       const SolverLimits& l, const RotationField* w)
      : model(m),
        warping(w),
        settings(s),
        limits(l),
        active_set(m, l),
        grasp(std::max(1, l.max_constraints), m.compliance_vertex_count()),
        linearization(std::max(1, l.max_constraints), m.compliance_vertex_count()) {
    const DrawnSurface& surface = m.surface;
    compliance_count = m.compliance_vertex_count();
    const int n = compliance_count;
    const int drawn = surface.vertex_count();
    const int triangles = surface.triangle_count();
    const int t = static_cast<int>(geometries.size());
    PALPATE_DEMAND(t >= 1 && t <= 64);
    per_tool_cap = std::min(settings.max_contacts_per_tool, limits.max_constraints / t);
    PALPATE_DEMAND(per_tool_cap >= 1);
    for (auto& g : geometries) {
      Tool tool;
      tool.geometry = std::move(g);
      tool.held.reserve(static_cast<std::size_t>(per_tool_cap));
      tool.tips.resize(static_cast<std::size_t>(per_tool_cap));
      tools.push_back(std::move(tool));
    }
    rest.resize(static_cast<std::size_t>(drawn));
    position.resize(static_cast<std::size_t>(drawn));
    position_seen.assign(static_cast<std::size_t>(drawn), 0);
    box_min = Vector3d::Constant(std::numeric_limits<double>::infinity());
    box_max = -box_min;
    for (int v = 0; v < drawn; ++v) {
      rest[static_cast<std::size_t>(v)] = surface.rest_position(v);
      box_min = box_min.cwiseMin(rest[static_cast<std::size_t>(v)]);
      box_max = box_max.cwiseMax(rest[static_cast<std::size_t>(v)]);
    }
    // A vertex without a normal (in no triangle of non-zero area) pushes along z.
    vertex_normal.resize(static_cast<std::size_t>(n));
    const Eigen::MatrixX3d surface_normals = vertex_normals(surface);
    for (int v = 0; v < n; ++v)
      vertex_normal[static_cast<std::size_t>(v)] =
          surface_normals.row(v).squaredNorm() > 0 ? Vector3d(surface_normals.row(v).transpose())
                                                   : Vector3d::UnitZ();
    // Triangles around each drawn vertex (compressed rows).
    triangle_vertices.assign(surface.triangles.begin(), surface.triangles.end());
    vertex_triangles_begin.assign(static_cast<std::size_t>(drawn) + 1, 0);
    for (const int v : triangle_vertices) ++vertex_triangles_begin[static_cast<std::size_t>(v) + 1];
    for (int v = 0; v < drawn; ++v)
      vertex_triangles_begin[static_cast<std::size_t>(v) + 1] +=
          vertex_triangles_begin[static_cast<std::size_t>(v)];
    vertex_triangles.resize(triangle_vertices.size());
    std::vector<int> fill(vertex_triangles_begin.begin(), vertex_triangles_begin.end() - 1);
    for (int tri = 0; tri < triangles; ++tri)
      for (int c = 0; c < 3; ++c)
        vertex_triangles[static_cast<std::size_t>(
            fill[static_cast<std::size_t>(triangle_vertices[3 * static_cast<std::size_t>(tri) +
                                                            static_cast<std::size_t>(c)])]++)] =
            tri;
    triangle_seen.assign(static_cast<std::size_t>(triangles), 0);
    previous_triangle_owner.assign(static_cast<std::size_t>(triangles), -1);
    // Each triangle's ball at rest and the largest √‖G^{vv}‖ of its
    // compliance vertices (far_from_tip).
    triangle_centre.resize(static_cast<std::size_t>(triangles));
    triangle_radius.resize(static_cast<std::size_t>(triangles));
    triangle_softness.assign(static_cast<std::size_t>(triangles), 0.0);
    for (int tri = 0; tri < triangles; ++tri) {
      const auto tt = static_cast<std::size_t>(tri);
      const int* corner = &triangle_vertices[3 * tt];
      Vector3d centre = Vector3d::Zero();
      for (int i = 0; i < 3; ++i) centre += rest[static_cast<std::size_t>(corner[i])] / 3;
      double radius2 = 0;
      for (int i = 0; i < 3; ++i) {
        radius2 =
            std::max(radius2, (rest[static_cast<std::size_t>(corner[i])] - centre).squaredNorm());
        if (corner[i] < n)
          triangle_softness[tt] =
              std::max(triangle_softness[tt], std::sqrt(m.G_block(corner[i], corner[i]).norm()));
      }
      triangle_centre[tt] = centre;
      triangle_radius[tt] = std::sqrt(radius2);
      max_softness = std::max(max_softness, triangle_softness[tt]);
    }
    owner.assign(static_cast<std::size_t>(n), -1);
    candidates.resize(static_cast<std::size_t>(drawn));
    near_bits.assign((static_cast<std::size_t>(drawn) + 63) / 64, 0);
    double edges_m = 0;
    for (int tri = 0; tri < triangles; ++tri)
      for (int c = 0; c < 3; ++c)
        edges_m +=
            (rest[static_cast<std::size_t>(triangle_vertices[3 * static_cast<std::size_t>(tri) +
                                                             static_cast<std::size_t>(c)])] -
             rest[static_cast<std::size_t>(
                 triangle_vertices[3 * static_cast<std::size_t>(tri) +
                                   static_cast<std::size_t>((c + 1) % 3)])])
                .norm();
    grid = detail::VertexGrid(rest, triangles > 0 ? 1.5 * edges_m / (3.0 * triangles) : 0.0);
    found.resize(static_cast<std::size_t>(triangles));
    ranked.resize(static_cast<std::size_t>(triangles));
    grasp_triangles.resize(static_cast<std::size_t>(triangles));
    near_triangles.resize(static_cast<std::size_t>(triangles));
    grasp_corners.resize(3 * static_cast<std::size_t>(triangles));
    wanted_bits.assign((static_cast<std::size_t>(n) + 63) / 64, 0);
    wanted.resize(static_cast<std::size_t>(n));
    wanted_u.resize(static_cast<std::size_t>(n));
    const auto k = static_cast<std::size_t>(limits.max_constraints);
    touched.reserve(k);
    points.resize(k);
    tip_of.resize(k);
    load_index.resize(3 * k);
    load_tool.resize(3 * k);
    load_force.resize(9 * k);
    load_slot.assign(static_cast<std::size_t>(n), -1);
    b_tool.resize(k);
    b_tip.resize(k);
    b_held.resize(k);
    rows.resize(k);
    row_rotation.assign(k, Matrix3d::Identity());
    row_world_normal.assign(k, Vector3d::Zero());
    material_force.assign(k, Vector3d::Zero());
    local_rows.resize(k);
    if (warping != nullptr) {
      PALPATE_DEMAND(warping->vertex_count() == n);
      rotations.emplace(*warping, n);
    }
  }

  /// Forgets the deformed positions (the loads changed).
  void next_epoch() {
    if (++epoch == 0) {
      std::fill(position_seen.begin(), position_seen.end(), 0);
      epoch = 1;
    }
    if (rotations) rotations->next_epoch();
  }

  /// u_v = Σ_l G^{v l} f_l under the last solve's loads: the displacement of
  /// compliance vertex @p v (the material one, û, when warped).
  Vector3d load_displacement(int v) const {
    Vector3d u = Vector3d::Zero();
    for (int l = 0; l < load_count; ++l)
      u.noalias() += model.G_block(v, load_index[static_cast<std::size_t>(l)]) *
                     Eigen::Map<const Vector3d>(&load_force[3 * static_cast<std::size_t>(l)]);
    return u;
  }

  /// Warped: ω of compliance vertex @p v under the last solve's loads.
  const Vector3d& rotation_vector(int v) {
    return rotations->rotation(v, [this](int j) { return load_displacement(j); });
  }
  /// Warped: R̃ of a point on @p count drawn vertices with @p weights, from the
  /// weighted mean of their ω (a fixed vertex does not rotate).
  template <typename Point>
  Matrix3d point_rotation(const Point& point) {
    Vector3d w = Vector3d::Zero();
    for (int i = 0; i < point.count; ++i) {
      const int v = point.vertices[static_cast<std::size_t>(i)];
      if (v < compliance_count)
        w += point.weights[static_cast<std::size_t>(i)] * rotation_vector(v);
    }
    return integrated_rotation(w);
  }

  /// Deformed position of drawn vertex @p v under the last solve's loads
  /// (a fixed vertex stays at rest): p + u, or p + R̃(ω) û when warped;
  /// computed once per epoch.
  const Vector3d& deformed(int v) {
    const auto vv = static_cast<std::size_t>(v);
    if (position_seen[vv] == epoch) return position[vv];
    position_seen[vv] = epoch;
    if (v >= compliance_count)
      position[vv] = rest[vv];
    else if (warping == nullptr)
      position[vv] = rest[vv] + load_displacement(v);
    else
      position[vv] =
          rest[vv] + integrated_rotation(rotation_vector(v)) *
                         rotations->material(v, [this](int j) { return load_displacement(j); });
    return position[vv];
  }

  /// The deformed positions of the corners of @p triangles not computed in
  /// this epoch, as deformed() computes them (the same sums in the same
  /// order, so the same numbers), but load by load: G^{v l} for one load l
  /// and every vertex v lies in G's three columns of l, read downwards with
  /// the vertices in ascending order, where deformed() alone reads three
  /// columns per vertex and load. A wide tip meets hundreds of vertices
  /// under tens of loads (BENCHMARKS.md, "The wide tick"). Linear model
  /// only: the warped one goes through its rotation memo, vertex by vertex.
  void deform_corners(std::span<const int> triangles) {
    if (warping != nullptr) return;
    int wanted_count = 0;
    for (const int tri : triangles)
      for (int i = 0; i < 3; ++i) {
        const int v =
            triangle_vertices[3 * static_cast<std::size_t>(tri) + static_cast<std::size_t>(i)];
        if (v >= compliance_count || position_seen[static_cast<std::size_t>(v)] == epoch) continue;
        std::uint64_t& word = wanted_bits[static_cast<std::size_t>(v) / 64];
        const std::uint64_t bit = std::uint64_t{1} << (v % 64);
        if ((word & bit) == 0) ++wanted_count;
        word |= bit;
      }
    if (wanted_count == 0) return;
    int k = 0;
    for (std::size_t w = 0; w < wanted_bits.size(); ++w) {
      for (std::uint64_t word = wanted_bits[w]; word != 0; word &= word - 1)
        wanted[static_cast<std::size_t>(k++)] = static_cast<int>(64 * w) + std::countr_zero(word);
      wanted_bits[w] = 0;
    }
    const auto wanted_n = static_cast<std::size_t>(k);
    for (std::size_t j = 0; j < wanted_n; ++j) wanted_u[j].setZero();
    for (int l = 0; l < load_count; ++l) {
      const int a = load_index[static_cast<std::size_t>(l)];
      const Vector3d f = Eigen::Map<const Vector3d>(&load_force[3 * static_cast<std::size_t>(l)]);
      if (model.float32()) {
        for (std::size_t j = 0; j < wanted_n; ++j)
          wanted_u[j].noalias() += model.G_block(wanted[j], a) * f;
        continue;
      }
      // G's three columns of load a, from its row 0.
      const Eigen::Index ld = model.G.rows();
      const double* columns = model.G.data() + 3 * a * ld;
      Vector3d* u = wanted_u.data();
      const int* v = wanted.data();
      for (std::size_t j = 0; j < wanted_n; ++j)
        u[j].noalias() += Eigen::Map<const Matrix3d, 0, Eigen::OuterStride<>>(
                              columns + 3 * v[j], 3, 3, Eigen::OuterStride<>(ld)) *
                          f;
    }
    for (std::size_t j = 0; j < wanted_n; ++j) {
      const auto v = static_cast<std::size_t>(wanted[j]);
      position[v] = rest[v] + wanted_u[j];
      position_seen[v] = epoch;
    }
  }

  /// True when no point of triangle @p tri, deformed under the loads, can
  /// come within @p reach of @p tool's axis, known from the triangle at rest
  /// without its deformed corners. A vertex's displacement is bounded by
  /// the loads' energy: for a unit e, eᵀ u_v = eᵀ G_{v·} f ≤
  /// √(eᵀ G^{vv} e) √(fᵀ G f) (Cauchy–Schwarz in the inner product of G,
  /// symmetric positive definite), so |u_v| ≤ √(‖G^{vv}‖ fᵀ G f), and a
  /// point of the triangle moves no farther than its corners' largest
  /// bound. The margins (1e-6 relative, and 1e-6 of the reach) are far
  /// above round-off and G's asymmetry (1e-15): nothing the closest points
  /// would find near is dropped. Linear model only (the warped one meets
  /// its vertices' rotations in the order deformed() asks for them).
  /// (@p spread: (1 + 1e-6) √(fᵀ G f), the same for every triangle of a tick.)
  bool far_from_tip(const Tool& tool, int tri, double reach, double spread) const {
    if (warping != nullptr) return false;
    const auto tt = static_cast<std::size_t>(tri);
    const Vector3d& c = triangle_centre[tt];
    const double beyond = (1 + 1e-6) * reach + triangle_radius[tt] + triangle_softness[tt] * spread;
    return (c - closest_on_segment(tool.pose.position_m, tool.rotation.col(2),
                                   tip_length(tool.geometry), c))
               .squaredNorm() >= beyond * beyond;
  }

  /// Longest reach of a tool from its hinge along z, and its radius of interest.
  static double reach_length(const ToolGeometry& g) {
    return std::max(g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0, g.jaw_length_m);
  }
  double tip_length(const ToolGeometry& g) const {
    return g.tip == TipShape::kCapsule ? g.tip_length_m : 0.0;
  }

  /// How far from a tool's segment its candidate vertices lie at rest, m.
  double search_radius(const ToolGeometry& g) const {
    const double wedge = g.jaw_length_m * std::tan(0.5 * g.max_jaw_angle_rad);
    return std::max(g.tip_radius_m, wedge + g.tip_radius_m) + settings.search_margin_m +
           max_displacement;
  }

  /// Drawn vertices whose rest position is near tool @p t; returns their count.
  int gather_candidates(const Tool& tool) {
    const ToolGeometry& g = tool.geometry;
    const Vector3d axis = tool.rotation.col(2);
    const double length = reach_length(g);
    const double radius = search_radius(g);
    const double radius2 = radius * radius;
    const auto near = [&](const Vector3d& x) {
      return (x - closest_on_segment(tool.pose.position_m, axis, length, x)).squaredNorm() <=
             radius2;
    };
    int n = 0;
    const int vertices = static_cast<int>(rest.size());
    // The grid's cells that the box around the segment (plus the radius and
    // a margin far above the round-off of the test) overlaps: a vertex
    // outside them is farther than the radius in one coordinate. Their
    // vertices are tested, marked, and taken in the order of the scan of
    // every vertex; a box over half the grid is the scan.
    const Vector3d end = tool.pose.position_m + length * axis;
    const Vector3d reach = Vector3d::Constant(radius * (1 + 1e-6));
    const std::array<int, 3> lo = grid.cell_of(tool.pose.position_m.cwiseMin(end) - reach);
    const std::array<int, 3> hi = grid.cell_of(tool.pose.position_m.cwiseMax(end) + reach);
    const std::int64_t cells =
        std::int64_t{hi[0] - lo[0] + 1} * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
    if (!(2 * cells < grid.cell_count())) {
      for (int j = 0; j < vertices; ++j)
        if (near(rest[static_cast<std::size_t>(j)])) candidates[static_cast<std::size_t>(n++)] = j;
      return n;
    }
    for (int z = lo[2]; z <= hi[2]; ++z)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int x = lo[0]; x <= hi[0]; ++x)
          for (const int j : grid.vertices_in({x, y, z}))
            if (near(rest[static_cast<std::size_t>(j)]))
              near_bits[static_cast<std::size_t>(j) / 64] |= std::uint64_t{1} << (j % 64);
    for (std::size_t w = 0; w < near_bits.size(); ++w) {
      for (std::uint64_t word = near_bits[w]; word != 0; word &= word - 1)
        candidates[static_cast<std::size_t>(n++)] =
            static_cast<int>(64 * w) + std::countr_zero(word);
      near_bits[w] = 0;
    }
    return n;
  }

  /// The distinct surface triangles around the first @p n candidates, into
  /// near_triangles, in the order met; returns their count.
  int gather_triangles(int n) {
    if (++triangle_epoch == 0) {
      std::fill(triangle_seen.begin(), triangle_seen.end(), 0);
      triangle_epoch = 1;
    }
    int count = 0;
    for (int c = 0; c < n; ++c) {
      const int v = candidates[static_cast<std::size_t>(c)];
      for (int e = vertex_triangles_begin[static_cast<std::size_t>(v)];
           e < vertex_triangles_begin[static_cast<std::size_t>(v) + 1]; ++e) {
        const int tri = vertex_triangles[static_cast<std::size_t>(e)];
        if (triangle_seen[static_cast<std::size_t>(tri)] == triangle_epoch) continue;
        triangle_seen[static_cast<std::size_t>(tri)] = triangle_epoch;
        near_triangles[static_cast<std::size_t>(count++)] = tri;
      }
    }
    return count;
  }

  /// Is the deformed point @p x between the jaws of @p tool opened at @p angle?
  static bool between_jaws(const Tool& tool, const Vector3d& x, double angle) {
    return detail::JawGrasp::between(jaws_of(tool, angle), x, angle);
  }
  static detail::JawsAtClosing jaws_of(const Tool& tool, double opening) {
    return {tool.pose.position_m, tool.rotation, &tool.geometry, opening};
  }

  /// Grasp state machine of tool @p t for its new jaw angle (before contacts).
  void update_grasp(int t, ToolOutput& out) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    const ToolGeometry& g = tool.geometry;
    const double jaw = tool.pose.jaw_angle_rad;
    if (!tool.held.empty()) {
      if (jaw >= g.release_angle_rad) {
        tool.held.clear();
        push_event(out, ToolEventKind::kRelease);
      }
      return;
    }
    const bool closing = tool.has_previous_jaw && tool.previous_jaw > g.grasp_angle_rad &&
                         jaw <= g.grasp_angle_rad && g.jaw_length_m > 0;
    if (!closing) return;
    next_epoch();
    const int n = gather_candidates(tool);
    // The triangles near the jaws that this tool may hold: not wholly fixed,
    // no vertex of a point another tool holds.
    std::size_t near = 0;
    const int m = gather_triangles(n);
    for (int k = 0; k < m; ++k) {
      const int tri = near_triangles[static_cast<std::size_t>(k)];
      const int* corner = &triangle_vertices[3 * static_cast<std::size_t>(tri)];
      int fixed = 0;
      bool elsewhere = false;
      for (int i = 0; i < 3; ++i) {
        if (corner[i] >= compliance_count)
          ++fixed;
        else
          elsewhere |= owner_held_elsewhere(corner[i], t);
      }
      if (fixed == 3 || elsewhere) continue;
      grasp_triangles[near++] = tri;
    }
    deform_corners({grasp_triangles.data(), near});
    for (std::size_t k = 0; k < near; ++k)
      for (std::size_t i = 0; i < 3; ++i)
        grasp_corners[3 * k + i] =
            deformed(triangle_vertices[3 * static_cast<std::size_t>(grasp_triangles[k]) + i]);
    // What the tip pressed at the last tick.
    touched.clear();
    for (int c = 0; c < count; ++c) {
      const ContactPoint& point = points[static_cast<std::size_t>(c)];
      if (point.tool != t || point.held) continue;
      HeldPoint h;
      h.triangle = point.triangle;
      h.count = point.vertex_count;
      h.vertices = point.vertices;
      h.weights = point.weights;
      for (int i = 0; i < h.count; ++i)
        h.rest += h.weights[static_cast<std::size_t>(i)] *
                  rest[static_cast<std::size_t>(h.vertices[static_cast<std::size_t>(i)])];
      touched.push_back(h);
    }
    grasp.choose(jaws_of(tool, std::max(tool.widest_jaw, tool.previous_jaw)),
                 {grasp_triangles.data(), near}, {grasp_corners.data(), 3 * near},
                 triangle_vertices, rest, touched, tool.held, per_tool_cap);
    if (!tool.held.empty()) push_event(out, ToolEventKind::kGrasp);
  }

  bool owner_held_elsewhere(int j, int t) const {
    for (int other = 0; other < static_cast<int>(tools.size()); ++other) {
      if (other == t) continue;
      for (const auto& h : tools[static_cast<std::size_t>(other)].held)
        for (int i = 0; i < h.count; ++i)
          if (h.vertices[static_cast<std::size_t>(i)] == j) return true;
    }
    return false;
  }

  static void push_event(ToolOutput& out, ToolEventKind kind) {
    if (out.event_count < static_cast<int>(out.events.size()))
      out.events[static_cast<std::size_t>(out.event_count++)] = kind;
  }

  /// Tool @p t's tip contacts: the deepest point of each deformed surface
  /// triangle near it that the tip penetrates (docs/tools.md, "Tip contacts").
  void find_tips(int t) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    const ToolGeometry& g = tool.geometry;
    const Vector3d axis = tool.rotation.col(2);
    const double r = g.tip_radius_m;
    const double shell = 0.05 * r;  // a contact stays while within 5 % of r outside the tip
    const double near = 0.25 * r;   // triangles this close are watched during the solve
    const bool jaws_open = g.jaw_length_m > 0 && tool.pose.jaw_angle_rad > g.grasp_angle_rad;
    const int n = gather_candidates(tool);
    int total = 0;
    // The triangles to test, in the order met: none with a vertex of a
    // held point, none wholly fixed.
    int m = 0;
    const int met = gather_triangles(n);
    // far_from_tip pays only where it can skip triangles: each candidate
    // triangle has a corner within the search radius of the axis, so none is
    // skipped unless the loads move the softest triangle's points less than
    // that radius minus r + near (a deep wide press moves them more).
    const double spread = (1 + 1e-6) * std::sqrt(std::max(load_energy, 0.0));
    const bool screen = warping == nullptr && max_softness * spread + r + near < search_radius(g);
    for (int k = 0; k < met; ++k) {
      const int tri = near_triangles[static_cast<std::size_t>(k)];
      const int* corner = &triangle_vertices[3 * static_cast<std::size_t>(tri)];
      bool blocked = false;
      int fixed = 0;
      for (int i = 0; i < 3; ++i) {
        if (corner[i] >= compliance_count)
          ++fixed;
        else if (owner[static_cast<std::size_t>(corner[i])] >= 0)
          blocked = true;
      }
      if (!blocked && fixed < 3 && !(screen && far_from_tip(tool, tri, r + near, spread)))
        near_triangles[static_cast<std::size_t>(m++)] = tri;
    }
    deform_corners({near_triangles.data(), static_cast<std::size_t>(m)});
    for (int k = 0; k < m; ++k) {
      const int tri = near_triangles[static_cast<std::size_t>(k)];
      const int* corner = &triangle_vertices[3 * static_cast<std::size_t>(tri)];
      const Vector3d& a = deformed(corner[0]);
      const Vector3d& b = deformed(corner[1]);
      const Vector3d& cc = deformed(corner[2]);
      // Most of a wide tip's triangles are far from it: a triangle within
      // the ball about its centre through its farthest corner, a ball
      // r + near away from the axis, has no point nearer, and goes without
      // its closest points. The margin, 1e-6 r, is far above the round-off
      // of either distance: this skips only what the test below would.
      // (Any centre will do; the distances compare squared.)
      const Vector3d centre = (a + b + cc) * (1.0 / 3);
      const double ball = std::sqrt(std::max(
          {(a - centre).squaredNorm(), (b - centre).squaredNorm(), (cc - centre).squaredNorm()}));
      const double beyond = r + near + 1e-6 * r + ball;
      if ((centre - closest_on_segment(tool.pose.position_m, axis, tip_length(g), centre))
              .squaredNorm() >= beyond * beyond)
        continue;
      const detail::SegmentTrianglePair pair =
          detail::closest_segment_triangle(tool.pose.position_m, axis, tip_length(g), a, b, cc);
      const bool was = previous_triangle_owner[static_cast<std::size_t>(tri)] == t;
      const bool active = pair.distance < r || (was && pair.distance < r + shell);
      if (!active && pair.distance >= r + near) continue;
      const Vector3d& p = pair.on_triangle.point;
      // Tissue between open jaws is not pushed: it may be grasped.
      if (jaws_open && tool.held.empty() && !was && between_jaws(tool, p, tool.pose.jaw_angle_rad))
        continue;
      // Pushed from the axis to the point, onto the tip's surface. That
      // normal's tangent plane bounds the tip (it is convex), so a sliding
      // contact never pulls while the tissue would spring into the tip.
      // An axis on the triangle, or beyond it (the tip pushed through in
      // one tick), pushes along the triangle's inward normal.
      const Vector3d outward = (b - a).cross(cc - a);
      Vector3d normal = outward.squaredNorm() > 0 ? Vector3d(-outward.normalized())
                                                  : Vector3d(-vertex_normal_of(corner));
      if (pair.distance > 1e-9 * r && (p - pair.on_segment).dot(outward) <= 0)
        normal = (p - pair.on_segment) / pair.distance;
      TipCandidate candidate{tri,
                             0,
                             {},
                             {},
                             r - pair.distance,
                             normal,
                             pair.on_segment + r * normal,
                             Vector3d::Zero(),
                             active};
      bool movable = false;
      for (int i = 0; i < 3; ++i) {
        const double w = pair.on_triangle.weights[static_cast<std::size_t>(i)];
        if (w == 0) continue;  // on the opposite edge: not part of the point
        candidate.vertices[static_cast<std::size_t>(candidate.count)] = corner[i];
        candidate.weights[static_cast<std::size_t>(candidate.count)] = w;
        ++candidate.count;
        candidate.rest += w * rest[static_cast<std::size_t>(corner[i])];
        movable |= corner[i] < compliance_count;
      }
      if (!movable) continue;  // a point of the attachment's edge
      ranked[static_cast<std::size_t>(total)] = {candidate.depth, total};
      found[static_cast<std::size_t>(total++)] = candidate;
    }
    // Deepest first; a point on an edge or a vertex is found from every
    // triangle around it: keep it once. Points closer than 0.05 r to a
    // deeper one would add a nearly equal row (and the surface between them
    // stays within ~(0.05 r)²/2r = 0.1 % of r of the tip). A sticking point
    // fixes three components, so with friction points keep 0.3 r apart
    // (within ~4.5 % of r): closer ones make a nearly singular system.
    // (Their depths are sorted, not the points: the same comparisons, so
    // the same order, equal depths included, without moving the points.)
    std::sort(ranked.begin(), ranked.begin() + total,
              [](const Ranked& x, const Ranked& y) { return x.depth > y.depth; });
    const int room = std::max(0, per_tool_cap - static_cast<int>(tool.held.size()));
    const double spacing2 = (g.friction > 0 ? 0.09 : 0.0025) * r * r;
    int kept = 0;
    for (int c = 0; c < total && kept < room; ++c) {
      const TipCandidate& x =
          found[static_cast<std::size_t>(ranked[static_cast<std::size_t>(c)].index)];
      const Vector3d point = x.target - x.depth * x.normal;  // on the deformed triangle
      bool near = false;
      for (int k = 0; k < kept && !near; ++k) {
        const TipCandidate& y = tool.tips[static_cast<std::size_t>(k)];
        near = (y.target - y.depth * y.normal - point).squaredNorm() < spacing2;
      }
      if (!near) tool.tips[static_cast<std::size_t>(kept++)] = x;
    }
    tool.tip_count = kept;
  }

  Vector3d vertex_normal_of(const int* corner) const {
    for (int i = 0; i < 3; ++i)
      if (corner[i] < compliance_count) return vertex_normal[static_cast<std::size_t>(corner[i])];
    return Vector3d::UnitZ();
  }

  /// Every living tool's contacts at its latest pose, one solve for all.
  /// On failure the previous solution stays.
  RequestStatus find_contacts_and_solve() {
    // Held vertices first: they win a vertex over any tip.
    for (int t = 0; t < static_cast<int>(tools.size()); ++t)
      if (tools[static_cast<std::size_t>(t)].alive)
        for (const auto& h : tools[static_cast<std::size_t>(t)].held)
          for (int i = 0; i < h.count; ++i)
            if (h.vertices[static_cast<std::size_t>(i)] < compliance_count)
              owner[static_cast<std::size_t>(h.vertices[static_cast<std::size_t>(i)])] = t;
    next_epoch();
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      Tool& tool = tools[static_cast<std::size_t>(t)];
      // Ramping out: the last contacts, scaled down, not found again (the
      // scaled-back tissue would leave the frozen tip and come back).
      if (tool.alive && tool.in_watchdog) continue;
      tool.tip_count = 0;
      if (tool.alive) find_tips(t);
    }
    return solve_all();
  }

  /// Builds, solves (with adhesion release) and stores every tool's constraints.
  RequestStatus solve_all() {
    building = 0;
    // A point on its vertices, a fixed one as −1 (its share goes to the attachment).
    auto add = [&](int t, int tip, int held, const auto& point, ConstraintKind kind,
                   const Vector3d& value, const Vector3d& normal, const Vector3d& lever) {
      const auto b = static_cast<std::size_t>(building++);
      detail::LocalRow& l = local_rows[b];
      l.tool = t;
      l.tip = tip >= 0;
      l.lever = lever;
      l.normal = normal;
      l.rotation = Matrix3d::Identity();
      for (int i = 0; i < point.count && l.tip; ++i)
        l.corners[static_cast<std::size_t>(i)] =
            deformed(point.vertices[static_cast<std::size_t>(i)]);
      b_tool[b] = t;
      b_tip[b] = tip;
      b_held[b] = held;
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      detail::ActiveRow& row = rows[b];
      row.count = point.count;
      for (std::size_t i = 0; i < 3; ++i) {
        const int v = static_cast<int>(i) < point.count ? point.vertices[i] : -1;
        row.index[i] = v < compliance_count ? v : -1;
        row.weights[i] = static_cast<int>(i) < point.count ? point.weights[i] : 0.0;
      }
      row.kind = kind;
      row.value = value;
      row.normal = normal;
      row_world_normal[b] = normal;
      if (warping != nullptr) {
        // Into the point's material frame (docs/model.md, "Large rotations:
        // warped compliance"): d̂ = R̃⁻¹ d; a normal n̂ = R̃ᵀ n / s, δ̂ = δ / s.
        const Matrix3d Rt = point_rotation(point);
        row_rotation[b] = Rt;
        l.rotation = Rt;
        if (kind == ConstraintKind::kDisplacement) row.value = Rt.inverse() * value;
        if (normal.squaredNorm() > 0) {
          const Vector3d n = Rt.transpose() * normal;
          const double scale = n.norm();
          row.normal = n / scale;
          if (kind == ConstraintKind::kNormalDisplacement) row.value.x() = value.x() / scale;
        }
      }
      row.tip = tip >= 0;
      row.friction = tool.geometry.friction;
      row.depth = row.tip ? tool.tips[static_cast<std::size_t>(tip)].depth : 0.0;
      row.join_gap_m = 1e-3 * tool.geometry.tip_radius_m;
      row.state = detail::ActiveRow::kActive;
    };
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      if (!tool.alive) continue;
      for (int h = 0; h < static_cast<int>(tool.held.size()); ++h) {
        const HeldPoint& held = tool.held[static_cast<std::size_t>(h)];
        const Vector3d lever = tool.rotation * held.local;  // it turns with the jaws
        add(t, -1, h, held, ConstraintKind::kDisplacement,
            tool.scale * (tool.pose.position_m + lever - held.rest), Vector3d::Zero(), lever);
      }
    }
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const Tool& tool = tools[static_cast<std::size_t>(t)];
      if (!tool.alive) continue;
      for (int c = 0; c < tool.tip_count; ++c) {
        const TipCandidate& tip = tool.tips[static_cast<std::size_t>(c)];
        const Vector3d u = tool.scale * (tip.target - tip.rest);
        // The tip's surface point moves as the point of the axis it is
        // pushed from (its normal frozen).
        const Vector3d lever =
            tip.target - tool.geometry.tip_radius_m * tip.normal - tool.pose.position_m;
        if (tool.geometry.friction > 0)
          add(t, c, -1, tip, ConstraintKind::kDisplacement, u, tip.normal, lever);
        else
          add(t, c, -1, tip, ConstraintKind::kNormalDisplacement, Vector3d(tip.normal.dot(u), 0, 0),
              tip.normal, lever);
        detail::LocalRow& l = local_rows[static_cast<std::size_t>(building - 1)];
        l.target = tip.target;
        l.radius = tool.geometry.tip_radius_m;
        l.distance = tool.geometry.tip_radius_m - tip.depth;
        if (!tip.active)
          rows[static_cast<std::size_t>(building - 1)].state = detail::ActiveRow::kDormant;
      }
    }
    const RequestStatus status =
        active_set.solve({rows.data(), static_cast<std::size_t>(building)}, settings.max_iterations,
                         settings.incremental_active_set ? detail::ActiveSetMethod::kIncremental
                                                         : detail::ActiveSetMethod::kRefactor);
    factored = status == RequestStatus::kOk;
    for (int t = 0; t < static_cast<int>(tools.size()); ++t)
      for (const auto& h : tools[static_cast<std::size_t>(t)].held)
        for (int i = 0; i < h.count; ++i)
          if (h.vertices[static_cast<std::size_t>(i)] < compliance_count)
            owner[static_cast<std::size_t>(h.vertices[static_cast<std::size_t>(i)])] = -1;
    if (status != RequestStatus::kOk) {
      const std::size_t length = strnlen(active_set.message(), sizeof message - 1);
      std::memcpy(message, active_set.message(), length);
      message[length] = '\0';
      return status;
    }
    store_solution();
    return RequestStatus::kOk;
  }

  void store_solution() {
    // Forget last tick's tip contacts' triangles (for the hysteresis shell).
    for (int c = 0; c < count; ++c) {
      const ContactPoint& old = points[static_cast<std::size_t>(c)];
      if (!old.held) previous_triangle_owner[static_cast<std::size_t>(old.triangle)] = -1;
    }
    count = 0;
    max_displacement = 0;
    load_energy = 0;
    for (auto& tool : tools) {
      tool.raw_force.setZero();
      tool.raw_torque.setZero();
      tool.raw_grip = 0;
      tool.contacts = 0;
    }
    for (int b = 0; b < building; ++b) {
      const auto bb = static_cast<std::size_t>(b);
      const detail::ActiveRow& row = rows[bb];
      if (row.state != detail::ActiveRow::kActive) continue;
      const auto c = static_cast<std::size_t>(count);
      const int t = b_tool[bb];
      Tool& tool = tools[static_cast<std::size_t>(t)];
      ContactPoint& point = points[c];
      point.tool = t;
      point.held = b_tip[bb] < 0;
      // A held point and a tip's point are both a point of a triangle.
      const auto take = [&point](const auto& from) {
        point.triangle = from.triangle;
        point.vertex_count = from.count;
        point.vertices = from.vertices;
        point.weights = from.weights;
        return from.rest;
      };
      const Vector3d at_rest = point.held ? take(tool.held[static_cast<std::size_t>(b_held[bb])])
                                          : take(tool.tips[static_cast<std::size_t>(b_tip[bb])]);
      tip_of[c] = b_tip[bb];
      // Warped: the solve's force and displacement are the material ones;
      // the world's are f = R̃⁻ᵀ f̂ and R̃ û. The loads stay material.
      material_force[c] = active_set.force(b);
      const Matrix3d& Rt = row_rotation[bb];
      point.force_n = warping != nullptr ? Vector3d(Rt.transpose().inverse() * material_force[c])
                                         : material_force[c];
      const Vector3d displacement = warping != nullptr ? Vector3d(Rt * active_set.displacement(b))
                                                       : Vector3d(active_set.displacement(b));
      point.position_m = at_rest + displacement;
      point.normal =
          row.kind == ConstraintKind::kNormalDisplacement ? row_world_normal[bb] : Vector3d::Zero();
      max_displacement = std::max(max_displacement, displacement.norm());
      load_energy += material_force[c].dot(active_set.displacement(b));
      local_rows[bb].position = point.position_m;
      local_rows[bb].force = point.force_n;
      local_rows[bb].material_force = material_force[c];
      tool.raw_force -= point.force_n;  // the organ pushes the tool back
      tool.raw_torque += (point.position_m - tool.pose.position_m).cross(-point.force_n);
      if (point.held) {
        tool.raw_grip += 0.5 * std::abs(point.force_n.dot(tool.rotation.col(0)));
      } else {
        previous_triangle_owner[static_cast<std::size_t>(point.triangle)] = t;
      }
      ++tool.contacts;
      ++count;
    }
    gather_loads();
  }

  /// The points' forces as loads on their vertices, f_S = Hᵀ f_C, tool by
  /// tool (a vertex two tools load appears once for each).
  void gather_loads() {
    load_count = 0;
    for (int t = 0; t < static_cast<int>(tools.size()); ++t) {
      const int first = load_count;
      for (int c = 0; c < count; ++c) {
        const ContactPoint& point = points[static_cast<std::size_t>(c)];
        if (point.tool != t) continue;
        for (int i = 0; i < point.vertex_count; ++i) {
          const int v = point.vertices[static_cast<std::size_t>(i)];
          if (v >= compliance_count) continue;  // the attachment takes it
          int& slot = load_slot[static_cast<std::size_t>(v)];
          if (slot < first) {
            slot = load_count++;
            load_index[static_cast<std::size_t>(slot)] = v;
            load_tool[static_cast<std::size_t>(slot)] = t;
            Eigen::Map<Vector3d>{&load_force[3 * static_cast<std::size_t>(slot)]}.setZero();
          }
          Eigen::Map<Vector3d>{&load_force[3 * static_cast<std::size_t>(slot)]} +=
              point.weights[static_cast<std::size_t>(i)] *
              material_force[static_cast<std::size_t>(c)];
        }
      }
    }
    for (int l = 0; l < load_count; ++l)
      load_slot[static_cast<std::size_t>(load_index[static_cast<std::size_t>(l)])] = -1;
  }

  /// Tool @p t's contact wrench linearized about its pose (LocalContactModel,
  /// docs/tools.md "The local model"), from the factor of the stored solve.
  void local_model(int t, LocalContactModel& local) {
    const Tool& tool = tools[static_cast<std::size_t>(t)];
    local.valid = true;
    local.position_m = tool.pose.position_m;
    local.orientation = tool.pose.orientation;
    local.holding = tool.alive && !tool.held.empty();
    local.force_n = tool.alive ? tool.raw_force : Vector3d::Zero();
    local.torque_nm = tool.alive ? tool.raw_torque : Vector3d::Zero();
    local.stiffness.setZero();
    if (!tool.alive || tool.contacts == 0) return;
    const auto n = static_cast<std::size_t>(building);
    local.stiffness = linearization.stiffness({rows.data(), n}, {local_rows.data(), n}, t,
                                              tool.pose.position_m, tool.scale, active_set);
  }

  /// The feedback of tool @p t at @p now_s: clamp, slew limit, state events.
  void make_output(int t, double now_s, ToolOutput& out) {
    Tool& tool = tools[static_cast<std::size_t>(t)];
    // The local model of this tick's solve; the last one's when it failed
    // (its pose is its own, so it stays right about where it was made).
    if (factored)
      local_model(t, out.local);
    else
      out.local = tool.out.local;
    const ToolGeometry& g = tool.geometry;
    Vector3d target = tool.raw_force;
    bool limited = false;
    if (const double magnitude = target.norm(); magnitude > g.force_limit_n) {
      target *= g.force_limit_n / magnitude;
      limited = true;
    }
    const Vector3d previous = tool.has_output ? tool.out.force_n : Vector3d::Zero();
    const double dt = tool.has_output ? std::clamp(now_s - tool.last_output_s, 0.0, 0.01) : 0.001;
    const double step = g.max_force_rate_n_per_s * dt;
    Vector3d force = target;
    if (const double change = (target - previous).norm(); change > step) {
      force = previous + (target - previous) * (step / change);
      limited = true;
    }
    if (!tool.alive) {  // ramped out: nothing left to feel
      force.setZero();
      limited = false;
    }
    const double raw = tool.raw_force.norm();
    const double torque_scale = raw > 0 ? std::min(1.0, force.norm() / raw) : 0.0;
    out.force_n = force;
    out.torque_nm = tool.raw_torque * torque_scale;
    out.grip_n = tool.raw_grip * torque_scale;
    out.contacts = tool.alive ? tool.contacts : 0;
    out.held = tool.alive ? static_cast<int>(tool.held.size()) : 0;
    out.force_limited = limited;
    out.watchdog = tool.in_watchdog;
    out.sequence = tool.pose.sequence;
    out.send_time_ns = tool.pose.send_time_ns;
    const ToolState state = !tool.held.empty() && tool.alive ? ToolState::kGrasping
                            : out.contacts > 0               ? ToolState::kTouching
                                                             : ToolState::kFree;
    if (state != tool.shown_state) {
      if (state == ToolState::kTouching && tool.shown_state == ToolState::kFree)
        push_event(out, ToolEventKind::kTouch);
      if (state == ToolState::kFree && tool.shown_state == ToolState::kTouching)
        push_event(out, ToolEventKind::kLeave);
    }
    out.state = state;
    tool.shown_state = state;
    tool.out = out;
    tool.has_output = true;
    tool.last_output_s = now_s;
  }
};

ToolContactEngine::ToolContactEngine(const SurfaceModel& model, std::vector<ToolGeometry> tools,
                                     const ContactSettings& settings, const SolverLimits& limits,
                                     const RotationField* warping)
    : impl_(std::make_unique<Impl>(model, std::move(tools), settings, limits, warping)) {}
ToolContactEngine::~ToolContactEngine() = default;

int ToolContactEngine::tool_count() const { return static_cast<int>(impl_->tools.size()); }

int ToolContactEngine::tool_index(std::string_view id) const {
  for (std::size_t t = 0; t < impl_->tools.size(); ++t)
    if (impl_->tools[t].geometry.id == id) return static_cast<int>(t);
  return -1;
}

const ToolGeometry& ToolContactEngine::tool(int index) const {
  return impl_->tools.at(static_cast<std::size_t>(index)).geometry;
}

PoseProblem ToolContactEngine::check(int t, ToolPoseInput& pose) const {
  const Impl& s = *impl_;
  const auto& tool = s.tools.at(static_cast<std::size_t>(t));
  const std::string& id = tool.geometry.id;
  const auto& q = pose.orientation.coeffs();
  if (!pose.position_m.allFinite() || !q.allFinite() || !std::isfinite(pose.jaw_angle_rad)) {
    s.explain("pose of tool '{}' has a non-finite position, orientation or jaw angle", id);
    return PoseProblem::kNonFinite;
  }
  const double norm = q.norm();
  if (!(norm > 0.9 && norm < 1.1)) {
    s.explain(
        "orientation of tool '{}' is a quaternion of norm {:.3g}; accepted: a unit "
        "quaternion (norm within 0.9-1.1, normalized here)",
        id, norm);
    return PoseProblem::kBadQuaternion;
  }
  pose.orientation.normalize();
  const double max_jaw = tool.geometry.max_jaw_angle_rad;
  if (!(pose.jaw_angle_rad >= 0 && pose.jaw_angle_rad <= max_jaw + 1e-9)) {
    s.explain("jaw angle {:.4g}° of tool '{}' is {} its limit; accepted: 0° to {:.4g}°",
              in_degrees(pose.jaw_angle_rad), id, pose.jaw_angle_rad < 0 ? "under" : "over",
              in_degrees(max_jaw));
    return PoseProblem::kBadJawAngle;
  }
  const double margin_m = s.settings.workspace_margin_m;
  const Eigen::Vector3d margin = Eigen::Vector3d::Constant(margin_m);
  if ((pose.position_m.array() < (s.box_min - margin).array()).any() ||
      (pose.position_m.array() > (s.box_max + margin).array()).any()) {
    s.explain(
        "tool '{}' at ({:.4g}, {:.4g}, {:.4g}) m is more than {:.4g} m outside the "
        "organ's box ({:.4g}, {:.4g}, {:.4g})-({:.4g}, {:.4g}, {:.4g}) m",
        id, pose.position_m.x(), pose.position_m.y(), pose.position_m.z(), margin_m, s.box_min.x(),
        s.box_min.y(), s.box_min.z(), s.box_max.x(), s.box_max.y(), s.box_max.z());
    return PoseProblem::kOutOfWorkspace;
  }
  // A pose not newer than the last one is stale, unless the watchdog fired
  // since (a restarted client counts again from 1).
  if (tool.alive && !tool.in_watchdog && tool.has_sequence && pose.sequence <= tool.pose.sequence) {
    s.explain("pose {} of tool '{}' is not newer than pose {} already taken", pose.sequence, id,
              tool.pose.sequence);
    return PoseProblem::kStale;
  }
  return PoseProblem::kNone;
}

const char* ToolContactEngine::problem_message() const { return impl_->problem; }

RequestStatus ToolContactEngine::update(int t, const ToolPoseInput& pose, double now_s) {
  Impl& s = *impl_;
  if (s.rotations) s.rotations->next_tick();
  auto& tool = s.tools.at(static_cast<std::size_t>(t));
  ToolOutput out;
  if (tool.in_watchdog || !tool.alive) {
    if (tool.in_watchdog || tool.has_sequence) Impl::push_event(out, ToolEventKind::kResumed);
    tool.in_watchdog = false;
    tool.scale = 1;
  }
  tool.alive = true;
  tool.has_previous_jaw = tool.has_sequence;
  tool.previous_jaw = tool.pose.jaw_angle_rad;
  tool.widest_jaw = tool.has_sequence && tool.held.empty()
                        ? std::max(tool.widest_jaw, tool.previous_jaw)
                        : tool.previous_jaw;
  tool.pose = pose;
  tool.has_sequence = true;
  tool.rotation = pose.orientation.toRotationMatrix();
  tool.last_pose_s = now_s;

  s.update_grasp(t, out);
  const RequestStatus status = s.find_contacts_and_solve();
  s.make_output(t, now_s, out);
  return status;
}

std::uint64_t ToolContactEngine::watchdog(double now_s) {
  Impl& s = *impl_;
  std::uint64_t changed = 0;
  std::array<ToolOutput, 64> outs{};
  for (int t = 0; t < static_cast<int>(s.tools.size()); ++t) {
    auto& tool = s.tools[static_cast<std::size_t>(t)];
    if (!tool.alive) continue;
    const double silent = now_s - tool.last_pose_s - s.settings.watchdog_timeout_s;
    if (silent <= 0) continue;
    if (!tool.in_watchdog) {
      tool.in_watchdog = true;
      Impl::push_event(outs[static_cast<std::size_t>(t)], ToolEventKind::kWatchdog);
    }
    tool.scale = std::clamp(1 - silent / s.settings.watchdog_ramp_s, 0.0, 1.0);
    changed |= std::uint64_t{1} << t;
  }
  if (changed == 0) return 0;
  // A tool ramped to zero lets go of everything and is forgotten.
  for (auto& tool : s.tools)
    if (tool.alive && tool.scale == 0) {
      tool.held.clear();
      tool.alive = false;
    }
  s.find_contacts_and_solve();
  for (int t = 0; t < static_cast<int>(s.tools.size()); ++t)
    if (changed >> t & 1) s.make_output(t, now_s, outs[static_cast<std::size_t>(t)]);
  return changed;
}

bool ToolContactEngine::end(int t, double now_s) {
  Impl& s = *impl_;
  auto& tool = s.tools.at(static_cast<std::size_t>(t));
  if (!tool.alive && !tool.has_sequence) return false;
  const bool had_contacts = tool.alive && (tool.contacts > 0 || !tool.held.empty());
  tool.held.clear();
  tool.alive = false;
  tool.in_watchdog = false;
  tool.scale = 1;
  tool.has_sequence = false;  // its next pose starts a new session, not a resumed one
  tool.has_previous_jaw = false;
  tool.widest_jaw = 0;
  tool.tip_count = 0;
  // The others feel the tissue it let go of.
  if (had_contacts) s.find_contacts_and_solve();
  ToolOutput out;
  s.make_output(t, now_s, out);                       // a touching tool leaves first,
  Impl::push_event(tool.out, ToolEventKind::kEnded);  // then its session ends
  return true;
}

const ToolOutput& ToolContactEngine::output(int t) const {
  return impl_->tools.at(static_cast<std::size_t>(t)).out;
}
const ToolPoseInput& ToolContactEngine::pose(int t) const {
  return impl_->tools.at(static_cast<std::size_t>(t)).pose;
}
const char* ToolContactEngine::solver_message() const { return impl_->message; }
std::span<const ContactPoint> ToolContactEngine::contact_points() const {
  return {impl_->points.data(), static_cast<std::size_t>(impl_->count)};
}
std::span<const int> ToolContactEngine::contact_indices() const {
  return {impl_->load_index.data(), static_cast<std::size_t>(impl_->load_count)};
}
std::span<const double> ToolContactEngine::contact_forces() const {
  return {impl_->load_force.data(), 3 * static_cast<std::size_t>(impl_->load_count)};
}
std::span<const int> ToolContactEngine::contact_tools() const {
  return {impl_->load_tool.data(), static_cast<std::size_t>(impl_->load_count)};
}
std::uint64_t ToolContactEngine::solves() const { return impl_->active_set.solves(); }
ToolContactEngine::SolveTimes ToolContactEngine::solve_times() const {
  const detail::ActiveSet& a = impl_->active_set;
  return {a.solves() - a.later_solves(), a.later_solves(), a.first_seconds(), a.later_seconds()};
}

}  // namespace palpate
