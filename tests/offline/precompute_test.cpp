// The precompute pipeline: job files, attachment, every bad input's error,
// the compliance file's round trip and atomic writing.

#include "palpate/offline/precompute.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <fstream>

#include "palpate/core/error.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/compliance_file.hpp"
#include "support/box_job.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::TempDir;

PrecomputeJob box_job(const TempDir& dir) { return testing::box_job(dir.path()); }

using testing::expect_error;

TEST(Precompute, WritesAFileThatReadsBackWithTheContract) {
  TempDir dir;
  const PrecomputeJob job = box_job(dir);
  const auto report = run_precompute(job, {});
  EXPECT_LE(report.checks->max_relative_difference.value(), 1e-8);
  EXPECT_LE(report.checks->max_residual, 1e-10);
  Eigen::MatrixXd G;
  const ComplianceModel model = read_compliance_file(job.output, &G);
  const Eigen::Index n = model.compliance_vertices.size();
  EXPECT_EQ(model.vertices_m.rows(), 5 * 3 * 3);
  EXPECT_EQ(model.fixed_vertices.size(), 3 * 3);
  EXPECT_EQ(n, 5 * 3 * 3 - 9 - 3);  // minus the fixed face and the 3 interior vertices
  EXPECT_EQ(G.rows(), 3 * n);
  EXPECT_EQ(model.method, "both");
  EXPECT_EQ(model.input_hash.rfind("sha256:", 0), 0u);
  EXPECT_EQ(model.precision, Precision::kFloat64);
  ASSERT_EQ(model.materials.size(), 1u);
  EXPECT_EQ(model.materials[0].name, "organ");
  EXPECT_EQ(model.materials[0].young_modulus_pa, 85e3);
  EXPECT_LE(symmetry_error(G), 1e-10);
  // No temporary left beside the output.
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    EXPECT_EQ(entry.path().filename().string().find(".tmp-"), std::string::npos) << entry.path();

  // Same inputs, same hash; float32 storage rounds G to single precision.
  PrecomputeJob single = job;
  single.output = dir / "box32.h5";
  single.precision = Precision::kFloat32;
  single.method = Method::kCondensation;
  run_precompute(single, {});
  Eigen::MatrixXd G32;
  const ComplianceModel m32 = read_compliance_file(single.output, &G32);
  EXPECT_EQ(m32.input_hash, model.input_hash);
  EXPECT_EQ(m32.precision, Precision::kFloat32);
  EXPECT_LE(max_relative_difference(G, G32), 1e-6);
}

TEST(Precompute, JobWithoutPathsRoundTripsThroughToml) {
  // No `file = ""` for a missing mesh or output: it would read back as the
  // job file's directory (found by fuzz_job).
  TempDir dir;
  std::ofstream(dir / "job.toml") << to_toml(PrecomputeJob{});
  const PrecomputeJob back = read_job_file(dir / "job.toml");
  EXPECT_TRUE(back.mesh_file.empty()) << back.mesh_file;
  EXPECT_TRUE(back.output.empty()) << back.output;
}

TEST(Precompute, JobFileRoundTripsThroughToml) {
  TempDir dir;
  PrecomputeJob job = box_job(dir);
  job.mesh_unit = "mm";
  job.group_materials.push_back({"tumour", 3e5, 0.4});
  job.attachment.spheres.push_back({{0.01, 0.02, 0.03}, 0.005});
  job.attachment.boxes.push_back({{0, 0, 0}, {0.001, 0.002, 0.003}});
  job.method = Method::kSolves;
  job.block_columns = 96;
  std::ofstream(dir / "job.toml") << to_toml(job);
  const PrecomputeJob back = read_job_file(dir / "job.toml");
  EXPECT_EQ(back.mesh_file, std::filesystem::absolute(job.mesh_file));
  EXPECT_EQ(back.mesh_unit, "mm");
  EXPECT_EQ(back.young_modulus_pa, 85e3);
  EXPECT_EQ(back.poisson_ratio, 0.45);
  ASSERT_EQ(back.group_materials.size(), 1u);
  EXPECT_EQ(back.group_materials[0].group, "tumour");
  ASSERT_EQ(back.attachment.spheres.size(), 1u);
  EXPECT_NEAR(back.attachment.spheres[0].radius, 0.005, 1e-15);  // mm in the file, m inside
  EXPECT_NEAR(back.attachment.boxes[0].max.z(), 0.003, 1e-15);
  EXPECT_NEAR(back.attachment.half_spaces[0].point.x(), 0.001, 1e-15);
  EXPECT_EQ(back.method, Method::kSolves);
  EXPECT_EQ(back.block_columns, 96);
}

TEST(Precompute, JobFileErrorsNameFileLineAndKey) {
  TempDir dir;
  std::ofstream(dir / "typo.toml") << "[mesh]\nfile = \"a.msh\"\n\n[material]\nyoung_modulus = 5\n";
  expect_error<InputError>(
      [&] { read_job_file(dir / "typo.toml"); },
      {"typo.toml:5", "material.young_modulus", "unknown key", "young_modulus_pa"});
  std::ofstream(dir / "bad.toml") << "[mesh\n";
  expect_error<InputError>([&] { read_job_file(dir / "bad.toml"); },
                           {"bad.toml:", "not valid TOML"});
  std::ofstream(dir / "unit.toml") << "[mesh]\nunit = \"inch\"\n";
  expect_error<InputError>([&] { read_job_file(dir / "unit.toml"); },
                           {"unit.toml:2", "m, cm or mm"});
  std::ofstream(dir / "type.toml") << "[material]\npoisson_ratio = \"high\"\n";
  expect_error<InputError>([&] { read_job_file(dir / "type.toml"); },
                           {"type.toml:2", "expected a number"});
}

TEST(Precompute, EachBadInputGetsItsErrorAndNoFile) {
  TempDir dir;
  const PrecomputeJob good = box_job(dir);
  auto run = [&](PrecomputeJob job) { run_precompute(job, {}); };
  {
    PrecomputeJob j = good;
    j.young_modulus_pa = -1;
    expect_error<InputError>([&] { run(j); }, {"Young's modulus", "> 0"});
  }
  {
    PrecomputeJob j = good;
    j.poisson_ratio = 0.5;
    expect_error<InputError>([&] { run(j); }, {"Poisson ratio", "(-1, 0.5)"});
  }
  {
    PrecomputeJob j = good;
    j.mesh_file = dir / "missing.msh";
    expect_error<InputError>([&] { run(j); }, {"missing.msh", "no such file"});
  }
  {
    PrecomputeJob j = good;
    j.attachment = {};
    expect_error<InputError>([&] { run(j); }, {"no attachment"});
  }
  {
    PrecomputeJob j = good;
    j.attachment = {};
    j.attachment.spheres.push_back({{0, 0, 0}, 1e-4});  // one corner vertex only
    expect_error<InputError>([&] { run(j); }, {"fixes 1 vertex,", "rigid motions", "at least 3"});
  }
  {
    PrecomputeJob j = good;
    j.attachment = {};
    j.attachment.boxes.push_back({{-1, -1, -1}, {1, 1e-4, 1e-4}});  // the x-axis edge: collinear
    expect_error<InputError>([&] { run(j); }, {"all on one line"});
  }
  {
    PrecomputeJob j = good;
    j.attachment.boxes.push_back({{5, 5, 5}, {6, 6, 6}});
    expect_error<InputError>([&] { run(j); }, {"selects no vertex", "the mesh spans"});
  }
  {
    PrecomputeJob j = good;
    j.attachment.groups.push_back("ligament");
    expect_error<InputError>([&] { run(j); }, {"'ligament'", "not a physical group"});
  }
  {
    PrecomputeJob j = good;
    std::ofstream(dir / "ids.txt") << "0\n1\n# comment\n\n4000\n";
    j.attachment.ids_file = dir / "ids.txt";
    expect_error<InputError>([&] { run(j); }, {"ids.txt", "4000", "out of range", "0..44"});
    std::ofstream(dir / "ids.txt") << "0\nseven\n";
    expect_error<InputError>([&] { run(j); }, {"ids.txt:2", "'seven'"});
  }
  {
    PrecomputeJob j = good;
    j.group_materials.push_back({"tumour", 1e5, 0.3});
    expect_error<InputError>([&] { run(j); }, {"'tumour'", "not a physical volume"});
  }
  {
    PrecomputeJob j = good;
    j.memory_limit_bytes = 1000;
    expect_error<ResourceError>([&] { run(j); }, {"needs about", "1.0 kB", "memory limit"});
  }
  {
    PrecomputeJob j = good;
    j.output = dir / "no-such-dir" / "out.h5";
    expect_error<InputError>([&] { run(j); }, {"does not exist"});
  }
  EXPECT_FALSE(std::filesystem::exists(good.output));
}

TEST(Precompute, RefusesPartsJoinedOnlyAtAVertex) {
  // Two tetrahedra sharing one vertex: the second can turn about it, so
  // holding the first does not stop the rigid motions of the whole.
  TempDir dir;
  TetMesh mesh;
  mesh.vertices.resize(7, 3);
  mesh.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, -1, 0, 0, 0, -1, 0, 0, 0, -1;
  mesh.tetrahedra.resize(2, 4);
  mesh.tetrahedra << 0, 1, 2, 3, 0, 4, 6, 5;
  mesh.tet_group = Eigen::VectorXi::Zero(2);
  testing::write_msh22(mesh, dir / "hinge.msh");
  PrecomputeJob job;
  job.mesh_file = dir / "hinge.msh";
  job.young_modulus_pa = 1e5;
  job.poisson_ratio = 0.3;
  job.attachment.boxes.push_back({{-0.1, -0.1, -0.1}, {1.1, 1.1, 1.1}});  // the first tetrahedron
  job.output = dir / "hinge.h5";
  expect_error<InputError>([&] { run_precompute(job, {}); },
                           {"part 2 of 2", "turn about it", "at least 3"});
  EXPECT_FALSE(std::filesystem::exists(job.output));
}

TEST(Precompute, UsesTheIdsFileInTheMeshFilesNodeOrder) {
  TempDir dir;
  PrecomputeJob job = box_job(dir);
  job.attachment = {};
  // Nodes 0, 5, 10, 15 and 20 of the file: a line at x = 0 ... plus two more
  // off that line, on the x = 0 face (grid 5 × 3 × 3, index i + 5 (j + 3 k)).
  std::ofstream(dir / "ids.txt") << "0\n5\n10\n15\n30\n";
  job.attachment.ids_file = dir / "ids.txt";
  run_precompute(job, {});
  const ComplianceModel model = read_compliance_file(job.output, nullptr);
  ASSERT_EQ(model.fixed_vertices.size(), 5);
  for (int i = 0; i < 5; ++i)
    EXPECT_EQ(model.source_vertex_ids[model.fixed_vertices[i]],
              std::vector<int>({0, 5, 10, 15, 30})[static_cast<size_t>(i)]);
}

TEST(ComplianceFile, RefusesForeignTruncatedAndWrongVersionFiles) {
  TempDir dir;
  const PrecomputeJob job = box_job(dir);
  run_precompute(job, {});
  std::ofstream(dir / "text.h5") << "not hdf5";
  expect_error<InputError>([&] { read_compliance_file(dir / "text.h5", nullptr); },
                           {"not an HDF5 file"});
  // Truncate a copy to half its size.
  const auto size = std::filesystem::file_size(job.output);
  std::filesystem::copy_file(job.output, dir / "half.h5");
  std::filesystem::resize_file(dir / "half.h5", size / 2);
  Eigen::MatrixXd G;
  EXPECT_THROW(read_compliance_file(dir / "half.h5", &G), InputError);
  expect_error<InputError>([&] { read_compliance_file(dir / "none.h5", nullptr); },
                           {"no such file"});
}

TEST(AtomicOutput, LeavesNothingWhenAbandonedOrInterrupted) {
  TempDir dir;
  {
    AtomicOutput out(dir / "a.txt");
    std::ofstream(out.temp_path()) << "partial";
    EXPECT_TRUE(std::filesystem::exists(out.temp_path()));
  }  // abandoned: no commit
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));

  // A child writes, then is killed by SIGTERM before committing.
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    install_interrupt_cleanup();
    AtomicOutput out(dir / "b.txt");
    std::ofstream(out.temp_path()) << "partial";
    ::raise(SIGTERM);
    ::_exit(0);  // not reached
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));

  {
    AtomicOutput out(dir / "c.txt");
    std::ofstream(out.temp_path()) << "whole";
    out.commit();
  }
  std::ifstream in(dir / "c.txt");
  std::string text;
  in >> text;
  EXPECT_EQ(text, "whole");
}

}  // namespace
}  // namespace palpate
