#include "fuzz_support.hpp"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>

#include "box_job.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace palpate::fuzz {

namespace {

struct ScratchDir {
  std::filesystem::path path;
  ScratchDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "palpate-fuzz-XXXXXX").string();
    if (!::mkdtemp(pattern.data())) fail("cannot create a scratch directory under $TMPDIR");
    path = pattern;
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

struct Box {
  std::filesystem::path file;
  SurfaceModel model;
  Box() {
    PrecomputeJob job = testing::box_job(scratch_dir(), "box", 2);
    job.write_xdmf = false;
    run_precompute(job, {});
    file = job.output;
    model = load_surface_model("box", file);
  }
};

const Box& box() {
  static const Box instance;
  return instance;
}

}  // namespace

const std::filesystem::path& scratch_dir() {
  static const ScratchDir dir;
  return dir.path;
}

std::filesystem::path write_scratch_file(const std::string& name,
                                         std::span<const std::uint8_t> bytes) {
  const auto path = scratch_dir() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  if (!out.flush()) fail("cannot write " + path.string());
  return path;
}

const std::filesystem::path& box_compliance_file() { return box().file; }
const SurfaceModel& box_model() { return box().model; }

void serve(const SurfaceModel& model) {
  const int n = model.compliance_vertex_count();
  const std::uint32_t vertices = model.mesh_vertex_count();
  const std::size_t drawn = model.surface.vertex_ids.size();
  PALPATE_FUZZ_CHECK(model.G.rows() == 3 * n && model.G.cols() == 3 * n && model.G.allFinite());
  PALPATE_FUZZ_CHECK(model.surface.rest_positions_m.size() == 3 * drawn);
  PALPATE_FUZZ_CHECK(drawn >= static_cast<std::size_t>(n) &&
                     model.surface.triangles.size() % 3 == 0);
  for (const std::uint32_t id : model.surface.vertex_ids) PALPATE_FUZZ_CHECK(id < vertices);
  for (const std::uint32_t t : model.surface.triangles) PALPATE_FUZZ_CHECK(t < drawn);
  for (int a = 0; a < n; ++a)
    PALPATE_FUZZ_CHECK(model.compliance_index_of_vertex[model.surface.vertex_ids[a]] == a);
  for (const double x : model.surface.rest_positions_m) PALPATE_FUZZ_CHECK(std::isfinite(x));
  if (n == 0) return;

  SolverLimits limits;
  limits.max_constraints = 8;
  ConstraintSolver solver(model, limits);
  const double up[3] = {0, 0, 1e-3}, normal[3] = {0, 0, 1};
  RequestStatus status = solver.begin(1);
  if (status == RequestStatus::kOk) status = solver.add(model.surface.vertex_ids[0], 1, up, normal);
  if (status == RequestStatus::kOk) status = solver.solve();
  if (status == RequestStatus::kOk) {
    Eigen::VectorXd u(3 * n);
    solver.surface_displacement(u);
    PALPATE_FUZZ_CHECK(solver.forces().allFinite() && u.allFinite());
  }

  ToolGeometry probe;
  probe.id = "probe";
  ToolContactEngine engine(model, {probe}, ContactSettings{}, limits);
  ToolPoseInput pose;
  pose.sequence = 1;
  pose.position_m = Eigen::Vector3d(model.surface.rest_positions_m.data());
  if (engine.check(0, pose) == PoseProblem::kNone) {
    engine.update(0, pose, 0);
    PALPATE_FUZZ_CHECK(engine.output(0).force_n.allFinite());
  }
}

void fail(std::string_view what) {
  std::fprintf(stderr, "palpate fuzz: %.*s\n", static_cast<int>(what.size()), what.data());
  std::fflush(stderr);
  std::abort();
}

}  // namespace palpate::fuzz
