// Batch precomputation (issue 7, docs/precompute.md "Batch precomputation"):
// shards merged equal a single run bit for bit; merge refuses mismatched
// shards; a run interrupted halfway resumes from its checkpoint and gives the
// same file; a run under a memory bound smaller than G succeeds and matches;
// a float32 file is served from float32 memory within float32 tolerance.

#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/file/compliance_file.hpp"
#include "palpate/offline/partial_file.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "support/box_job.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::TempDir;

// A box of 6 cells along x: 228 columns of G, in blocks of 16 (15 blocks):
// enough blocks for 3 shards, a resume halfway and a bounded run.
PrecomputeJob small_job(const TempDir& dir, const std::string& name = "box") {
  PrecomputeJob job = testing::box_job(dir.path(), name, 6);
  job.block_columns = 16;
  job.write_xdmf = false;
  return job;
}

struct Read {
  ComplianceModel model;
  Eigen::MatrixXd G;
};
Read read(const std::filesystem::path& path) {
  Read r;
  r.model = read_compliance_file(path, &r.G);
  return r;
}

bool same_bits(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<size_t>(a.size())) == 0;
}

// Runs shards `count` of @p job, then merges them into @p output.
PrecomputeReport shard_and_merge(PrecomputeJob job, int count, const std::filesystem::path& output,
                                 std::vector<std::filesystem::path>* parts = nullptr) {
  MergeJob merge;
  merge.output = output;
  merge.write_xdmf = false;
  for (int k = 0; k < count; ++k) {
    job.shard = {k, count};
    const auto report = run_precompute(job, {});
    merge.shards.emplace_back(report.output->file);
  }
  if (parts) *parts = merge.shards;
  return merge_shards(merge, {});
}

TEST(BatchPrecompute, ThreeShardsMergedEqualASingleRunBitForBit) {
  TempDir dir;
  PrecomputeJob job = small_job(dir);
  run_precompute(job, {});  // method both, G in memory
  const Read single = read(job.output);
  ASSERT_EQ(single.G.rows(), 228);

  std::vector<std::filesystem::path> parts;
  const auto report = shard_and_merge(job, 3, dir / "merged.h5", &parts);
  // Whole blocks of 16, as even as they go: 15 blocks → 5, 5, 5 (the last
  // one 4 columns wide).
  ASSERT_EQ(parts.size(), 3u);
  EXPECT_EQ(parts[0].filename(), "box.part-0-80.h5");
  EXPECT_EQ(parts[1].filename(), "box.part-80-160.h5");
  EXPECT_EQ(parts[2].filename(), "box.part-160-228.h5");
  ASSERT_TRUE(report.shards);
  EXPECT_EQ(report.shards->size(), 3u);
  const Read merged = read(dir / "merged.h5");
  EXPECT_TRUE(same_bits(merged.G, single.G));
  EXPECT_EQ(merged.model.content_sha256, single.model.content_sha256);
  EXPECT_EQ(merged.model.content_sha256.rfind("sha256:", 0), 0u);
  EXPECT_EQ(merged.model.input_hash, single.model.input_hash);
  EXPECT_EQ(merged.model.method, "solves");
  EXPECT_LE(report.checks->symmetry_error.value(), 1e-10);

  // The streaming single run (solves) gives the same bits too.
  PrecomputeJob solves = job;
  solves.method = Method::kSolves;
  solves.output = dir / "solves.h5";
  run_precompute(solves, {});
  EXPECT_EQ(read(solves.output).model.content_sha256, single.model.content_sha256);
  EXPECT_FALSE(std::filesystem::exists(checkpoint_path(solves.output)));

  // float32: the shards and the file are half the size, and equal a single
  // float32 run.
  PrecomputeJob single32 = job;
  single32.precision = Precision::kFloat32;
  single32.output = dir / "single32.h5";
  run_precompute(single32, {});
  PrecomputeJob sharded32 = single32;
  sharded32.output = dir / "sharded32.h5";
  shard_and_merge(sharded32, 3, sharded32.output);
  EXPECT_EQ(read(sharded32.output).model.content_sha256,
            read(single32.output).model.content_sha256);
  // G is 416 kB in float64 and the rest of the file about 40 kB.
  EXPECT_LT(std::filesystem::file_size(single32.output),
            0.6 * static_cast<double>(std::filesystem::file_size(job.output)));
}

TEST(BatchPrecompute, MergeRefusesMismatchedShardsClearly) {
  TempDir dir;
  PrecomputeJob job = small_job(dir);
  job.method = Method::kSolves;
  std::vector<std::filesystem::path> thirds, halves;
  auto shards = [&](PrecomputeJob j, int count) {
    std::vector<std::filesystem::path> out;
    for (int k = 0; k < count; ++k) {
      j.shard = {k, count};
      out.emplace_back(run_precompute(j, {}).output->file);
    }
    return out;
  };
  thirds = shards(job, 3);
  PrecomputeJob halves_job = job;
  halves_job.output = dir / "halves" / "box.h5";
  std::filesystem::create_directory(dir / "halves");
  halves = shards(halves_job, 2);
  PrecomputeJob stiffer = job;
  stiffer.young_modulus_pa = 170e3;
  stiffer.output = dir / "stiffer" / "box.h5";
  std::filesystem::create_directory(dir / "stiffer");
  const auto other = shards(stiffer, 3);

  MergeJob merge;
  merge.output = dir / "merged.h5";
  merge.write_xdmf = false;
  auto merge_of = [&](std::vector<std::filesystem::path> files) {
    merge.shards = std::move(files);
    merge_shards(merge, {});
  };
  expect_error<InputError>(
      [&] {
        merge_of({thirds[0], other[1], thirds[2]});
      },
      {"different inputs", "input hash", "box.part-0-80.h5"});
  // Halves are 0:112 and 112:228.
  expect_error<InputError>(
      [&] {
        merge_of({halves[0], thirds[1], thirds[2]});
      },
      {"both hold columns 80:112", "overlapping"});
  expect_error<InputError>(
      [&] {
        merge_of({thirds[0], thirds[2]});
      },
      {"columns 80:160 of 228 are in no shard", "--columns 80:160"});
  expect_error<InputError>(
      [&] {
        merge_of({thirds[1], thirds[2]});
      },
      {"columns 0:80 of 228 are in no shard"});
  expect_error<InputError>(
      [&] {
        merge_of({thirds[0], thirds[1]});
      },
      {"columns 160:228 of 228 are in no shard"});
  expect_error<InputError>(
      [&] {
        merge_of({thirds[0], thirds[0], thirds[1], thirds[2]});
      },
      {"both hold columns 0:80"});
  PrecomputeJob single32 = job;
  single32.precision = Precision::kFloat32;
  single32.output = dir / "f32" / "box.h5";
  std::filesystem::create_directory(dir / "f32");
  const auto f32 = shards(single32, 3);
  expect_error<InputError>(
      [&] {
        merge_of({thirds[0], f32[1], thirds[2]});
      },
      {"float64 and float32", "--precision"});
  EXPECT_FALSE(std::filesystem::exists(merge.output));

  // Not shards: a compliance file, a missing file.
  run_precompute(job, {});
  expect_error<InputError>([&] { merge_of({job.output}); },
                           {"a complete compliance file, not a shard"});
  expect_error<InputError>([&] { merge_of({dir / "none.h5"}); }, {"none.h5", "no such file"});
  // A shard is not a compliance file either.
  expect_error<InputError>([&] { read_compliance_file(thirds[0], nullptr); },
                           {"palpate-compliance-partial", "palpate-precompute merge"});
  // Columns a single run would not solve the same way are refused before any work.
  PrecomputeJob misaligned = job;
  misaligned.shard.begin = 10;
  misaligned.shard.end = 100;
  expect_error<InputError>([&] { run_precompute(misaligned, {}); },
                           {"columns 10:100", "blocks of 16", "multiple of 16"});
  ColumnShard parsed;
  expect_error<InputError>([&] { parse_shard("3/3", &parsed); }, {"'3/3'", "INDEX/COUNT"});
  expect_error<InputError>([&] { parse_shard("5:2", &parsed); }, {"'5:2'", "BEGIN:END"});
}

TEST(BatchPrecompute, AnInterruptedRunResumesFromItsCheckpointAndGivesTheSameFile) {
  TempDir dir;
  PrecomputeJob job = small_job(dir);
  job.method = Method::kSolves;
  PrecomputeJob reference = job;
  reference.output = dir / "reference.h5";
  run_precompute(reference, {});

  // Interrupted once half the columns are on disk: the checkpoint stays.
  // (A SIGKILL, which no code sees, is tests/batch/batch_scripts_test.py's:
  // fork() cannot be used here, CHOLMOD's OpenMP does not survive it.)
  struct Interrupted {};
  PrecomputeHooks stop;
  stop.progress = [](const std::string&) -> ProgressFn {
    return [](long done, long total) {
      if (2 * done >= total) throw Interrupted{};
    };
  };
  EXPECT_THROW(run_precompute(job, stop), Interrupted);
  EXPECT_FALSE(std::filesystem::exists(job.output));
  ASSERT_TRUE(std::filesystem::exists(checkpoint_path(job.output)));

  std::vector<std::string> lines;
  PrecomputeHooks hooks;
  hooks.info = [&](const std::string& s) { lines.push_back(s); };
  hooks.warn = [&](const std::string& s) { lines.push_back("warning: " + s); };
  const auto report = run_precompute(job, hooks);
  const long resumed = report.columns->resumed_blocks;
  // Half of 228 columns is 114: at least 8 blocks of 16 were flagged complete.
  EXPECT_GE(resumed, 8);
  EXPECT_LT(resumed, 15);
  bool said = false;
  for (const auto& l : lines) said |= l.find("resuming") != std::string::npos;
  EXPECT_TRUE(said) << ::testing::PrintToString(lines);
  EXPECT_EQ(read(job.output).model.content_sha256, read(reference.output).model.content_sha256);
  EXPECT_TRUE(same_bits(read(job.output).G, read(reference.output).G));
  EXPECT_FALSE(std::filesystem::exists(checkpoint_path(job.output)));

  // A checkpoint made for other inputs is not resumed: discarded, with a warning.
  const auto ckpt = checkpoint_path(job.output);
  ComplianceModel other = read(job.output).model;
  other.input_hash = "sha256:other";
  PartialFile::create(
      ckpt, other, ShardIdentity{other.input_hash, 0, 228, 228, 16, Precision::kFloat64}, {}, "x");
  lines.clear();
  run_precompute(job, hooks);
  said = false;
  for (const auto& l : lines) said |= l.find("warning: discarded") != std::string::npos;
  EXPECT_TRUE(said) << ::testing::PrintToString(lines);
  EXPECT_EQ(read(job.output).model.content_sha256, read(reference.output).model.content_sha256);
}

TEST(BatchPrecompute, AMemoryBoundSmallerThanGIsEnoughAndGivesTheSameFile) {
  TempDir dir;
  // A plate one cell thick: every vertex is on the surface, so G (m = n =
  // 1632, 21 MB) dwarfs K, its factor and a block of columns per thread, as
  // it does for large organs (G ~ m², the factor ~ n^(4/3)).
  PrecomputeJob job = testing::box_job(dir.path(), "plate", 2);  // its attachment: x ≤ 1 mm
  testing::write_msh22(testing::box_mesh(0.1, 0.1, 0.01, 16, 16, 1), job.mesh_file);
  job.block_columns = 8;
  job.write_xdmf = false;
  const auto in_ram = run_precompute(job, {});  // method both
  const double g_bytes = in_ram.memory->G_bytes.value();

  PrecomputeJob bounded = job;
  bounded.method = Method::kSolves;
  bounded.output = dir / "bounded.h5";
  bounded.memory_limit_bytes = 0.75 * g_bytes;
  const auto report = run_precompute(bounded, {});
  EXPECT_LT(report.memory->estimate_bytes.value(), bounded.memory_limit_bytes);
  EXPECT_LT(bounded.memory_limit_bytes, report.memory->G_bytes.value());
  // The final file was written in bands of rows, not from a whole G.
  const long m = report.dofs->surface;
  EXPECT_LT(report.memory->merge_band_rows.value(), m);
  EXPECT_TRUE(same_bits(read(bounded.output).G, read(job.output).G));
  EXPECT_EQ(read(bounded.output).model.content_sha256, read(job.output).model.content_sha256);

  // The methods that hold G in memory are refused under that bound, with the way out.
  PrecomputeJob both = bounded;
  both.method = Method::kBoth;
  expect_error<ResourceError>([&] { run_precompute(both, {}); }, {"G alone", "--method solves"});
  // Below one block and the factor, solves is refused too.
  bounded.memory_limit_bytes = 1e4;
  expect_error<ResourceError>([&] { run_precompute(bounded, {}); },
                              {"even one block of 8 columns", "--block-columns"});
}

TEST(BatchPrecompute, AFloat32FileIsServedFromFloat32MemoryWithinItsTolerance) {
  TempDir dir;
  PrecomputeJob job = small_job(dir);
  run_precompute(job, {});
  PrecomputeJob single = job;
  single.precision = Precision::kFloat32;
  single.output = dir / "box32.h5";
  run_precompute(single, {});

  const SurfaceModel m64 = load_surface_model("box", job.output, true);
  const SurfaceModel m32 = load_surface_model("box", single.output, true);
  EXPECT_FALSE(m64.float32());
  ASSERT_TRUE(m32.float32());
  EXPECT_EQ(m32.G.size(), 0);
  EXPECT_EQ(m32.compliance_vertex_count(), m64.compliance_vertex_count());
  EXPECT_DOUBLE_EQ(m32.G_bytes(), m64.G_bytes() / 2);
  // The float32 entries are G rounded to nearest: relative 2⁻²⁴ ≈ 6e-8.
  EXPECT_LE((m32.G32.cast<double>() - m64.G).cwiseAbs().maxCoeff(),
            6.0e-8 * m64.G.cwiseAbs().maxCoeff());

  const int top =
      testing::box_top_vertex(m64.surface.rest_positions_m, m64.compliance_vertex_count(), 90, 25);
  const int side =
      testing::box_top_vertex(m64.surface.rest_positions_m, m64.compliance_vertex_count(), 50, 10);
  ASSERT_GE(top, 0);
  ASSERT_GE(side, 0);
  for (int threads : {1, 2}) {
    SolverLimits limits;
    limits.surface_threads = threads;
    ConstraintSolver s64(m64, limits), s32(m32, limits);
    for (ConstraintSolver* s : {&s64, &s32}) {
      const double press[3] = {0, 0, -0.004}, push[3] = {0.2, 0, -0.5}, none[3] = {0, 0, 0};
      ASSERT_EQ(s->begin(2), RequestStatus::kOk);
      ASSERT_EQ(s->add(m64.surface.vertex_ids[static_cast<size_t>(top)], 1, press, none),
                RequestStatus::kOk);
      ASSERT_EQ(s->add(m64.surface.vertex_ids[static_cast<size_t>(side)], 0, push, none),
                RequestStatus::kOk);
      ASSERT_EQ(s->solve(), RequestStatus::kOk) << s->message();
    }
    // Forces come from a 3 × 3 solve on G_CC (condition ~10 here): within
    // 1e-5 relative, 100 × the storage rounding. Displacements are G f:
    // within 1e-6 relative of the largest.
    EXPECT_LE((s32.forces() - s64.forces()).norm(), 1e-5 * s64.forces().norm());
    Eigen::VectorXd u64(m64.compliance_rows()), u32(m32.compliance_rows());
    s64.surface_displacement(u64);
    s32.surface_displacement(u32);
    EXPECT_GT(u64.norm(), 0);
    EXPECT_LE((u32 - u64).cwiseAbs().maxCoeff(), 1e-6 * u64.cwiseAbs().maxCoeff());
  }
  // Without keep_float32, G comes back as double (the default for tools).
  const SurfaceModel widened = load_surface_model("box", single.output);
  EXPECT_FALSE(widened.float32());
  EXPECT_TRUE((widened.G.array() == m32.G32.cast<double>().array()).all());
}

}  // namespace
}  // namespace palpate
