// The typed precompute report (offline/precompute_report.hpp): its JSON is
// the contract of docs/compliance-file.md ("The report"), and merge reads a
// shard's report back from it.
#include "palpate/offline/precompute_report.hpp"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

namespace palpate {
namespace {

PrecomputeReport full_report() {
  PrecomputeReport r;
  r.producer = "palpate-precompute 0.1.0";
  r.created_utc = "2026-11-23T20:00:00Z";
  r.blas = "[OpenBLAS 0.3.21]";
  r.method = "both";
  r.phases.push_back({"read mesh", 0.5, 1e6, 2e6, std::nullopt, std::nullopt});
  r.phases.push_back({"assemble K", 0.1, 2e6, 3e6, 123456, std::nullopt});
  r.phases.push_back({"solves", 2.0, 3e6, 9e6, std::nullopt, 12.5});
  MeshReport& m = r.mesh.emplace();
  m.file = "organ.msh";
  m.unit = "mm";
  m.vertices = 802;
  m.tetrahedra = 3929;
  m.compliance_vertices = 242;
  m.bbox_min_m = {-0.08, -0.05, -0.04};
  m.bbox_max_m = {0.08, 0.05, 0.04};
  r.dofs = DofReport{2361, 726};
  r.materials = std::vector<MaterialRecord>{{"organ", 85e3, 0.45}, {"tumour", 340e3, 0.45}};
  r.input_hash = "sha256:0123";
  MemoryReport& mem = r.memory.emplace();
  mem.G_bytes = 4.2e6;
  mem.limit_bytes = 8e9;
  mem.streamed = true;
  mem.merge_band_rows = 256;
  MethodReport& solves = r.methods["solves"];
  solves.ordering = "amd";
  solves.nnz_L = 3.9e5;
  solves.checked_columns = {0, 145, 725};
  ChecksReport& c = r.checks.emplace();
  c.max_residual = 1.3e-13;
  c.symmetry_error = 1e-15;
  c.min_diagonal_block_vertex = 17;
  c.checked_columns = std::vector<int>{0, 725};
  OutputReport& o = r.output.emplace();
  o.file = "organ.h5";
  o.precision = "float64";
  o.bytes = 4300000;
  r.peak_rss_bytes = 9e6;
  r.shards = std::vector<ShardReport>{{"organ.part-0-384.h5", 0, 384, "[OpenBLAS]", 8000.0, {}}};
  return r;
}

TEST(PrecomputeReport, RoundTripsThroughJson) {
  const PrecomputeReport r = full_report();
  const std::string text = to_json(r);
  const PrecomputeReport back = report_from_json(text);
  EXPECT_EQ(to_json(back), text);
  ASSERT_TRUE(back.mesh);
  EXPECT_EQ(back.mesh->bbox_max_m[1], 0.05);
  ASSERT_TRUE(back.phase("assemble K"));
  EXPECT_EQ(back.phase("assemble K")->nnz_upper, 123456);
  EXPECT_EQ(back.phase("missing"), nullptr);
}

TEST(PrecomputeReport, JsonKeysAndTypesAreTheDocumentedOnes) {
  const auto j = nlohmann::json::parse(to_json(full_report()));
  EXPECT_TRUE(j["mesh"]["vertices"].is_number_integer());
  EXPECT_TRUE(j["memory"]["G_bytes"].is_number_float());
  EXPECT_TRUE(j["output"]["bytes"].is_number_integer());
  EXPECT_EQ(j["shards"][0]["columns"], nlohmann::json({0, 384}));
  EXPECT_FALSE(j["memory"].contains("estimate_bytes")) << "absent values are left out";
  EXPECT_FALSE(j["checks"].contains("tolerance"));
  // No sidecar: null, as --no-xdmf documents it.
  EXPECT_TRUE(j["output"]["xdmf"].is_null());
  // The phases keep their order.
  EXPECT_EQ(j["phases"][2]["name"], "solves");
  EXPECT_EQ(j["phases"][2]["gflop_per_s"], 12.5);
}

TEST(PrecomputeReport, ForeignOrDamagedJsonGivesWhatCanBeRead) {
  EXPECT_TRUE(report_from_json("not json").producer.empty());
  const PrecomputeReport r =
      report_from_json(R"({"producer": "x", "mesh": {"vertices": "many"}, "checks": 3})");
  EXPECT_EQ(r.producer, "x");
  ASSERT_TRUE(r.mesh);
  EXPECT_EQ(r.mesh->vertices, 0) << "a value of the wrong type is left empty";
  EXPECT_FALSE(r.checks);
  // A report without mesh or checks prints its first line only.
  EXPECT_EQ(format_report(r), "palpate-precompute report (x)\n");
}

TEST(PrecomputeReport, TextForATerminal) {
  const std::string text = format_report(full_report());
  for (const char* line :
       {"mesh       organ.msh: 802 vertices, 3929 tetrahedra",
        "material   tumour: E = 3.4e+05 Pa, nu = 0.45", "solves       factor: amd ordering",
        "symmetry error 1.00e-15", "shard      organ.part-0-384.h5: columns 0:384",
        "output     organ.h5 (float64, 4.3 MB)"})
    EXPECT_NE(text.find(line), std::string::npos) << line << "\nin\n" << text;
}

}  // namespace
}  // namespace palpate
