// Format 1.1's additions for viewers: the softness map and the fixed flags in
// /visualization, the XDMF sidecars (volume and surface), their option, their
// errors, and that 1.0 files (without /visualization) still load, in the
// daemon's loader too.
// tests/file/xdmf_test.py checks the same files with independent readers (numpy,
// meshio).

#include "palpate/file/xdmf.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "palpate/core/error.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "support/box_job.hpp"
#include "support/expect_error.hpp"
#include "support/files.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::slurp;
using testing::TempDir;

size_t occurrences(const std::string& text, const std::string& what) {
  size_t count = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++count;
  return count;
}

// Turns a 1.1 file into the 1.0 layout: no /visualization, minor version 0.
void downgrade_to_1_0(const std::filesystem::path& path) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_GE(H5Ldelete(file, "/visualization", H5P_DEFAULT), 0);
  const hid_t attr = H5Aopen(file, "format_version_minor", H5P_DEFAULT);
  ASSERT_GE(attr, 0);
  const int zero = 0;
  EXPECT_GE(H5Awrite(attr, H5T_NATIVE_INT, &zero), 0);
  H5Aclose(attr);
  H5Fclose(file);
}

TEST(Softness, IsTheLargestEigenvalueOfEachDiagonalBlock) {
  // Blocks Q diag(λ) Qᵀ with known λ and random rotations Q, plus an
  // antisymmetric part (which G from `solves` has at round-off) that the
  // symmetric part ignores, and off-diagonal blocks that must not matter.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  const int n = 5;
  Eigen::MatrixXd G = Eigen::MatrixXd::NullaryExpr(3 * n, 3 * n, [&] { return 1e-3 * u(rng); });
  Eigen::VectorXd expected(n);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d lambda(1e-4 * (k + 1), 3e-4 * (k + 1), 2e-4 * (k + 1));  // m/N
    const Eigen::Matrix3d Q =
        Eigen::Quaterniond(Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized())
            .toRotationMatrix();
    Eigen::Matrix3d A;
    A << 0, 1, -2, -1, 0, 3, 2, -3, 0;
    G.block<3, 3>(3 * k, 3 * k) = Q * lambda.asDiagonal() * Q.transpose() + 1e-6 * A;
    expected[k] = lambda.maxCoeff();
  }
  const Eigen::VectorXd got = diagonal_block_largest_eigenvalues(G);
  ASSERT_EQ(got.size(), n);
  // A 3 × 3 symmetric eigensolver in double: a few ulps of the block's norm.
  for (int k = 0; k < n; ++k)
    EXPECT_NEAR(got[k], expected[k], 1e-14 * expected[k]) << "block " << k;
}

TEST(Softness, IsStoredPerVertexWithTheFixedFlags) {
  TempDir dir;
  const PrecomputeJob job = testing::box_job(dir.path());
  run_precompute(job, {});
  Eigen::MatrixXd G;
  const ComplianceModel m = read_compliance_file(job.output, &G);
  EXPECT_EQ(m.format_version_minor, kComplianceFormatMinor);
  ASSERT_EQ(m.softness_m_per_n.size(), m.vertices_m.rows());
  const Eigen::VectorXd blocks = diagonal_block_largest_eigenvalues(G);
  std::vector<bool> in_compliance(static_cast<size_t>(m.vertices_m.rows()), false);
  for (Eigen::Index a = 0; a < m.compliance_vertices.size(); ++a) {
    const int v = m.compliance_vertices[a];
    in_compliance[static_cast<size_t>(v)] = true;
    // Same G, same function: equal to the last bit (float64 storage).
    EXPECT_EQ(m.softness_m_per_n[v], blocks[a]) << "vertex " << v;
    EXPECT_GT(m.softness_m_per_n[v], 0.0);
  }
  for (Eigen::Index v = 0; v < m.vertices_m.rows(); ++v)
    if (!in_compliance[static_cast<size_t>(v)]) {
      EXPECT_EQ(m.softness_m_per_n[v], 0.0) << "vertex " << v;
    }
  // A 1 N push on the free end of a 100 mm soft box clamped at x = 0 moves
  // it millimetres, not metres or microns: the unit is m/N.
  EXPECT_GT(m.softness_m_per_n.maxCoeff(), 1e-4);
  EXPECT_LT(m.softness_m_per_n.maxCoeff(), 1.0);

  // /visualization/fixed, read with the C API: 1 exactly on fixed_vertex_ids.
  const hid_t file = H5Fopen(job.output.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t set = H5Dopen2(file, "/visualization/fixed", H5P_DEFAULT);
  ASSERT_GE(set, 0);
  const hid_t type = H5Dget_type(set);
  EXPECT_EQ(H5Tget_size(type), 1u);
  EXPECT_EQ(H5Tget_sign(type), H5T_SGN_2);
  H5Tclose(type);
  std::vector<signed char> fixed(static_cast<size_t>(m.vertices_m.rows()), -1);
  EXPECT_GE(H5Dread(set, H5T_NATIVE_SCHAR, H5S_ALL, H5S_ALL, H5P_DEFAULT, fixed.data()), 0);
  H5Dclose(set);
  H5Fclose(file);
  std::vector<signed char> expected(fixed.size(), 0);
  for (const int v : m.fixed_vertices) expected[static_cast<size_t>(v)] = 1;
  EXPECT_EQ(fixed, expected);
}

TEST(Softness, ComesFromTheFloat64GEvenWhenGIsStoredAsFloat32) {
  TempDir dir;
  PrecomputeJob job = testing::box_job(dir.path());
  job.method = Method::kCondensation;  // deterministic: same G both times
  run_precompute(job, {});
  PrecomputeJob single = job;
  single.output = dir / "box32.h5";
  single.precision = Precision::kFloat32;
  run_precompute(single, {});
  Eigen::MatrixXd G32;
  const ComplianceModel m64 = read_compliance_file(job.output, nullptr);
  const ComplianceModel m32 = read_compliance_file(single.output, &G32);
  ASSERT_EQ(m32.precision, Precision::kFloat32);
  // The float64 file's softness (to round-off: two runs of the same
  // condensation; the threaded BLAS may not repeat the last bit) ...
  ASSERT_EQ(m32.softness_m_per_n.size(), m64.softness_m_per_n.size());
  for (Eigen::Index v = 0; v < m64.softness_m_per_n.size(); ++v)
    EXPECT_NEAR(m32.softness_m_per_n[v], m64.softness_m_per_n[v], 1e-12 * m64.softness_m_per_n[v])
        << v;
  // ... which the rounded G would not give (relative error ~1e-8 there).
  const Eigen::VectorXd from_rounded = diagonal_block_largest_eigenvalues(G32);
  double worst = 0;
  for (Eigen::Index a = 0; a < from_rounded.size(); ++a) {
    const double s = m32.softness_m_per_n[m32.compliance_vertices[a]];
    worst = std::max(worst, std::abs(from_rounded[a] - s) / s);
  }
  EXPECT_GT(worst, 1e-12);
  EXPECT_LT(worst, 1e-6);
}

TEST(ComplianceFile, Version1_0FilesStillLoadInTheReaderAndTheDaemonsLoader) {
  TempDir dir;
  const auto path = testing::write_box_compliance(dir.path());
  Eigen::MatrixXd G11;
  read_compliance_file(path, &G11);
  std::filesystem::copy_file(path, dir / "old.h5");
  downgrade_to_1_0(dir / "old.h5");

  Eigen::MatrixXd G10;
  const ComplianceModel old = read_compliance_file(dir / "old.h5", &G10);
  EXPECT_EQ(old.format_version_minor, 0);
  EXPECT_EQ(old.softness_m_per_n.size(), 0);
  EXPECT_EQ(G10, G11);
  const SurfaceModel served = load_surface_model("old", dir / "old.h5");  // palpated's loader
  EXPECT_EQ(served.G, G11);
  EXPECT_EQ(served.compliance_vertex_count() * 3, G11.rows());
}

TEST(ComplianceFile, RefusesAMalformedSoftnessDataset) {
  TempDir dir;
  const auto path = testing::write_box_compliance(dir.path());
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_GE(H5Ldelete(file, "/visualization/softness", H5P_DEFAULT), 0);
  hsize_t dims[1] = {3};
  const hid_t space = H5Screate_simple(1, dims, nullptr);
  const hid_t set = H5Dcreate2(file, "/visualization/softness", H5T_IEEE_F64LE, space, H5P_DEFAULT,
                               H5P_DEFAULT, H5P_DEFAULT);
  const double values[3] = {0, 0, 0};
  EXPECT_GE(H5Dwrite(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values), 0);
  H5Dclose(set);
  H5Sclose(space);
  H5Fclose(file);
  expect_error<InputError>([&] { read_compliance_file(path, nullptr); },
                           {"/visualization/softness", "has 3 entries, expected one per vertex"});
}

TEST(XdmfSidecar, IsWrittenNextToTheFileAndRefersToItsDatasets) {
  TempDir dir;
  const PrecomputeJob job = testing::box_job(dir.path());
  const auto report = run_precompute(job, {});
  const auto volume = dir / "box.xdmf";
  const auto surface = dir / "box.surface.xdmf";
  EXPECT_EQ(xdmf_sidecar_path(job.output), volume);
  EXPECT_EQ(xdmf_surface_sidecar_path(job.output), surface);
  EXPECT_EQ(report.output->xdmf.value(), volume.string());
  ASSERT_TRUE(std::filesystem::exists(volume));
  ASSERT_TRUE(std::filesystem::exists(surface));
  const ComplianceModel m = read_compliance_file(job.output, nullptr);
  const std::string v = slurp(volume), s = slurp(surface);
  EXPECT_EQ(v, xdmf_document(m, "box.h5"));
  EXPECT_EQ(s, xdmf_surface_document(m, "box.h5"));
  const auto count = [](Eigen::Index k) {
    std::string quoted(1, '"');
    quoted += std::to_string(k);
    quoted += '"';
    return quoted;
  };
  // One Uniform grid per file (what meshio.read takes), no collection; every
  // array by relative file name; the node arrays in both.
  for (const std::string* text : {&v, &s}) {
    EXPECT_NE(text->find("<Xdmf Version=\"3.0\">"), std::string::npos);
    EXPECT_EQ(occurrences(*text, "<Grid "), 1u);
    EXPECT_EQ(occurrences(*text, "GridType=\"Uniform\""), 1u);
    EXPECT_EQ(occurrences(*text, "Collection"), 0u);
    EXPECT_EQ(occurrences(*text, "<Topology "), 1u);
    EXPECT_EQ(occurrences(*text, "box.h5:/mesh/vertices</DataItem>"), 1u);
    EXPECT_EQ(occurrences(*text, "box.h5:/visualization/softness</DataItem>"), 1u);
    // int8 is "Char" in XDMF 3: Xdmf3 reads "Int" with Precision 1 as int32.
    EXPECT_EQ(occurrences(*text, "DataType=\"Char\" Precision=\"1\" Dimensions=" +
                                     count(m.vertices_m.rows()) +
                                     " Format=\"HDF\">box.h5:/visualization/fixed</DataItem>"),
              1u);
    EXPECT_EQ(occurrences(*text, dir.path().string()), 0u) << "no absolute path";
    EXPECT_NE(text->find("Dimensions=\"" + std::to_string(m.vertices_m.rows()) + " 3\""),
              std::string::npos);
  }
  EXPECT_NE(v.find("TopologyType=\"Tetrahedron\" NumberOfElements=" + count(m.tetrahedra.rows())),
            std::string::npos);
  EXPECT_NE(v.find("box.h5:/mesh/tetrahedron_material</DataItem>"), std::string::npos);
  EXPECT_NE(
      s.find("TopologyType=\"Triangle\" NumberOfElements=" + count(m.surface_triangles.rows())),
      std::string::npos);
  EXPECT_EQ(s.find("Center=\"Cell\""), std::string::npos);
  // Each names the other in its comment.
  EXPECT_NE(v.find("box.surface.xdmf"), std::string::npos);
  EXPECT_NE(s.find("box.xdmf"), std::string::npos);
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    EXPECT_EQ(entry.path().filename().string().find(".tmp-"), std::string::npos) << entry.path();
}

TEST(XdmfSidecar, EscapesTheFileNameAndKeepsCommentsWellFormed) {
  ComplianceModel m;
  m.vertices_m.resize(4, 3);
  m.tetrahedra.resize(1, 4);
  m.surface_triangles.resize(4, 3);
  m.materials = {
      {"organ", 1e5, 0.45}, {"odd--name-", 2e5, 0.45}, {std::string("bad") + '\xff', 1e5, 0.4}};
  const std::string text = xdmf_document(m, "a&b<c>.h5");
  const std::string surface = xdmf_surface_document(m, "a&b<c>--.h5");
  EXPECT_NE(text.find(">a&amp;b&lt;c&gt;.h5:/mesh/vertices<"), std::string::npos);
  EXPECT_NE(surface.find(">a&amp;b&lt;c&gt;--.h5:/mesh/vertices<"), std::string::npos);
  // A comment holds no "--" but its delimiters, and only valid UTF-8.
  for (const std::string* doc : {&text, &surface}) {
    const size_t open = doc->find("<!--"), close = doc->find("-->");
    ASSERT_NE(open, std::string::npos);
    ASSERT_NE(close, std::string::npos);
    EXPECT_EQ(doc->substr(open + 4, close - open - 4).find("--"), std::string::npos);
    EXPECT_EQ(doc->find('\xff'), std::string::npos);
  }
  EXPECT_NE(text.find("1 = odd- -name-"), std::string::npos);
}

TEST(XdmfSidecar, CanBeTurnedOffByTheJobFileAndThenWarnsAboutAStaleOne) {
  TempDir dir;
  PrecomputeJob job = testing::box_job(dir.path());
  job.write_xdmf = false;
  std::ofstream(dir / "job.toml") << to_toml(job);
  EXPECT_NE(slurp(dir / "job.toml").find("xdmf = false"), std::string::npos);
  const PrecomputeJob back = read_job_file(dir / "job.toml");
  EXPECT_FALSE(back.write_xdmf);
  const auto report = run_precompute(back, {});
  EXPECT_FALSE(report.output->xdmf.has_value());
  EXPECT_TRUE(std::filesystem::exists(job.output));
  EXPECT_FALSE(std::filesystem::exists(dir / "box.xdmf"));
  EXPECT_FALSE(std::filesystem::exists(dir / "box.surface.xdmf"));

  std::ofstream(dir / "box.xdmf") << "from an earlier run";
  std::vector<std::string> warnings;
  PrecomputeHooks hooks;
  hooks.warn = [&](const std::string& s) { warnings.push_back(s); };
  run_precompute(back, hooks);
  EXPECT_EQ(slurp(dir / "box.xdmf"), "from an earlier run");  // left alone
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("box.xdmf is left from an earlier run"), std::string::npos)
      << warnings[0];

  std::ofstream(dir / "bad.toml") << "[output]\nfile = \"x.h5\"\nxdmf = \"yes\"\n";
  expect_error<InputError>([&] { read_job_file(dir / "bad.toml"); },
                           {"bad.toml:3", "output.xdmf", "expected true or false"});
}

TEST(XdmfSidecar, OutputNamesItCannotDescribeAreRefusedBeforeAnyWork) {
  TempDir dir;
  PrecomputeJob job = testing::box_job(dir.path());
  job.output = dir / "organ.xdmf";
  expect_error<InputError>([&] { run_precompute(job, {}); },
                           {"organ.xdmf", "its own XDMF sidecar", "--no-xdmf"});
  job.output = dir / "organ:1.h5";
  expect_error<InputError>([&] { run_precompute(job, {}); },
                           {"'organ:1.h5'", "contains ':'", "--no-xdmf"});
  job.output = dir / (std::string("organ") + '\xff' + ".h5");
  expect_error<InputError>([&] { run_precompute(job, {}); }, {"not valid UTF-8", "--no-xdmf"});
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    EXPECT_EQ(entry.path().filename(), "box.msh") << "nothing written";
  // Without a sidecar the same names are fine.
  job.write_xdmf = false;
  job.output = dir / "organ:1.h5";
  run_precompute(job, {});
  EXPECT_TRUE(std::filesystem::exists(job.output));
}

}  // namespace
}  // namespace palpate
