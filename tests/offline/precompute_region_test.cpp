// A precompute job with a cuttable region (issue 20): the [cut_region] keys
// (each shape, each error with file:line:key, the warnings), and a run whose
// file holds G on the outside's boundary equal to outside_compliance()'s,
// the region equal to region_model()'s, and vertex and edge tensors that are
// the sums of the element blocks.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "offline/region_box.hpp"
#include "palpate/core/error.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/attachment.hpp"
#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/offline/region_tensors.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "support/box_job.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::TempDir;

PrecomputeJob job_from(const TempDir& dir, const std::string& name, const std::string& region) {
  std::ofstream(dir / name) << "[mesh]\nfile = \"organ.msh\"\n\n" << region;
  return read_job_file(dir / name);
}

TEST(CutRegionJob, ReadsEachShapeInMillimetres) {
  TempDir dir;
  const PrecomputeJob box = job_from(
      dir, "box.toml", "[cut_region]\nbox_min_mm = [10, -5, 0]\nbox_max_mm = [30, 5, 40.5]\n");
  ASSERT_TRUE(box.cut_region);
  EXPECT_EQ(box.cut_region->spec.kind, RegionSpec::Kind::box);
  // 1e-18 m: the conversion is one multiplication by 1e-3 (round-off of 1e-16 relative).
  EXPECT_NEAR(box.cut_region->spec.min_m.x(), 0.010, 1e-18);
  EXPECT_NEAR(box.cut_region->spec.min_m.y(), -0.005, 1e-18);
  EXPECT_NEAR(box.cut_region->spec.max_m.z(), 0.0405, 1e-18);
  EXPECT_EQ(box.cut_region->density_kg_m3, kSoftTissueDensityKgM3);
  EXPECT_EQ(box.cut_region->damping_per_s, kDefaultRegionDampingPerS);

  const PrecomputeJob ball = job_from(dir, "ball.toml",
                                      "[cut_region]\nsphere_center_mm = [1, 2, 3]\n"
                                      "sphere_radius_mm = 12\ndensity_kg_m3 = 1000\n"
                                      "damping_per_s = 0\n");
  ASSERT_TRUE(ball.cut_region);
  EXPECT_EQ(ball.cut_region->spec.kind, RegionSpec::Kind::sphere);
  EXPECT_NEAR(ball.cut_region->spec.center_m.z(), 0.003, 1e-18);
  EXPECT_NEAR(ball.cut_region->spec.radius_m, 0.012, 1e-18);
  EXPECT_EQ(ball.cut_region->density_kg_m3, 1000);
  EXPECT_EQ(ball.cut_region->damping_per_s, 0);

  const PrecomputeJob group = job_from(dir, "group.toml", "[cut_region]\ngroup = \"tumour\"\n");
  ASSERT_TRUE(group.cut_region);
  EXPECT_EQ(group.cut_region->spec.kind, RegionSpec::Kind::group);
  EXPECT_EQ(group.cut_region->spec.group, "tumour");

  EXPECT_FALSE(job_from(dir, "none.toml", "").cut_region);
}

TEST(CutRegionJob, EachErrorNamesFileLineAndKey) {
  TempDir dir;
  // The table starts on line 4 of each file (job_from's [mesh] takes 3).
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"[cut_region]\ndensity_kg_m3 = 1000\n",
       {"x.toml:4", "cut_region", "no shape given", "exactly one shape"}},
      {"[cut_region]\ngroup = \"a\"\nsphere_center_mm = [0, 0, 0]\nsphere_radius_mm = 1\n",
       {"x.toml:4", "cut_region", "more than one shape"}},
      {"[cut_region]\nbox_min_mm = [0, 0, 0]\n", {"x.toml:4", "cut_region.box_max_mm", "missing"}},
      {"[cut_region]\nbox_min_mm = [0, 0, 5]\nbox_max_mm = [1, 1, 1]\n",
       {"x.toml:6", "cut_region.box_max_mm", "axis z", "min ≤ max"}},
      {"[cut_region]\nbox_min_mm = [0, 0]\nbox_max_mm = [1, 1, 1]\n",
       {"x.toml:5", "cut_region.box_min_mm", "3 numbers"}},
      {"[cut_region]\nsphere_radius_mm = 3\n",
       {"x.toml:4", "cut_region.sphere_center_mm", "missing"}},
      {"[cut_region]\nsphere_center_mm = [0, 0, 0]\nsphere_radius_mm = 0\n",
       {"x.toml:6", "cut_region.sphere_radius_mm", "> 0"}},
      {"[cut_region]\nsphere_center_mm = [0, 0, 0]\nsphere_radius_mm = nan\n",
       {"x.toml:6", "cut_region.sphere_radius_mm", "> 0"}},
      {"[cut_region]\ngroup = \"\"\n", {"x.toml:5", "cut_region.group", "physical group"}},
      {"[cut_region]\ngroup = \"a\"\ndensity_kg_m3 = -1\n",
       {"x.toml:6", "cut_region.density_kg_m3", "> 0", "kg/m³"}},
      {"[cut_region]\ngroup = \"a\"\ndamping_per_s = -0.5\n",
       {"x.toml:6", "cut_region.damping_per_s", "≥ 0"}},
      {"[cut_region]\ngroup = \"a\"\nradius_mm = 3\n",
       {"x.toml:6", "cut_region.radius_mm", "unknown key", "sphere_radius_mm"}},
      {"[[cut_region]]\ngroup = \"a\"\n", {"x.toml:4", "cut_region", "expected a table"}},
  };
  for (const auto& [text, fragments] : cases) {
    SCOPED_TRACE(text);
    std::ofstream(dir / "x.toml") << "[mesh]\nfile = \"organ.msh\"\n\n" << text;
    try {
      read_job_file(dir / "x.toml");
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      for (const auto& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << msg;
    }
  }
}

TEST(CutRegionJob, RoundTripsThroughTheStoredToml) {
  TempDir dir;
  for (const RegionSpec& spec :
       {RegionSpec::box({0.001, -0.002, 0}, {0.0305, 0.01, 0.02}),
        RegionSpec::sphere({0.01, 0.02, -0.03}, 0.012), RegionSpec::physical_group("tu\"m")}) {
    PrecomputeJob job = testing::box_job(dir.path());
    job.mesh_unit = "cm";  // the region's keys are in mm whatever the mesh's unit
    job.cut_region = CutRegionJob{spec, 1100, 7.5};
    std::ofstream(dir / "job.toml") << to_toml(job);
    const PrecomputeJob back = read_job_file(dir / "job.toml");
    ASSERT_TRUE(back.cut_region);
    EXPECT_EQ(back.cut_region->spec.describe(), spec.describe());
    // 1e-17 m: millimetres written as short as they read back, then × 1e-3.
    EXPECT_LE((back.cut_region->spec.min_m - spec.min_m).norm(), 1e-17);
    EXPECT_LE((back.cut_region->spec.max_m - spec.max_m).norm(), 1e-17);
    EXPECT_LE((back.cut_region->spec.center_m - spec.center_m).norm(), 1e-17);
    EXPECT_NEAR(back.cut_region->spec.radius_m, spec.radius_m, 1e-17);
    EXPECT_EQ(back.cut_region->spec.group, spec.group);
    EXPECT_EQ(back.cut_region->density_kg_m3, 1100);
    EXPECT_EQ(back.cut_region->damping_per_s, 7.5);
  }
}

// ---- a run ----------------------------------------------------------------

using namespace testing::region_box;  // NOLINT: the organ and its region

// For the measured differences in the test's XML output (--gtest_output=xml).
std::string scientific(double value) {
  std::ostringstream s;
  s << std::scientific << std::setprecision(2) << value;
  return s.str();
}

double max_relative_difference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

Eigen::Matrix3d tensor(const Eigen::MatrixXd& rows, Eigen::Index r) {
  Eigen::Matrix3d K;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) K(i, j) = rows(r, 3 * i + j);
  return K;
}

struct RegionRun {
  TempDir dir;
  PrecomputeJob job;
  std::vector<std::string> warnings;
  ComplianceModel model;
  Eigen::MatrixXd G;
  TetMesh mesh;  // the whole organ as precompute read it
  RegionSplit split;
};

void run(RegionRun& r, const RegionSpec& spec, double density_kg_m3 = 1060) {
  r.job = testing::clamped_job(organ(), r.dir.path(), "organ", 85e3);
  r.job.cut_region = CutRegionJob{spec, density_kg_m3, 20};
  PrecomputeHooks hooks;
  hooks.warn = [&](const std::string& w) { r.warnings.push_back(w); };
  run_precompute(r.job, hooks);
  r.model = read_compliance_file(r.job.output, &r.G);
  r.mesh = read_mesh(r.job.mesh_file, {parse_length_unit("m"), 0});
  validate_and_compact(r.mesh);
  r.split = split_region(r.mesh, spec, select_fixed_vertices(r.mesh, r.job.attachment));
}

TEST(PrecomputeRegion, WritesTheOutsidesComplianceAndTheRegionsModel) {
  RegionRun r;
  run(r, far_top_box());
  ASSERT_TRUE(r.model.cut_region);
  const CutRegionData& c = *r.model.cut_region;
  const RegionSplit& split = r.split;
  EXPECT_TRUE(r.warnings.empty()) << r.warnings.front();

  // G on the outside's boundary: the same vertices, in the same order, and
  // equal to outside_compliance()'s within 1e-10 relative (both are the
  // solves of the same K; the file's was cross-checked against condensation).
  const Eigen::VectorXi material = Eigen::VectorXi::Zero(r.mesh.tetrahedra.rows());
  const std::vector<Lame> lame{lame_parameters(85e3, 0.45)};
  const OutsideCompliance oc =
      outside_compliance(split, material, lame, OutsideMethod::solves, ComplianceOptions{});
  ASSERT_EQ(static_cast<size_t>(r.model.compliance_vertices.size()), oc.vertices.size());
  for (size_t a = 0; a < oc.vertices.size(); ++a)
    EXPECT_EQ(r.model.source_vertex_ids[r.model.compliance_vertices[static_cast<Eigen::Index>(a)]],
              r.mesh.source_ids[oc.vertices[a]])
        << a;
  ASSERT_EQ(r.G.rows(), oc.G.rows());
  const double g_difference = max_relative_difference(r.G, oc.G);
  EXPECT_LE(g_difference, 1e-10);
  RecordProperty("G_relative_difference", scientific(g_difference));
  // The file's mesh is the outside.
  EXPECT_EQ(r.model.tetrahedra.rows(), static_cast<Eigen::Index>(split.outside_tets.size()));
  EXPECT_EQ(r.model.vertices_m, split.outside.vertices);

  // Γ: where the run time finds G_ΓΓ in the file's G.
  EXPECT_EQ(
      std::vector<int>(c.interface_compliance_index.begin(), c.interface_compliance_index.end()),
      oc.interface);
  Eigen::MatrixXd Ggg = vertex_block(r.G, oc.interface,
                                     oc.interface);  // positions in the file's G are oc's positions
  EXPECT_LE(max_relative_difference(Ggg, oc.interface_compliance), 1e-10);

  // The region as region_model() makes it.
  const RegionModel rm = region_model(r.mesh, split, material, lame);
  EXPECT_EQ(c.vertices_m, rm.vertices_m);
  EXPECT_EQ(c.tetrahedra, rm.tetrahedra);
  EXPECT_EQ(c.boundary_triangles, rm.boundary_triangles);
  EXPECT_EQ(std::vector<int>(c.interface_vertices.begin(), c.interface_vertices.end()),
            rm.interface);
  EXPECT_EQ(std::vector<int>(c.fixed_vertices.begin(), c.fixed_vertices.end()), rm.fixed);
  ASSERT_EQ(c.source_vertex_ids.size(), static_cast<Eigen::Index>(rm.to_mesh.size()));
  for (size_t i = 0; i < rm.to_mesh.size(); ++i)
    EXPECT_EQ(c.source_vertex_ids[static_cast<Eigen::Index>(i)], r.mesh.source_ids[rm.to_mesh[i]]);
  ASSERT_EQ(c.element_stiffness_n_per_m.rows(), static_cast<Eigen::Index>(rm.mesh_tets.size()));
  double k_scale = 0;
  for (const auto& K : rm.element_stiffness) k_scale = std::max(k_scale, K.cwiseAbs().maxCoeff());
  double element_difference = 0;
  for (Eigen::Index t = 0; t < c.element_stiffness_n_per_m.rows(); ++t)
    for (int i = 0; i < 12; ++i)
      for (int j = 0; j < 12; ++j)
        element_difference = std::max(element_difference,
                                      std::abs(c.element_stiffness_n_per_m(t, 12 * i + j) -
                                               rm.element_stiffness[static_cast<size_t>(t)](i, j)));
  EXPECT_LE(element_difference, 1e-12 * k_scale);  // stored as computed: equal bit for bit
  EXPECT_EQ(c.density_kg_m3, 1060);
  EXPECT_EQ(c.damping_per_s, 20);
  EXPECT_EQ(c.spec, far_top_box().describe());
  // The report stored in the file says what was cut.
  const nlohmann::json report = nlohmann::json::parse(r.model.report_json);
  EXPECT_EQ(report["cut_region"]["tetrahedra"], rm.mesh_tets.size());
  EXPECT_EQ(report["cut_region"]["organ_tetrahedra"], r.mesh.tetrahedra.rows());
  EXPECT_EQ(report["cut_region"]["interface_vertices"], rm.interface.size());
  EXPECT_EQ(report["mesh"]["compliance_vertices"], oc.vertices.size());

  // The tensors are the sums of the element blocks: K_R assembled here from
  // the file's element rows, dense, and its blocks compared (1e-12 of the
  // largest entry: sums of a few terms in another order).
  const Eigen::Index nr = c.vertices_m.rows();
  Eigen::MatrixXd KR = Eigen::MatrixXd::Zero(3 * nr, 3 * nr);
  for (Eigen::Index t = 0; t < c.tetrahedra.rows(); ++t)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            KR(3 * c.tetrahedra(t, a) + i, 3 * c.tetrahedra(t, b) + j) +=
                c.element_stiffness_n_per_m(t, 12 * (3 * a + i) + 3 * b + j);
  const double scale = KR.cwiseAbs().maxCoeff();
  double tensor_difference = 0;
  for (Eigen::Index v = 0; v < nr; ++v)
    tensor_difference = std::max(
        tensor_difference, (tensor(c.vertex_stiffness_n_per_m, v) - KR.block<3, 3>(3 * v, 3 * v))
                               .cwiseAbs()
                               .maxCoeff());
  std::map<std::pair<int, int>, Eigen::Index> edge_row;
  for (Eigen::Index e = 0; e < c.edges.rows(); ++e) {
    edge_row[{c.edges(e, 0), c.edges(e, 1)}] = e;
    tensor_difference = std::max(
        tensor_difference,
        (tensor(c.edge_stiffness_n_per_m, e) - KR.block<3, 3>(3 * c.edges(e, 0), 3 * c.edges(e, 1)))
            .cwiseAbs()
            .maxCoeff());
  }
  EXPECT_LE(tensor_difference, 1e-12 * scale);
  RecordProperty("tensor_relative_difference", scientific(tensor_difference / scale));
  // Every pair of vertices a tetrahedron holds is an edge, and no other.
  std::map<std::pair<int, int>, int> expected;
  for (Eigen::Index t = 0; t < c.tetrahedra.rows(); ++t)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        if (c.tetrahedra(t, a) < c.tetrahedra(t, b))
          expected[{c.tetrahedra(t, a), c.tetrahedra(t, b)}] = 1;
  EXPECT_EQ(expected.size(), edge_row.size());
  for (const auto& [ij, one] : expected) EXPECT_TRUE(edge_row.count(ij)) << ij.first;
}

TEST(PrecomputeRegion, SaysItsWarningsAndStoresThemInNoFile) {
  RegionRun r;
  // Every cell with i ≥ 2: two thirds of the tetrahedra; and a density in g/cm³.
  run(r, RegionSpec::box({kLx * 2 / kNx, 0, 0}, {kLx, kLy, kLz}), 1.06);
  ASSERT_GE(r.warnings.size(), 2u);
  bool fraction = false, density = false;
  for (const auto& w : r.warnings) {
    fraction |= w.find("tetrahedra (67 %)") != std::string::npos;
    density |= w.find("density 1.06 kg/m³") != std::string::npos &&
               w.find("give 1060") != std::string::npos;
  }
  EXPECT_TRUE(fraction);
  EXPECT_TRUE(density);
}

TEST(PrecomputeRegion, IsRefusedOnTheStreamedPathsWithOneMessage) {
  TempDir dir;
  PrecomputeJob job = testing::clamped_job(organ(), dir.path(), "organ", 85e3);
  job.cut_region = CutRegionJob{far_top_box()};
  job.method = Method::kSolves;
  expect_error<InputError>([&] { run_precompute(job, {}); },
                           {"cut region", "in memory only", "--method both"});
  job.method = Method::kBoth;
  job.shard.count = 2;
  expect_error<InputError>([&] { run_precompute(job, {}); }, {"cut region", "--shard"});
  EXPECT_FALSE(std::filesystem::exists(job.output));
}

TEST(PrecomputeRegion, ADensityOrDampingFromTheCommandLineIsCheckedToo) {
  // The job file's reader checks them with their line; validate_job() for
  // values that come from flags (--cut-density, --cut-damping).
  TempDir dir;
  PrecomputeJob job = testing::clamped_job(organ(), dir.path(), "organ", 85e3);
  job.cut_region = CutRegionJob{far_top_box(), -1, 20};
  expect_error<InputError>([&] { run_precompute(job, {}); }, {"cut region density -1", "> 0"});
  job.cut_region = CutRegionJob{far_top_box(), 1060, NAN};
  expect_error<InputError>([&] { run_precompute(job, {}); }, {"cut region damping nan", "≥ 0"});
  EXPECT_FALSE(std::filesystem::exists(job.output));
}

TEST(PrecomputeRegion, ARegionTheSplitRefusesIsReportedBeforeAnyWork) {
  TempDir dir;
  PrecomputeJob job = testing::clamped_job(organ(), dir.path(), "organ", 85e3);
  job.cut_region = CutRegionJob{RegionSpec::sphere({1, 1, 1}, 0.001)};
  expect_error<InputError>([&] { run_precompute(job, {}); },
                           {"holds no tetrahedron's centroid", "the mesh spans"});
  EXPECT_FALSE(std::filesystem::exists(job.output));
}

TEST(PrecomputeRegion, TheSampleCutJobRunsOnTheSampleOrgan) {
  // config/sample-organ-cut.toml as shipped, on a freshly made sample organ.
  TempDir dir;
  PrecomputeJob job =
      read_job_file(std::filesystem::path(PALPATE_SOURCE_DIR) / "config/sample-organ-cut.toml");
  write_sample_organ(dir / "organ.msh", 0.012);
  job.mesh_file = dir / "organ.msh";
  job.output = dir / "organ-cut.h5";
  std::vector<std::string> warnings;
  PrecomputeHooks hooks;
  hooks.warn = [&](const std::string& w) { warnings.push_back(w); };
  run_precompute(job, hooks);
  EXPECT_TRUE(warnings.empty()) << warnings.front();
  Eigen::MatrixXd G;
  const ComplianceModel m = read_compliance_file(job.output, &G);
  ASSERT_TRUE(m.cut_region);
  const CutRegionData& c = *m.cut_region;
  EXPECT_GT(c.tetrahedra.rows(), 0);
  EXPECT_EQ(c.fixed_vertices.size(), 0) << "the ball is far from the attachment";
  // Every region tetrahedron's centroid is in the 12 mm ball (1e-12 m: round-off).
  const Eigen::RowVector3d center(0.040, 0, -0.03464);
  for (Eigen::Index t = 0; t < c.tetrahedra.rows(); ++t) {
    Eigen::RowVector3d centroid = Eigen::RowVector3d::Zero();
    for (int k = 0; k < 4; ++k) centroid += c.vertices_m.row(c.tetrahedra(t, k)) / 4;
    EXPECT_LE((centroid - center).norm(), 0.012 + 1e-12) << t;
  }
  EXPECT_EQ(G.rows(), 3 * m.compliance_vertices.size());
  // A served model of it knows its region (palpated steps it: HybridRegion);
  // one without a region does not.
  const SurfaceModel served = load_surface_model("cut", job.output);
  EXPECT_EQ(served.cut_region_spec, c.spec);
  EXPECT_FALSE(served.cut_region_spec.empty());
  ASSERT_TRUE(served.cut_region);
  EXPECT_EQ(served.cut_region->tetrahedra, c.tetrahedra);
  job.cut_region.reset();
  job.output = dir / "organ.h5";
  run_precompute(job, hooks);
  EXPECT_TRUE(load_surface_model("whole", job.output).cut_region_spec.empty());
}

TEST(TensorMass, OneTetrahedronsTensorsAreItsBlocks) {
  Matrix43d P;
  P << 0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01;
  const Matrix12d K = element_stiffness(P, lame_parameters(85e3, 0.45));
  Eigen::MatrixX4i T(1, 4);
  T << 2, 0, 3, 1;  // vertex a of the tetrahedron is mesh vertex T(0, a)
  const TensorMassTensors t = tensor_mass_tensors(4, T, {K});
  ASSERT_EQ(t.edges.rows(), 6);
  for (int a = 0; a < 4; ++a)
    EXPECT_EQ(tensor(t.vertex_n_per_m, T(0, a)), Eigen::Matrix3d(K.block(3 * a, 3 * a, 3, 3)));
  for (Eigen::Index e = 0; e < 6; ++e) {
    int a = -1, b = -1;
    for (int k = 0; k < 4; ++k) {
      if (T(0, k) == t.edges(e, 0)) a = k;
      if (T(0, k) == t.edges(e, 1)) b = k;
    }
    EXPECT_LT(t.edges(e, 0), t.edges(e, 1));
    EXPECT_EQ(tensor(t.edge_n_per_m, e), Eigen::Matrix3d(K.block(3 * a, 3 * b, 3, 3)));
  }
}

}  // namespace
}  // namespace palpate
