// The hybrid model as served (runtime/hybrid_region): a compliance file
// made by precompute with a cuttable region, loaded as palpated loads it,
// stepped in 1 ms ticks with the rest's loads and a tool tip, against the
// organ's own static answer K u = f assembled here from the mesh (sparse
// LDLᵀ: no compliance, no condensation, no tensor-mass code). Without a
// cut the two are the same linear problem; after a cut, against the mesh
// without the tetrahedra the cut removed, which checks the release of Γ
// vertices the cut leaves without a region tetrahedron (docs/model/hybrid-serving.md, "The
// hybrid model as served"). The dynamics (random cuts, the two integrators,
// pliers beside the region) are hybrid_dynamics_test's.

#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/hybrid_region.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/tool_contact.hpp"
#include "palpate/runtime/tool_tick.hpp"
#include "runtime/hybrid_organ.hpp"
#include "support/allocation_counter.hpp"
#include "support/box_job.hpp"
#include "support/expect_error.hpp"
#include "support/sphere_tool.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using Eigen::Vector3d;
using Eigen::VectorXd;
using testing::kE;
using testing::kLx;
using testing::kLz;
using testing::kNu;
using testing::Organ;
using testing::rest_vertex_near;

/// The organ's static displacement (3#V, m) under @p f (3#V, N) with the
/// tetrahedra @p removed (mesh numbering) taken out, clamped on x ≤ 1 mm as
/// the job: K u = f on the free vertices any remaining tetrahedron uses.
VectorXd reference(const TetMesh& mesh, const std::set<std::array<int, 4>>& removed,
                   const VectorXd& f) {
  std::vector<std::array<int, 4>> kept;
  for (Eigen::Index t = 0; t < mesh.tetrahedra.rows(); ++t) {
    std::array<int, 4> tet{mesh.tetrahedra(t, 0), mesh.tetrahedra(t, 1), mesh.tetrahedra(t, 2),
                           mesh.tetrahedra(t, 3)};
    std::array<int, 4> key = tet;
    std::sort(key.begin(), key.end());
    if (!removed.count(key)) kept.push_back(tet);
  }
  Eigen::MatrixX4i tets(static_cast<Eigen::Index>(kept.size()), 4);
  for (std::size_t t = 0; t < kept.size(); ++t)
    for (int c = 0; c < 4; ++c) tets(static_cast<Eigen::Index>(t), c) = kept[t][c];
  const SparseMatrixd K = assemble_full_stiffness(
      mesh.vertices, tets, Eigen::VectorXi::Zero(tets.rows()), {lame_parameters(kE, kNu)});
  std::vector<char> used(static_cast<std::size_t>(mesh.vertices.rows()), 0);
  for (const auto& t : kept)
    for (int v : t) used[static_cast<std::size_t>(v)] = 1;
  std::vector<int> free_dofs;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    if (used[static_cast<std::size_t>(v)] && mesh.vertices(v, 0) > 0.001)
      for (int a = 0; a < 3; ++a) free_dofs.push_back(static_cast<int>(3 * v + a));
  std::vector<int> position(static_cast<std::size_t>(K.rows()), -1);
  for (std::size_t i = 0; i < free_dofs.size(); ++i)
    position[static_cast<std::size_t>(free_dofs[i])] = static_cast<int>(i);
  std::vector<Eigen::Triplet<double>> entries;
  for (int col = 0; col < K.outerSize(); ++col)
    for (SparseMatrixd::InnerIterator it(K, col); it; ++it)
      if (position[it.row()] >= 0 && position[it.col()] >= 0)
        entries.emplace_back(position[it.row()], position[it.col()], it.value());
  SparseMatrixd Kf(static_cast<Eigen::Index>(free_dofs.size()),
                   static_cast<Eigen::Index>(free_dofs.size()));
  Kf.setFromTriplets(entries.begin(), entries.end());
  VectorXd ff(Kf.rows());
  for (std::size_t i = 0; i < free_dofs.size(); ++i) ff[i] = f[free_dofs[i]];
  const Eigen::SimplicialLDLT<SparseMatrixd> ldlt(Kf);
  EXPECT_EQ(ldlt.info(), Eigen::Success);
  const VectorXd uf = ldlt.solve(ff);
  VectorXd u = VectorXd::Zero(f.size());
  for (std::size_t i = 0; i < free_dofs.size(); ++i) u[free_dofs[i]] = uf[i];
  return u;
}

/// Mesh vertex of each input-file id (box_mesh writes its vertices in order).
int mesh_vertex(int source_id) { return source_id; }

/// What the served hybrid says every vertex does (3#V, m; NaN where it has
/// no answer: interior vertices of the rest), with the rest loaded by
/// @p rest_loads (compliance index → force).
VectorXd hybrid_field(const Organ& o, const HybridRegion& h,
                      const std::vector<std::pair<int, Vector3d>>& rest_loads) {
  const SurfaceModel& m = o.model;
  VectorXd u_s = VectorXd::Zero(m.compliance_rows());
  for (const auto& [index, f] : rest_loads)
    for (int a = 0; a < m.compliance_vertex_count(); ++a)
      u_s.segment<3>(3 * a) += m.G_block(a, index) * f;
  h.add_rest_displacement(u_s);
  VectorXd u = VectorXd::Constant(3 * o.mesh.vertices.rows(), std::nan(""));
  for (int a = 0; a < m.compliance_vertex_count(); ++a)
    u.segment<3>(3 * mesh_vertex(m.source_vertex_ids[m.surface.vertex_ids[a]])) =
        u_s.segment<3>(3 * a);
  const CutRegionData& region = *m.cut_region;
  const TensorMassModel& t = h.tensor_mass();
  for (int r = 0; r < t.vertex_count(); ++r) {
    const int v = mesh_vertex(region.source_vertex_ids[r]);
    if (t.is_detached(r)) continue;  // the rest's, if on its surface
    if (t.is_fixed(r)) {
      u.segment<3>(3 * v).setZero();
      continue;
    }
    const bool on_gamma =
        std::count(h.interface_vertices().begin(), h.interface_vertices().end(), r);
    if (on_gamma) {
      // Both sides give Γ: the region's own u_Γ and the rest's G_ΓS f_S + G_ΓΓ f_Γ.
      EXPECT_LE((t.displacement_m().segment<3>(3 * r) - u.segment<3>(3 * v)).norm(),
                1e-6 * u.segment<3>(3 * v).norm() + 1e-15)
          << "Γ vertex " << r;
    }
    u.segment<3>(3 * v) = t.displacement_m().segment<3>(3 * r);
  }
  return u;
}

/// Relative RMS difference over the vertices the hybrid answers for.
double relative_difference(const VectorXd& hybrid, const VectorXd& expected, int* compared) {
  double e2 = 0, n2 = 0;
  *compared = 0;
  for (Eigen::Index i = 0; i < hybrid.size(); i += 3) {
    if (std::isnan(hybrid[i])) continue;
    e2 += (hybrid.segment<3>(i) - expected.segment<3>(i)).squaredNorm();
    n2 += expected.segment<3>(i).squaredNorm();
    ++*compared;
  }
  return std::sqrt(e2 / n2);
}

/// Ticks of 1 ms until u changes by less than 1e-13 of itself in a tick.
int settle_region(HybridRegion& h, const std::vector<std::pair<int, Vector3d>>& rest_loads,
                  const std::vector<RegionTip>& tips) {
  std::vector<int> indices;
  std::vector<double> forces;
  for (const auto& [index, f] : rest_loads) {
    indices.push_back(index);
    forces.insert(forces.end(), {f.x(), f.y(), f.z()});
  }
  VectorXd before = h.tensor_mass().displacement_m();
  for (int tick = 1; tick <= 20000; ++tick) {
    h.advance(1e-3, indices, forces, tips);
    const VectorXd& u = h.tensor_mass().displacement_m();
    if (tick > 10 && (u - before).norm() <= 1e-13 * u.norm()) return tick;
    before = u;
  }
  return -1;
}

HybridRegionSettings settling_settings() {
  HybridRegionSettings s;
  s.damping_per_s = 1500;  // near critical for the region's slowest mode
  return s;
}

TEST(HybridServing, ALoadOnTheRestSettlesOnTheWholeOrgan) {
  const Organ o;
  HybridRegion h(o.model, settling_settings());
  ASSERT_GT(h.interface_vertices().size(), 20u);
  EXPECT_GT(h.interface_face_count(), 20);
  const int loaded = rest_vertex_near(o.model, {0.056, 0.032, kLz});
  const Vector3d f(0.05, -0.1, -0.5);
  const int ticks = settle_region(h, {{loaded, f}}, {});
  std::printf("settled in %d ticks (%d substeps of %.3g µs each)\n", ticks, h.substeps(),
              h.substep_s() * 1e6);
  ASSERT_GT(ticks, 0);
  VectorXd load = VectorXd::Zero(3 * o.mesh.vertices.rows());
  load.segment<3>(3 * mesh_vertex(o.model.source_vertex_ids[o.model.surface.vertex_ids[loaded]])) =
      f;
  int compared = 0;
  const double e = relative_difference(hybrid_field(o, h, {{loaded, f}}),
                                       reference(o.mesh, {}, load), &compared);
  std::printf("rest load: %d vertices, relative difference %.3g\n", compared, e);
  EXPECT_GT(compared, 500);
  EXPECT_LE(e, 1e-6);
}

TEST(HybridServing, ATipOnTheRegionSettlesOnTheWholeOrgan) {
  const Organ o;
  HybridRegion h(o.model, settling_settings());
  // A 6 mm sphere 1.5 mm into the top face over the region.
  const RegionTip tip{{0.082, 0.030, kLz + 0.0045}, {0.082, 0.030, kLz + 0.0045}, 0.006};
  ASSERT_GT(settle_region(h, {}, {tip}), 0);
  EXPECT_GT(h.pressed_vertices(), 0);
  // The tool feels what it pushes: minus the sum of the loads on the region.
  Vector3d on_region = Vector3d::Zero();
  const VectorXd& f_r = h.region_load_n();
  for (Eigen::Index i = 0; i < f_r.size(); i += 3) on_region += f_r.segment<3>(i);
  EXPECT_GT(on_region.norm(), 0.05);
  EXPECT_LE((h.tip_force_n(0) + on_region).norm(), 1e-9 * on_region.norm());
  EXPECT_GT(h.tip_force_n(0).z(), 0);  // pushed back up
  // The organ under the same loads.
  VectorXd load = VectorXd::Zero(3 * o.mesh.vertices.rows());
  for (int r = 0; r < h.tensor_mass().vertex_count(); ++r)
    load.segment<3>(3 * mesh_vertex(o.model.cut_region->source_vertex_ids[r])) +=
        f_r.segment<3>(3 * r);
  int compared = 0;
  const double e =
      relative_difference(hybrid_field(o, h, {}), reference(o.mesh, {}, load), &compared);
  std::printf("tip on the region: %.3g N, relative difference %.3g\n", on_region.norm(), e);
  EXPECT_LE(e, 1e-6);
}

/// Mesh tetrahedra (sorted vertex ids) the region removed.
std::set<std::array<int, 4>> removed_tets(const Organ& o, const HybridRegion& h) {
  std::set<std::array<int, 4>> out;
  const auto& tets = h.tensor_mass().tetrahedra();
  for (int t = 0; t < h.tensor_mass().tetrahedron_count(); ++t) {
    if (!h.tensor_mass().is_removed(t)) continue;
    std::array<int, 4> key{};
    for (int c = 0; c < 4; ++c)
      key[c] = mesh_vertex(o.model.cut_region->source_vertex_ids[tets(t, c)]);
    std::sort(key.begin(), key.end());
    out.insert(key);
  }
  return out;
}

TEST(HybridServing, ACutSettlesOnTheOrganWithoutWhatItRemoved) {
  const Organ o;
  HybridRegion h(o.model, settling_settings());
  const auto version = h.topology_version();
  const std::size_t held = h.interface_vertices().size();
  std::vector<std::array<int, 3>> before, after;
  h.visible_triangles(before);
  // A blade drawn down through the region's whole depth, to its bottom
  // face on the rest (z = 24 mm), across y: an incision 5 mm from the end.
  int removed = 0;
  for (double y = 0.017; y < 0.048; y += 0.002)
    removed += h.cut({0.091, y, kLz + 0.002}, {0.091, y, 0.0245});
  std::printf("the incision removed %d tetrahedra; %zu Γ vertices still held\n", removed,
              h.interface_vertices().size());
  ASSERT_GT(removed, 10);
  // It released Γ vertices (the Schur condensation of S) as well as cutting.
  EXPECT_LT(h.interface_vertices().size(), held);
  EXPECT_EQ(h.tensor_mass().remaining_tetrahedra(), h.tensor_mass().tetrahedron_count() - removed);
  EXPECT_GT(h.topology_version(), version);
  h.visible_triangles(after);
  EXPECT_NE(after.size(), before.size());
  int uncovered = 0;
  for (int t = 0; t < o.model.surface.triangle_count(); ++t)
    if (!h.covers_rest_triangle(t)) ++uncovered;
  // The blade reached the bottom face Γ: some of the rest's faces there are open now.
  EXPECT_GT(uncovered, o.model.surface.triangle_count() - h.interface_face_count());
  EXPECT_LT(uncovered, o.model.surface.triangle_count());

  const int loaded = rest_vertex_near(o.model, {0.056, 0.032, kLz});
  const Vector3d f(0.05, -0.1, -0.5);
  ASSERT_GT(settle_region(h, {{loaded, f}}, {}), 0);
  VectorXd load = VectorXd::Zero(3 * o.mesh.vertices.rows());
  load.segment<3>(3 * mesh_vertex(o.model.source_vertex_ids[o.model.surface.vertex_ids[loaded]])) =
      f;
  int compared = 0;
  const double e = relative_difference(hybrid_field(o, h, {{loaded, f}}),
                                       reference(o.mesh, removed_tets(o, h), load), &compared);
  std::printf("after the cut: relative difference %.3g over %d vertices\n", e, compared);
  EXPECT_LE(e, 1e-6);
}

TEST(HybridServing, CuttingTheWholeRegionOutLeavesTheRestAlone) {
  const Organ o;
  HybridRegion h(o.model, settling_settings());
  for (double x = 0.063; x <= kLx + 0.001; x += 0.002)
    for (double y = 0.015; y <= 0.049; y += 0.002) h.cut({x, y, kLz + 0.002}, {x, y, 0.023});
  EXPECT_EQ(h.tensor_mass().remaining_tetrahedra(), 0);
  EXPECT_TRUE(h.interface_vertices().empty());
  std::vector<std::array<int, 3>> visible;
  h.visible_triangles(visible);
  EXPECT_TRUE(visible.empty());
  for (int t = 0; t < o.model.surface.triangle_count(); ++t)
    EXPECT_FALSE(h.covers_rest_triangle(t));
  // Nothing left to push the rest or the tip.
  const RegionTip tip{{0.082, 0.030, kLz}, {0.082, 0.030, kLz}, 0.006};
  const std::vector<int> index{0};
  const std::vector<double> force{0, 0, -0.1};
  h.advance(1e-3, index, force, std::span(&tip, 1));
  EXPECT_EQ(h.tip_force_n(0), Vector3d::Zero());
  VectorXd u = VectorXd::Zero(o.model.compliance_rows());
  h.add_rest_displacement(u);
  EXPECT_EQ(u, VectorXd::Zero(o.model.compliance_rows()));
  EXPECT_EQ(h.cut({0.08, 0.03, kLz}, {0.08, 0.03, 0.02}), 0);
}

/// A frictionless 3 mm sphere probe (no jaws, no force limit in the way).
ToolGeometry sphere_probe() { return testing::sphere_tool("probe", 0.003); }

/// The force on the probe pressing 1.5 mm at @p hinge, held for @p ticks
/// of 1 ms; with @p region, the region stepped in each tick: when
/// @p coupled, as palpated serves it (ToolTick: its push given to the
/// engine as background loads), else alone beside the engine (the tools
/// never feel its push).
Vector3d probe_force(const SurfaceModel& model, const Vector3d& hinge, HybridRegion* region,
                     bool coupled, int ticks) {
  ToolTick tick(model, {sphere_probe()}, {}, {}, nullptr, coupled ? region : nullptr);
  ToolContactEngine& engine = tick.engine();
  Vector3d previous = Vector3d::Zero();
  for (int t = 1; t <= ticks; ++t) {
    ToolPoseInput pose;
    pose.sequence = static_cast<std::uint64_t>(t);
    pose.position_m = hinge;
    pose.orientation = Eigen::Quaterniond(0, 1, 0, 0);  // tip down
    EXPECT_EQ(engine.check(0, pose), PoseProblem::kNone);
    EXPECT_EQ(tick.update(0, pose, 1e-3 * t), RequestStatus::kOk);
    if (region != nullptr && !coupled)
      region->advance(1e-3, engine.contact_indices(), engine.contact_forces(), {});
    const Vector3d f = tick.output(0).force_n;
    if (t > 20 && (f - previous).norm() <= 1e-12 * f.norm()) break;
    previous = f;
  }
  return tick.output(0).force_n;
}

// A probe on the rest one cell from the region: the region resists the
// rest's motion at Γ, and the tools feel it through the background loads
// (ToolTick, ToolContactEngine::set_background_loads): the same force as on the
// whole organ, which the rest alone (the region's push left out) misses.
TEST(HybridServing, AProbeOnTheRestNextToTheRegionFeelsTheWholeOrgan) {
  const Organ o;
  PrecomputeJob whole_job = testing::clamped_job(o.mesh, o.dir.path(), "whole", kE);
  run_precompute(whole_job, {});
  const SurfaceModel whole = load_surface_model("whole", whole_job.output);
  const Vector3d hinge(0.056, 0.032, kLz + 0.003 - 0.0015);
  const Vector3d expected = probe_force(whole, hinge, nullptr, false, 50);
  HybridRegion coupled_region(o.model, settling_settings());
  const Vector3d coupled = probe_force(o.model, hinge, &coupled_region, true, 20000);
  HybridRegion one_way_region(o.model, settling_settings());
  const Vector3d one_way = probe_force(o.model, hinge, &one_way_region, false, 20000);
  const double e_coupled = (coupled - expected).norm() / expected.norm();
  const double e_one_way = (one_way - expected).norm() / expected.norm();
  std::printf(
      "probe next to the region: whole organ %.6f N; hybrid %.6f N (relative %.3g); "
      "without the region's push %.6f N (relative %.3g)\n",
      expected.norm(), coupled.norm(), e_coupled, one_way.norm(), e_one_way);
  EXPECT_GT(expected.z(), 0.05);
  EXPECT_LE(e_coupled, 1e-6);
  EXPECT_GT(e_one_way, 100 * e_coupled) << "the test tells the coupling from its absence";
}

// The served tick allocates nothing: the implicit step with a rest load (its
// u_Γ⁰ shift), a tip, and a cut's Woodbury update in use.
TEST(HybridServing, TheImplicitTickAllocatesNothing) {
  const Organ o;
  HybridRegion h(o.model);
  ASSERT_GT(h.cut({0.091, 0.030, kLz + 0.002}, {0.091, 0.034, kLz - 0.004}), 0);
  ASSERT_GT(h.update_rank(), 0);
  const std::vector<int> indices{rest_vertex_near(o.model, {0.056, 0.032, kLz})};
  const std::vector<double> forces{0.05, -0.1, -0.5};
  const RegionTip tip{{0.082, 0.030, kLz + 0.0045}, {0.082, 0.030, kLz + 0.0045}, 0.006};
  h.advance(1e-3, indices, forces, {&tip, 1});
  const auto before = testing::allocations_here();
  for (int n = 0; n < 10; ++n) h.advance(1e-3, indices, forces, {&tip, 1});
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  EXPECT_GT(h.interface_force_n().norm(), 0);
}

TEST(HybridServing, BadInputIsNamed) {
  testing::TempDir dir;
  const auto path = testing::write_box_compliance(dir.path());
  const SurfaceModel plain = load_surface_model("plain", path);
  testing::expect_error<InputError>([&] { HybridRegion h(plain); },
                                    {"no cuttable region", "[cut_region]"});
  const Organ o;
  HybridRegionSettings s;
  s.step_safety = 1.5;
  testing::expect_error<InputError>([&] { HybridRegion h(o.model, s); }, {"step safety", "(0, 1)"});
  HybridRegion h(o.model);
  const RegionTip tips[5]{};
  testing::expect_error<InputError>([&] { h.advance(1e-3, {}, {}, tips); },
                                    {"5 tips", "at most 4"});
  testing::expect_error<InputError>([&] { h.advance(0, {}, {}, {}); }, {"tick of 0 s"});
  const std::vector<int> one{0};
  testing::expect_error<InputError>([&] { h.advance(1e-3, one, {}, {}); }, {"3 per vertex"});
  const double force[3] = {0, 0, 0.1};
  for (const int outside : {-1, o.model.compliance_vertex_count()}) {
    const std::vector<int> bad{outside};
    testing::expect_error<InputError>([&] { h.advance(1e-3, bad, force, {}); },
                                      {"rest load on compliance vertex", "are accepted"});
  }
}

}  // namespace
}  // namespace palpate
