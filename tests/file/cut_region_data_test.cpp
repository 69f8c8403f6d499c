// The compliance file's /cut_region (format 1.3) on a small hand-made
// model: it round-trips bit for bit, its own digest covers it while
// content_sha256 stays what a 1.2 reader verifies, each malformed part is
// refused naming its dataset, a file without it is written as before (1.2's
// datasets, the same digest), and a 1.2 file still loads.

#include "palpate/file/cut_region_data.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <Eigen/Dense>
#include <functional>
#include <string>

#include "palpate/core/error.hpp"
#include "palpate/file/compliance_file.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::TempDir;

/// content_sha256 of AFileWithoutARegionKeepsItsDigestAndA1_2FileLoads's
/// file as palpate 768678a (format 1.2, before /cut_region) wrote it: its
/// write_compliance_file() built alone and run on the same model and G.
constexpr const char* kDigestBeforeCutRegion =
    "sha256:6641d78d8576140d4019b456ded119da3909bac6b1a36d214bc214fa256fecfe";

/// The support's two tetrahedra (compliance_file_test.cpp's model), with
/// the metadata the recorded digest was taken with.
ComplianceModel two_tetrahedra() {
  ComplianceModel m = testing::two_tetrahedra_model();
  m.method = "both";
  m.producer = "palpate unit test";
  m.created_utc = "2026-11-26T00:00:00Z";
  m.input_hash = "sha256:" + std::string(64, 'b');
  m.material_summary = "organ";
  return m;
}

/// A region of one tetrahedron (made-up but consistent values): its four
/// vertices, the stiffness entries distinct so that a transposition shows.
CutRegionData one_tetrahedron_region() {
  CutRegionData c;
  c.vertices_m.resize(4, 3);
  c.vertices_m << 0.01, 0.01, 0.01, 0.02, 0.01, 0.01, 0.01, 0.02, 0.01, 0.01, 0.01, 0.02;
  c.source_vertex_ids.resize(4);
  c.source_vertex_ids << 4, 5, 6, 7;
  c.tetrahedra.resize(1, 4);
  c.tetrahedra << 0, 1, 2, 3;
  c.tet_material = Eigen::VectorXi::Zero(1);
  c.element_stiffness_n_per_m.resize(1, kElementStiffnessValues);
  for (int k = 0; k < kElementStiffnessValues; ++k) c.element_stiffness_n_per_m(0, k) = 100.0 + k;
  c.vertex_stiffness_n_per_m = Eigen::MatrixXd::Zero(4, kTensorValues);
  for (int v = 0; v < 4; ++v) c.vertex_stiffness_n_per_m.row(v) << 3, 1, 0, 1, 3, 0, 0, 0, 3.5 + v;
  c.edges.resize(6, 2);
  c.edges << 0, 1, 0, 2, 0, 3, 1, 2, 1, 3, 2, 3;
  c.edge_stiffness_n_per_m.resize(6, kTensorValues);
  for (int e = 0; e < 6; ++e)
    for (int k = 0; k < kTensorValues; ++k) c.edge_stiffness_n_per_m(e, k) = -1.0 - e - 0.1 * k;
  c.boundary_triangles.resize(4, 3);
  c.boundary_triangles << 1, 2, 3, 0, 3, 2, 0, 1, 3, 0, 2, 1;
  c.interface_vertices.resize(3);
  c.interface_vertices << 0, 1, 2;
  c.interface_compliance_index.resize(3);
  c.interface_compliance_index << 0, 2, 3;
  c.fixed_vertices.resize(0);
  c.density_kg_m3 = 1060;
  c.damping_per_s = 20;
  c.spec = "sphere at (0.01, 0.01, 0.01) m of radius 0.012 m";
  return c;
}

Eigen::MatrixXd spd_G() {
  Eigen::MatrixXd A = Eigen::MatrixXd::Random(12, 12);
  return 1e-4 * (A * A.transpose() + 12 * Eigen::MatrixXd::Identity(12, 12));
}

void set_minor_version(const std::filesystem::path& path, int minor) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t attr = H5Aopen(file, "format_version_minor", H5P_DEFAULT);
  ASSERT_GE(attr, 0);
  EXPECT_GE(H5Awrite(attr, H5T_NATIVE_INT, &minor), 0);
  H5Aclose(attr);
  H5Fclose(file);
}

TEST(CutRegionFile, RoundTripsBitForBitAndTheDigestCoversIt) {
  TempDir dir;
  ComplianceModel with = two_tetrahedra();
  with.cut_region = one_tetrahedron_region();
  const Eigen::MatrixXd G = spd_G();
  write_compliance_file(dir / "cut.h5", with, G);
  Eigen::MatrixXd G_read;
  const ComplianceModel read = read_compliance_file(dir / "cut.h5", &G_read);
  EXPECT_EQ(read.format_version_minor, 3);
  ASSERT_TRUE(read.cut_region);
  const CutRegionData& a = *read.cut_region;
  const CutRegionData& b = *with.cut_region;
  EXPECT_EQ(a.vertices_m, b.vertices_m);
  EXPECT_EQ(a.source_vertex_ids, b.source_vertex_ids);
  EXPECT_EQ(a.tetrahedra, b.tetrahedra);
  EXPECT_EQ(a.tet_material, b.tet_material);
  EXPECT_EQ(a.element_stiffness_n_per_m, b.element_stiffness_n_per_m);
  EXPECT_EQ(a.vertex_stiffness_n_per_m, b.vertex_stiffness_n_per_m);
  EXPECT_EQ(a.edges, b.edges);
  EXPECT_EQ(a.edge_stiffness_n_per_m, b.edge_stiffness_n_per_m);
  EXPECT_EQ(a.boundary_triangles, b.boundary_triangles);
  EXPECT_EQ(a.interface_vertices, b.interface_vertices);
  EXPECT_EQ(a.interface_compliance_index, b.interface_compliance_index);
  EXPECT_EQ(a.fixed_vertices, b.fixed_vertices);
  EXPECT_EQ(a.density_kg_m3, b.density_kg_m3);
  EXPECT_EQ(a.damping_per_s, b.damping_per_s);
  EXPECT_EQ(a.spec, b.spec);
  EXPECT_EQ(G_read, G);

  // The same model without the region has the same content_sha256: it
  // covers the datasets a 1.2 reader knows (which then verifies a file
  // with a region), and the region has its own digest, which a file whose
  // region is changed after writing fails.
  ComplianceModel without = two_tetrahedra();
  write_compliance_file(dir / "plain.h5", without, G);
  const ComplianceModel plain = read_compliance_file(dir / "plain.h5", &G_read);
  EXPECT_FALSE(plain.cut_region);
  EXPECT_TRUE(plain.cut_region_sha256.empty());
  EXPECT_EQ(plain.content_sha256, read.content_sha256);
  EXPECT_EQ(read.cut_region_sha256.rfind("sha256:", 0), 0u);
  EXPECT_EQ(read.cut_region_sha256.size(), 7u + 64u);
  const hid_t file = H5Fopen((dir / "cut.h5").c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t set = H5Dopen2(file, "/cut_region/density_kg_m3", H5P_DEFAULT);
  const double other = 1000;
  EXPECT_GE(H5Dwrite(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, &other), 0);
  H5Dclose(set);
  H5Fclose(file);
  expect_error<InputError>([&] { read_compliance_file(dir / "cut.h5", &G_read); },
                           {"cut.h5", "cut_region_sha256", "/cut_region datasets", "corrupt"});
  // Without G (no digest verified), it reads.
  EXPECT_EQ(read_compliance_file(dir / "cut.h5", nullptr).cut_region->density_kg_m3, 1000);
}

TEST(CutRegionFile, AFileWithoutARegionKeepsItsDigestAndA1_2FileLoads) {
  TempDir dir;
  // The digest of a file without a region, recorded from the writer before
  // /cut_region existed (palpate 768678a, format 1.2), for this model and G:
  // a file without a region is written exactly as before.
  ComplianceModel m = two_tetrahedra();
  Eigen::MatrixXd G(12, 12);
  for (Eigen::Index i = 0; i < 12; ++i)
    for (Eigen::Index j = 0; j < 12; ++j) G(i, j) = 1e-4 / (1.0 + i + j) + (i == j ? 1e-3 : 0.0);
  write_compliance_file(dir / "plain.h5", m, G);
  Eigen::MatrixXd G_read;
  const ComplianceModel now = read_compliance_file(dir / "plain.h5", &G_read);
  EXPECT_EQ(now.content_sha256, kDigestBeforeCutRegion);

  // A 1.2 file (what the writer made before 1.3: the same datasets, minor 2)
  // loads, its digest verified, with no region.
  set_minor_version(dir / "plain.h5", 2);
  const ComplianceModel old = read_compliance_file(dir / "plain.h5", &G_read);
  EXPECT_EQ(old.format_version_minor, 2);
  EXPECT_FALSE(old.cut_region);
  EXPECT_EQ(G_read, G);
}

TEST(CutRegionFile, EachMalformedPartIsRefusedNamingItsDataset) {
  const std::vector<std::pair<std::function<void(CutRegionData&)>, std::vector<std::string>>>
      cases = {
          {[](CutRegionData& c) { c.tetrahedra(0, 1) = 9; },
           {"/cut_region/tetrahedra", "entry 1 is 9", "0..3"}},
          {[](CutRegionData& c) { std::swap(c.tetrahedra(0, 1), c.tetrahedra(0, 2)); },
           {"/cut_region/tetrahedra", "tetrahedron 0", "volume > 0"}},
          {[](CutRegionData& c) { c.vertices_m(2, 1) = NAN; },
           {"/cut_region/vertices", "non-finite"}},
          {[](CutRegionData& c) { c.element_stiffness_n_per_m(0, 7) = INFINITY; },
           {"/cut_region/element_stiffness", "non-finite"}},
          {[](CutRegionData& c) { c.vertex_stiffness_n_per_m(1, 1) = 5; },
           {"/cut_region/vertex_stiffness", "vertex 1", "not symmetric"}},
          {[](CutRegionData& c) { std::swap(c.edges(0, 0), c.edges(0, 1)); },
           {"/cut_region/edges", "edge 0", "i < j"}},
          {[](CutRegionData& c) { c.edge_stiffness_n_per_m.conservativeResize(5, 9); },
           {"/cut_region/edge_stiffness", "has 5 rows, expected 6"}},
          {[](CutRegionData& c) { c.interface_compliance_index[2] = 4; },
           {"/cut_region/interface_compliance_index", "entry 2 is 4", "/compliance/vertex_ids"}},
          {[](CutRegionData& c) { c.interface_compliance_index.conservativeResize(2); },
           {"/cut_region/interface_compliance_index", "one per interface vertex"}},
          {[](CutRegionData& c) { c.tet_material[0] = 1; },
           {"/cut_region/tetrahedron_material", "entry 0 is 1"}},
          {[](CutRegionData& c) { c.density_kg_m3 = 0; },
           {"/cut_region/density_kg_m3", "> 0 kg/m³"}},
          {[](CutRegionData& c) { c.damping_per_s = NAN; }, {"/cut_region/damping_per_s", "≥ 0"}},
      };
  TempDir dir;
  for (size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE(i);
    ComplianceModel m = two_tetrahedra();
    m.cut_region = one_tetrahedron_region();
    cases[i].first(*m.cut_region);
    const auto path = dir / ("bad" + std::to_string(i) + ".h5");
    write_compliance_file(path, m, spd_G());
    Eigen::MatrixXd G;
    std::vector<std::string> fragments = cases[i].second;
    fragments.push_back(path.filename().string());
    try {
      read_compliance_file(path, &G);
      ADD_FAILURE() << "not refused";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      for (const auto& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << msg;
    }
  }
}

}  // namespace
}  // namespace palpate
