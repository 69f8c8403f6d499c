// The compliance file (write_compliance_file / read_compliance_file) on a
// small hand-made model: every field and G bit for bit, the row-major layout
// read back with the HDF5 C API, the content digest recomputed from the
// specification (docs/compliance-file.md), float32 storage, the row-band
// writer, damaged and missing files, and failed writes that leave nothing.

#include "palpate/file/compliance_file.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/file/hash.hpp"
#include "support/expect_error.hpp"
#include "support/files.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::listing;
using testing::slurp;
using testing::TempDir;

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// The support's two tetrahedra sharing face (1, 2, 3): vertex 0 fixed, the
/// other four the compliance vertices (n = 4, G 12 × 12); here with two
/// materials, source ids that are not the identity and distinct softness.
ComplianceModel small_model() {
  ComplianceModel m = testing::two_tetrahedra_model();
  m.tet_material << 0, 1;
  m.materials = {{"organ", 85e3, 0.45}, {"tumeur dûre", 3.4e5, 0.49}};
  m.source_vertex_ids << 7, 1, 2, 3, 9;
  m.softness_m_per_n.resize(5);
  m.softness_m_per_n << 0, 1.25e-4, 2.5e-4, 3.75e-4, 5e-4;
  m.method = "solves";
  m.producer = "palpate unit test";
  m.created_utc = "2024-01-02T03:04:05Z";
  m.input_hash = "sha256:" + std::string(64, 'a');
  m.material_summary = "organ: E = 85000 Pa, nu = 0.45; tumeur dûre: E = 340000 Pa, nu = 0.49";
  m.job_toml = "mesh = \"/x/organ.msh\"\n[material]\nyoung_modulus_pa = 85000\n";
  m.report_json = R"({"columns":{"total":12}})";
  return m;
}

/// A random SPD 3n × 3n matrix of entries ~1e-4 m/N (a compliance's scale).
Eigen::MatrixXd random_spd_G(Eigen::Index n3, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  Eigen::MatrixXd A(n3, n3);
  for (Eigen::Index j = 0; j < n3; ++j)
    for (Eigen::Index i = 0; i < n3; ++i) A(i, j) = value(rng);
  return 1e-4 * (A * A.transpose() + static_cast<double>(n3) * Eigen::MatrixXd::Identity(n3, n3));
}

bool same_bits(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

/// Names in @p dir (to see that nothing, not even a temporary, is left).
/// content_sha256 recomputed from the model and G in memory, following
/// docs/compliance-file.md ("content_sha256: what is hashed"), not the writer.
std::string expected_digest(const ComplianceModel& m, const Eigen::MatrixXd& G) {
  Sha256 h;
  auto header = [&](const std::string& path, std::vector<Eigen::Index> dims) {
    std::string line = path + " ";
    for (std::size_t i = 0; i < dims.size(); ++i) {
      if (i > 0) line += 'x';
      line += std::to_string(dims[i]);
    }
    h.update(line + "\n");
  };
  auto matrix = [&](const std::string& path, const auto& M) {
    using Scalar = typename std::decay_t<decltype(M)>::Scalar;
    const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = M;
    header(path, {M.rows(), M.cols()});
    h.update(rows.data(), sizeof(Scalar) * static_cast<std::size_t>(rows.size()));
  };
  auto vector = [&](const std::string& path, const auto& v) {
    header(path, {v.size()});
    h.update(v.data(), sizeof(*v.data()) * static_cast<std::size_t>(v.size()));
  };
  matrix("/mesh/vertices", m.vertices_m);
  matrix("/mesh/tetrahedra", m.tetrahedra);
  vector("/mesh/tetrahedron_material", m.tet_material);
  matrix("/mesh/surface_triangles", m.surface_triangles);
  vector("/mesh/fixed_vertex_ids", m.fixed_vertices);
  vector("/mesh/source_vertex_ids", m.source_vertex_ids);
  header("/material/name", {static_cast<Eigen::Index>(m.materials.size())});
  for (const auto& mat : m.materials) h.update(mat.name.c_str(), mat.name.size() + 1);
  Eigen::VectorXd E(static_cast<Eigen::Index>(m.materials.size())), nu(E.size());
  for (std::size_t i = 0; i < m.materials.size(); ++i) {
    E[static_cast<Eigen::Index>(i)] = m.materials[i].young_modulus_pa;
    nu[static_cast<Eigen::Index>(i)] = m.materials[i].poisson_ratio;
  }
  vector("/material/young_modulus_pa", E);
  vector("/material/poisson_ratio", nu);
  vector("/compliance/vertex_ids", m.compliance_vertices);
  if (m.precision == Precision::kFloat32)
    matrix("/compliance/G", Eigen::MatrixXf(G.cast<float>()));
  else
    matrix("/compliance/G", G);
  vector("/visualization/softness", m.softness_m_per_n);
  Eigen::Matrix<std::int8_t, Eigen::Dynamic, 1> fixed =
      Eigen::Matrix<std::int8_t, Eigen::Dynamic, 1>::Zero(m.vertices_m.rows());
  for (int v : m.fixed_vertices) fixed[v] = 1;
  vector("/visualization/fixed", fixed);
  return h.hex_digest();
}

/// /compliance/G as stored, row-major, in double (HDF5 converts float32).
std::vector<double> raw_G(const std::filesystem::path& path, hsize_t* rows, hsize_t* cols,
                          std::size_t* stored_size) {
  std::vector<double> values;
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  EXPECT_GE(file, 0);
  const hid_t set = H5Dopen2(file, "/compliance/G", H5P_DEFAULT);
  const hid_t space = H5Dget_space(set);
  hsize_t dims[2] = {0, 0};
  H5Sget_simple_extent_dims(space, dims, nullptr);
  const hid_t type = H5Dget_type(set);
  *stored_size = H5Tget_size(type);
  values.resize(dims[0] * dims[1]);
  EXPECT_GE(H5Dread(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), 0);
  *rows = dims[0];
  *cols = dims[1];
  H5Tclose(type);
  H5Sclose(space);
  H5Dclose(set);
  H5Fclose(file);
  return values;
}

/// Overwrites entry (row, col) of a 2-D float64 dataset in place.
void overwrite(const std::filesystem::path& path, const char* dataset, hsize_t row, hsize_t col,
               double value) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t set = H5Dopen2(file, dataset, H5P_DEFAULT);
  ASSERT_GE(set, 0);
  const hid_t file_space = H5Dget_space(set);
  hsize_t start[2] = {row, col}, count[2] = {1, 1};
  EXPECT_GE(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr), 0);
  const hid_t mem_space = H5Screate_simple(2, count, nullptr);
  EXPECT_GE(H5Dwrite(set, H5T_NATIVE_DOUBLE, mem_space, file_space, H5P_DEFAULT, &value), 0);
  H5Sclose(mem_space);
  H5Sclose(file_space);
  H5Dclose(set);
  H5Fclose(file);
}

void expect_same_model(const ComplianceModel& read, const ComplianceModel& written) {
  EXPECT_EQ(read.vertices_m, written.vertices_m);
  EXPECT_EQ(read.tetrahedra, written.tetrahedra);
  EXPECT_EQ(read.tet_material, written.tet_material);
  ASSERT_EQ(read.materials.size(), written.materials.size());
  for (std::size_t i = 0; i < read.materials.size(); ++i) {
    EXPECT_EQ(read.materials[i].name, written.materials[i].name);
    EXPECT_EQ(read.materials[i].young_modulus_pa, written.materials[i].young_modulus_pa);
    EXPECT_EQ(read.materials[i].poisson_ratio, written.materials[i].poisson_ratio);
  }
  EXPECT_EQ(read.surface_triangles, written.surface_triangles);
  EXPECT_EQ(read.fixed_vertices, written.fixed_vertices);
  EXPECT_EQ(read.source_vertex_ids, written.source_vertex_ids);
  EXPECT_EQ(read.compliance_vertices, written.compliance_vertices);
  EXPECT_EQ(read.softness_m_per_n, written.softness_m_per_n);
  EXPECT_EQ(read.precision, written.precision);
  EXPECT_EQ(read.method, written.method);
  EXPECT_EQ(read.producer, written.producer);
  EXPECT_EQ(read.created_utc, written.created_utc);
  EXPECT_EQ(read.input_hash, written.input_hash);
  EXPECT_EQ(read.material_summary, written.material_summary);
  EXPECT_EQ(read.job_toml, written.job_toml);
  EXPECT_EQ(read.report_json, written.report_json);
  EXPECT_EQ(read.format_version_minor, kComplianceFormatMinor);
}

TEST(ComplianceFileUnit, RoundTripsEveryFieldAndGBitForBit) {
  TempDir dir;
  const ComplianceModel model = small_model();
  Eigen::MatrixXd G = random_spd_G(12, 1);
  // Values whose bits a conversion would change: a subnormal, −0 and the extremes.
  G(0, 11) = std::numeric_limits<double>::denorm_min();
  G(11, 0) = -0.0;
  G(5, 6) = std::numeric_limits<double>::max();
  G(6, 5) = std::numeric_limits<double>::lowest();
  const auto path = dir / "model.h5";
  std::vector<std::pair<long, long>> progress;
  write_compliance_file(path, model, G,
                        [&](long done, long total) { progress.emplace_back(done, total); });
  ASSERT_FALSE(progress.empty());
  EXPECT_EQ(progress.back(), std::make_pair(12L, 12L));

  Eigen::MatrixXd G_read;
  const ComplianceModel read = read_compliance_file(path, &G_read);
  expect_same_model(read, model);
  EXPECT_TRUE(same_bits(G_read, G));
  EXPECT_EQ(read.content_sha256, expected_digest(model, G))
      << "the digest of docs/compliance-file.md, recomputed here";
  EXPECT_EQ(read.content_sha256.rfind("sha256:", 0), 0u);

  // The file stores G row-major, row i of the file being row i of G: G is
  // not symmetric here, so a transposition would show.
  ASSERT_NE(G(0, 11), G(11, 0));
  hsize_t rows = 0, cols = 0;
  std::size_t bytes = 0;
  const std::vector<double> raw = raw_G(path, &rows, &cols, &bytes);
  ASSERT_EQ(rows, 12u);
  ASSERT_EQ(cols, 12u);
  EXPECT_EQ(bytes, 8u);
  for (Eigen::Index i = 0; i < 12; ++i)
    for (Eigen::Index j = 0; j < 12; ++j)
      ASSERT_EQ(std::memcmp(&raw[static_cast<std::size_t>(12 * i + j)], &G(i, j), 8), 0)
          << i << ", " << j;

  // Reading without G: the same model; with the 3-argument form, a float64
  // file fills G and leaves G32 empty.
  expect_same_model(read_compliance_file(path, nullptr), model);
  Eigen::MatrixXd G64;
  Eigen::MatrixXf G32 = Eigen::MatrixXf::Ones(2, 2);
  read_compliance_file(path, &G64, &G32);
  EXPECT_TRUE(same_bits(G64, G));
  EXPECT_EQ(G32.size(), 0);
  // Nothing but the file in the directory: no temporary left.
  EXPECT_EQ(listing(dir.path()), std::vector<std::string>{"model.h5"});
}

TEST(ComplianceFileUnit, Float32StorageRoundsGOnceAndCanBeKeptAsStored) {
  TempDir dir;
  ComplianceModel model = small_model();
  model.precision = Precision::kFloat32;
  const Eigen::MatrixXd G = random_spd_G(12, 2);
  const auto path = dir / "model32.h5";
  write_compliance_file(path, model, G);

  hsize_t rows = 0, cols = 0;
  std::size_t bytes = 0;
  raw_G(path, &rows, &cols, &bytes);
  EXPECT_EQ(bytes, 4u) << "stored as float32";

  // In double: each entry rounded to the nearest float, so within float32's
  // unit roundoff 2⁻²⁴ relative (entries are ~1e-4, far from float's
  // subnormals); and exactly the float the C++ conversion gives.
  Eigen::MatrixXd G_read;
  const ComplianceModel read = read_compliance_file(path, &G_read);
  EXPECT_EQ(read.precision, Precision::kFloat32);
  expect_same_model(read, model);
  const double u32 = std::ldexp(1.0, -24);
  ASSERT_EQ(G_read.rows(), 12);
  for (Eigen::Index j = 0; j < 12; ++j)
    for (Eigen::Index i = 0; i < 12; ++i) {
      EXPECT_LE(std::abs(G_read(i, j) - G(i, j)), u32 * std::abs(G(i, j))) << i << ", " << j;
      EXPECT_EQ(G_read(i, j), static_cast<double>(static_cast<float>(G(i, j))));
    }
  EXPECT_GT((G_read - G).cwiseAbs().maxCoeff(), 0) << "it was rounded";
  EXPECT_EQ(read.content_sha256, expected_digest(model, G)) << "over the float32 bytes";

  // Kept as stored: G32 filled with the same floats, G left empty.
  Eigen::MatrixXd G64 = Eigen::MatrixXd::Ones(3, 3);
  Eigen::MatrixXf G32;
  read_compliance_file(path, &G64, &G32);
  EXPECT_EQ(G64.size(), 0);
  ASSERT_EQ(G32.rows(), 12);
  EXPECT_EQ(G32, Eigen::MatrixXf(G.cast<float>()));
}

TEST(ComplianceFileUnit, TheRowBandWriterWritesTheSameFileContent) {
  TempDir dir;
  for (const Precision precision : {Precision::kFloat64, Precision::kFloat32}) {
    ComplianceModel model = small_model();
    model.precision = precision;
    const Eigen::MatrixXd G = random_spd_G(12, 3);
    const auto whole = dir / "whole.h5", bands = dir / "bands.h5";
    write_compliance_file(whole, model, G);
    // Bands of 5 rows: 5, 5 and a last band of 2, asked for in order, once each.
    std::vector<std::pair<long, long>> asked, progress;
    write_compliance_file(
        bands, model,
        [&](long first, long count, double* rows) {
          asked.emplace_back(first, count);
          Eigen::Map<RowMajor>(rows, count, 12) = G.middleRows(first, count);
        },
        5, [&](long done, long total) { progress.emplace_back(done, total); });
    const std::vector<std::pair<long, long>> expected_bands{{0, 5}, {5, 5}, {10, 2}};
    EXPECT_EQ(asked, expected_bands);
    const std::vector<std::pair<long, long>> expected_progress{{5, 12}, {10, 12}, {12, 12}};
    EXPECT_EQ(progress, expected_progress);

    Eigen::MatrixXd G_whole, G_bands;
    const ComplianceModel a = read_compliance_file(whole, &G_whole);
    const ComplianceModel b = read_compliance_file(bands, &G_bands);
    EXPECT_EQ(a.content_sha256, b.content_sha256);
    EXPECT_EQ(b.content_sha256, expected_digest(model, G));
    EXPECT_TRUE(same_bits(G_whole, G_bands));
    expect_same_model(b, model);
  }
}

TEST(ComplianceFileUnit, ADamagedDatasetIsRefusedNamingTheFile) {
  TempDir dir;
  const ComplianceModel model = small_model();
  const Eigen::MatrixXd G = random_spd_G(12, 4);
  const auto good = dir / "good.h5";
  write_compliance_file(good, model, G);

  // One entry of G changed (still finite, still plausible): only the digest tells.
  const auto in_g = dir / "damaged_g.h5";
  std::filesystem::copy_file(good, in_g);
  overwrite(in_g, "/compliance/G", 3, 7, std::nextafter(G(3, 7), 1.0));  // one ulp
  Eigen::MatrixXd G_read;
  expect_error<InputError>([&] { read_compliance_file(in_g, &G_read); },
                           {in_g.string(), "content_sha256", "corrupt"});

  // A coordinate changed: refused too when G is read (the digest covers every dataset).
  const auto in_mesh = dir / "damaged_mesh.h5";
  std::filesystem::copy_file(good, in_mesh);
  overwrite(in_mesh, "/mesh/vertices", 4, 2, 0.0125);
  expect_error<InputError>([&] { read_compliance_file(in_mesh, &G_read); },
                           {in_mesh.string(), "content_sha256"});

  // A non-finite entry is named for what it is, before the digest.
  const auto nan = dir / "nan.h5";
  std::filesystem::copy_file(good, nan);
  overwrite(nan, "/compliance/G", 11, 0, std::nan(""));
  expect_error<InputError>([&] { read_compliance_file(nan, &G_read); },
                           {nan.string(), "/compliance/G", "non-finite"});

  // The undamaged original still reads.
  EXPECT_NO_THROW(read_compliance_file(good, &G_read));
}

TEST(ComplianceFileUnit, AMissingFileIsRefusedNamingIt) {
  TempDir dir;
  const auto missing = dir / "absent.h5";
  Eigen::MatrixXd G;
  expect_error<InputError>([&] { read_compliance_file(missing, &G); },
                           {missing.string(), "no such file"});
  expect_error<InputError>([&] { read_compliance_file(missing, nullptr); },
                           {missing.string(), "no such file"});
  // Not HDF5 at all.
  std::ofstream(dir / "text.h5") << "palpate? no.";
  expect_error<InputError>([&] { read_compliance_file(dir / "text.h5", &G); },
                           {(dir / "text.h5").string(), "not an HDF5 file"});
}

TEST(ComplianceFileUnit, AFailedWriteLeavesNothingAtTheOutputPath) {
  TempDir dir;
  const ComplianceModel model = small_model();
  const Eigen::MatrixXd G = random_spd_G(12, 5);

  // The output directory is missing: refused, nothing created.
  const auto nowhere = dir / "missing" / "model.h5";
  EXPECT_ANY_THROW(write_compliance_file(nowhere, model, G));
  EXPECT_FALSE(std::filesystem::exists(nowhere));
  EXPECT_FALSE(std::filesystem::exists(dir / "missing"));
  EXPECT_TRUE(listing(dir.path()).empty());

  // The rows' source fails midway (after a band is written): the exception
  // comes through, no temporary is left, and an older file at the path is
  // kept as it was.
  const auto path = dir / "model.h5";
  write_compliance_file(path, model, G);
  const std::string before = slurp(path);
  struct SourceFailed {};
  EXPECT_THROW(write_compliance_file(
                   path, model,
                   [&](long first, long count, double* rows) {
                     if (first > 0) throw SourceFailed{};
                     Eigen::Map<RowMajor>(rows, count, 12) = 2 * G.middleRows(first, count);
                   },
                   4),
               SourceFailed);
  EXPECT_EQ(listing(dir.path()), std::vector<std::string>{"model.h5"});
  EXPECT_EQ(slurp(path), before);
  Eigen::MatrixXd G_read;
  read_compliance_file(path, &G_read);
  EXPECT_TRUE(same_bits(G_read, G));
}

}  // namespace
}  // namespace palpate
