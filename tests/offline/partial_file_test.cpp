// PartialFile, a shard's checkpointed file: blocks written and flagged,
// resumed by the same shard only, read back once finished (rows of G,
// diagonal entries, checks, model, report), incomplete shards refused, and
// checkpoint_path's naming. The columns are hand-made: this tests the file,
// not the solves.

#include "palpate/offline/partial_file.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/file/compliance_file.hpp"
#include "support/expect_error.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using testing::expect_error;
using testing::TempDir;

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

constexpr int kColumns = 12;  // m = 3n, n = 4 compliance vertices

/// The support's two tetrahedra, vertex 0 fixed, vertices 1..4 the
/// compliance vertices.
ComplianceModel small_model() {
  ComplianceModel m = testing::two_tetrahedra_model();
  m.method = "solves";
  m.producer = "palpate unit test";
  m.created_utc = "2024-01-02T03:04:05Z";
  m.input_hash = "sha256:" + std::string(64, 'b');
  m.material_summary = "organ: E = 85000 Pa, nu = 0.45";
  m.job_toml = "block_columns = 5\n";
  m.report_json = "{}";
  return m;
}

/// Distinct, non-symmetric values (so any column or row swap shows), ~1e-4.
Eigen::MatrixXd columns_of_G(std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(0.5e-4, 2e-4);
  Eigen::MatrixXd G(kColumns, kColumns);
  for (Eigen::Index j = 0; j < G.cols(); ++j)
    for (Eigen::Index i = 0; i < G.rows(); ++i) G(i, j) = value(rng);
  return G;
}

/// Columns 5..11 of 12 in blocks of 5: blocks 1 ([5, 10)) and 2 ([10, 12),
/// the last one partial).
ShardIdentity shard(Precision precision = Precision::kFloat64) {
  return {small_model().input_hash, 5, kColumns, kColumns, 5, precision};
}

void write_block(PartialFile& file, const Eigen::MatrixXd& G, int index) {
  const ShardIdentity& id = file.identity();
  const int first = index * id.block_columns;
  const int width = std::min(id.block_columns, id.columns_end - first);
  std::vector<ColumnCheck> checks;
  for (const int c : file.check_columns())
    if (c >= first && c < first + width) checks.push_back({c, 1e-14 * (c + 1), 1e-15 * (c + 1)});
  file.write_block(SolvedBlock{index, first, G.middleCols(first, width), checks});
}

TEST(PartialFile, BlocksWrittenLeaveThePendingOnesAndAreResumedByTheSameShard) {
  TempDir dir;
  const auto path = dir / "shard.h5";
  const Eigen::MatrixXd G = columns_of_G(1);
  const ShardIdentity id = shard();
  EXPECT_EQ(id.first_block(), 1);
  EXPECT_EQ(id.blocks(), 2);
  {
    auto file = PartialFile::create(path, small_model(), id, {5, 11}, "test BLAS");
    ASSERT_NE(file, nullptr);
    EXPECT_EQ(file->identity(), id);
    EXPECT_EQ(file->blas(), "test BLAS");
    EXPECT_EQ(file->check_columns(), (std::vector<int>{5, 11}));
    EXPECT_EQ(file->pending_blocks(), (std::vector<int>{1, 2}));
    write_block(*file, G, 2);
    EXPECT_EQ(file->pending_blocks(), (std::vector<int>{1}));
    file->close();
  }

  // Another shard's run does not resume it: null, and the reason says both.
  std::string why;
  ShardIdentity others[4] = {id, id, id, id};
  others[0].columns_begin = 0;                              // another range
  others[1].precision = Precision::kFloat32;                // another precision
  others[2].input_hash = "sha256:" + std::string(64, 'c');  // another problem
  others[3].block_columns = 7;  // another block size (7 ∤ 5: range moves too)
  others[3].columns_begin = 7;
  for (const auto& other : others) {
    why.clear();
    EXPECT_EQ(PartialFile::open_to_resume(path, other, &why), nullptr) << other.describe();
    EXPECT_NE(why.find("it holds " + id.describe()), std::string::npos) << why;
    EXPECT_NE(why.find(other.describe()), std::string::npos) << why;
  }

  // The same shard resumes where it was: block 2 done, block 1 pending.
  why.clear();
  auto resumed = PartialFile::open_to_resume(path, id, &why);
  ASSERT_NE(resumed, nullptr) << why;
  EXPECT_EQ(resumed->identity(), id);
  EXPECT_EQ(resumed->blas(), "test BLAS");
  EXPECT_EQ(resumed->check_columns(), (std::vector<int>{5, 11}));
  EXPECT_EQ(resumed->pending_blocks(), (std::vector<int>{1}));
  write_block(*resumed, G, 1);
  EXPECT_TRUE(resumed->pending_blocks().empty());
  resumed->finish(R"({"shard":"done"})");
  resumed->close();

  // Complete: not resumed again.
  why.clear();
  EXPECT_EQ(PartialFile::open_to_resume(path, id, &why), nullptr);
  EXPECT_NE(why.find("complete"), std::string::npos) << why;
}

TEST(PartialFile, AFinishedShardReadsBackWhatWasWritten) {
  TempDir dir;
  for (const Precision precision : {Precision::kFloat64, Precision::kFloat32}) {
    const auto path = dir / "shard.h5";
    const Eigen::MatrixXd G = columns_of_G(2);
    const ShardIdentity id = shard(precision);
    {
      auto file = PartialFile::create(path, small_model(), id, {5, 11}, "test BLAS");
      write_block(*file, G, 1);
      write_block(*file, G, 2);
      file->finish(R"({"precision":"any"})");
    }
    const auto done = PartialFile::open_complete(path);
    EXPECT_EQ(done->identity(), id);
    EXPECT_EQ(done->path(), path);
    EXPECT_EQ(done->report_json(), R"({"precision":"any"})");
    EXPECT_TRUE(done->pending_blocks().empty());
    // What the shard stores: G's columns, in float32 rounded to nearest.
    const Eigen::MatrixXd stored =
        precision == Precision::kFloat32 ? Eigen::MatrixXd(G.cast<float>().cast<double>()) : G;

    // All rows: the band's columns [5, 12) are the shard's, the others untouched.
    RowMajor band = RowMajor::Constant(kColumns, kColumns, -1.0);
    done->read_rows(0, kColumns, band.data());
    EXPECT_EQ(band.rightCols(7), stored.rightCols(7))
        << "precision " << static_cast<int>(precision);
    EXPECT_TRUE((band.leftCols(5).array() == -1.0).all());
    // A band of rows in the middle.
    RowMajor rows = RowMajor::Constant(4, kColumns, -1.0);
    done->read_rows(3, 4, rows.data());
    EXPECT_EQ(rows.rightCols(7), stored.block(3, 5, 4, 7));
    EXPECT_TRUE((rows.leftCols(5).array() == -1.0).all());

    // The diagonal-block entries of each column c, G(3k + i, c), k = c / 3,
    // kept in float64 whatever G's precision.
    const Eigen::MatrixX3d diagonal = done->diagonal_entries();
    ASSERT_EQ(diagonal.rows(), 7);
    for (int i = 0; i < 7; ++i) {
      const int c = 5 + i, k = c / 3;
      EXPECT_EQ(diagonal.row(i), G.col(c).segment<3>(3 * k).transpose()) << "column " << c;
    }

    const std::vector<ColumnCheck> checks = done->checks();
    ASSERT_EQ(checks.size(), 2u);
    EXPECT_EQ(checks[0].column, 5);
    EXPECT_EQ(checks[0].residual, 1e-14 * 6);
    EXPECT_EQ(checks[0].mismatch, 1e-15 * 6);
    EXPECT_EQ(checks[1].column, 11);
    EXPECT_EQ(checks[1].residual, 1e-14 * 12);
    EXPECT_EQ(checks[1].mismatch, 1e-15 * 12);

    const ComplianceModel model = done->model();
    const ComplianceModel written = small_model();
    EXPECT_EQ(model.input_hash, written.input_hash);
    EXPECT_EQ(model.vertices_m, written.vertices_m);
    EXPECT_EQ(model.tetrahedra, written.tetrahedra);
    EXPECT_EQ(model.compliance_vertices, written.compliance_vertices);
    EXPECT_EQ(model.fixed_vertices, written.fixed_vertices);
    EXPECT_EQ(model.precision, precision);
  }
}

TEST(PartialFile, AnUnfinishedShardIsNotOpenedForMerging) {
  TempDir dir;
  const Eigen::MatrixXd G = columns_of_G(3);
  const auto half = dir / "half.h5";
  {
    auto file = PartialFile::create(half, small_model(), shard(), {}, "test BLAS");
    write_block(*file, G, 1);
  }
  expect_error<InputError>([&] { PartialFile::open_complete(half); },
                           {half.string(), "incomplete shard", "1 of 2 blocks"});

  // Every block written but finish() never called: still not complete.
  const auto unfinished = dir / "unfinished.h5";
  {
    auto file = PartialFile::create(unfinished, small_model(), shard(), {}, "test BLAS");
    write_block(*file, G, 1);
    write_block(*file, G, 2);
  }
  expect_error<InputError>([&] { PartialFile::open_complete(unfinished); },
                           {unfinished.string(), "incomplete shard"});

  // Neither a missing file, nor one that is not HDF5, nor a compliance file.
  expect_error<InputError>([&] { PartialFile::open_complete(dir / "none.h5"); },
                           {(dir / "none.h5").string(), "no such file"});
  std::ofstream(dir / "text.h5") << "text";
  expect_error<InputError>([&] { PartialFile::open_complete(dir / "text.h5"); },
                           {(dir / "text.h5").string(), "not an HDF5 file"});
  write_compliance_file(dir / "model.h5", small_model(), G);
  expect_error<InputError>([&] { PartialFile::open_complete(dir / "model.h5"); },
                           {(dir / "model.h5").string(), "not a shard"});

  // Nor are those resumed.
  std::string why;
  EXPECT_EQ(PartialFile::open_to_resume(dir / "text.h5", shard(), &why), nullptr);
  EXPECT_FALSE(why.empty());
  why.clear();
  EXPECT_EQ(PartialFile::open_to_resume(dir / "model.h5", shard(), &why), nullptr);
  EXPECT_NE(why.find("not a shard"), std::string::npos) << why;
}

TEST(PartialFile, AFileOpenForWritingIsNotResumedByAnotherOpening) {
  // HDF5 (1.10+) locks a file it writes (flock); a second opening of the
  // file meanwhile is told that another run is computing it. Needs HDF5's
  // file locking, which HDF5_USE_FILE_LOCKING=FALSE turns off.
  if (const char* locking = std::getenv("HDF5_USE_FILE_LOCKING");
      locking != nullptr && std::string(locking) == "FALSE")
    GTEST_SKIP() << "HDF5 file locking is off";
  TempDir dir;
  const auto path = dir / "busy.h5";
  auto writing = PartialFile::create(path, small_model(), shard(), {}, "test BLAS");
  std::string why;
  expect_error<InputError>([&] { PartialFile::open_to_resume(path, shard(), &why); },
                           {path.string(), "locked"});
  writing->close();
  EXPECT_NE(PartialFile::open_to_resume(path, shard(), &why), nullptr) << why;
}

TEST(PartialFile, TheCheckpointIsAHiddenFileBesideTheOutput) {
  EXPECT_EQ(checkpoint_path("/data/run/liver.h5"),
            std::filesystem::path("/data/run/.liver.h5.checkpoint"));
  EXPECT_EQ(checkpoint_path("shards/part-3.h5"),
            std::filesystem::path("shards/.part-3.h5.checkpoint"));
  const auto bare = checkpoint_path("liver.h5");
  EXPECT_EQ(bare.filename(), ".liver.h5.checkpoint");
  EXPECT_TRUE(std::filesystem::equivalent(bare.parent_path(), "."));
  // Not an atomic write's temporary name (".<name>.tmp-<pid>"), which
  // remove_stale_temporaries would take for its own.
  EXPECT_EQ(bare.filename().string().find(".tmp-"), std::string::npos);
}

}  // namespace
}  // namespace palpate
