// The cuttable region (issue 20): what the outside's compliance on its
// boundary (Γ and its part of the organ's surface) costs against the whole
// organ's surface compliance, by the same method in the same run, and how
// the interface Γ grows with the region (a ball of three radii) on the
// sample organ (docs/benchmarks-history.md, "The cuttable region").
//
//   build/bench/palpate_cut_region_bench [mesh_size_m] [repetitions]
//
// A small timed program: each compliance is computed `repetitions` times
// (default 3), the cases in turn, and the median is printed.

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "palpate/core/system_info.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh_io.hpp"

namespace {

using namespace palpate;

double once(const std::function<void()>& run) {
  const auto start = std::chrono::steady_clock::now();
  run();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  const double size_m = argc > 1 ? std::atof(argv[1]) : 0.008;
  const int repetitions = argc > 2 ? std::atoi(argv[2]) : 3;
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("palpate-cut-bench-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  write_sample_organ(dir / "organ.msh", size_m);
  TetMesh mesh = read_mesh(dir / "organ.msh", {});
  std::filesystem::remove_all(dir);
  validate_and_compact(mesh);

  // Held near one end (as tests/offline/compliance_test.cpp); parenchyma
  // 85 kPa, the tumour four times stiffer; ν = 0.45.
  std::vector<int> fixed;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v)
    if ((mesh.vertices.row(v) - Eigen::RowVector3d(-0.03, 0, 0.04)).norm() < 0.025)
      fixed.push_back(static_cast<int>(v));
  const Eigen::VectorXi material = (mesh.tet_group.array() == 2).cast<int>();
  const std::vector<Lame> materials = {lame_parameters(85e3, 0.45), lame_parameters(340e3, 0.45)};
  std::printf(
      "# blas: %s\n# sample organ, mesh size %.4g m: %ld vertices, %ld tetrahedra; "
      "median of %d\n",
      blas_description().c_str(), size_m, static_cast<long>(mesh.vertices.rows()),
      static_cast<long>(mesh.tetrahedra.rows()), repetitions);

  // Each case times its K's assembly and its compliance by one method; the
  // repetitions run the cases in turn (whole, then each ball), so that a
  // change of the shared machine's load falls on all of them alike.
  ComplianceOptions quiet;
  quiet.check_columns = 2;
  const DofMap whole_dofs = make_dof_map(extract_boundary(mesh).on_surface, fixed);
  auto whole = [&](OutsideMethod method) {
    const SparseMatrixd K =
        assemble_stiffness(mesh.vertices, mesh.tetrahedra, material, materials, whole_dofs);
    const int m = whole_dofs.surface_dofs();
    if (method == OutsideMethod::solves)
      compliance_by_solves(K, m, quiet, nullptr);
    else
      compliance_by_condensation(K, m, quiet, nullptr);
  };
  // Balls about a point under the surface at the far end from the attachment.
  const Eigen::Vector3d centre_m(0.065, 0, 0.015);
  const std::vector<double> radii_m = {0.010, 0.015, 0.020};
  std::vector<RegionSplit> splits;
  for (const double r : radii_m) {
    splits.push_back(split_region(mesh, RegionSpec::sphere(centre_m, r), fixed));
    for (const auto& w : splits.back().warnings) std::printf("# warning: %s\n", w.c_str());
  }
  std::vector<OutsideCompliance> outside(splits.size());
  const size_t cases = 1 + splits.size();
  std::vector<std::vector<double>> seconds(2 * cases);
  for (int rep = 0; rep < repetitions; ++rep)
    for (const OutsideMethod method : {OutsideMethod::solves, OutsideMethod::condensation})
      for (size_t c = 0; c < cases; ++c) {
        const size_t slot = 2 * c + (method == OutsideMethod::solves ? 0 : 1);
        seconds[slot].push_back(once([&] {
          if (c == 0)
            whole(method);
          else
            outside[c - 1] = outside_compliance(splits[c - 1], material, materials, method, quiet);
        }));
      }
  auto median = [&](size_t slot) {
    std::vector<double> t = seconds[slot];
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
  };
  std::printf(
      "| model | region tets | free Γ | outside S | G's vertices | solves | condensation |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  const int n_whole = static_cast<int>(whole_dofs.compliance_vertices.size());
  std::printf("| whole organ (baseline) | 0 | 0 | %d | %d | %.3f s | %.3f s |\n", n_whole, n_whole,
              median(0), median(1));
  for (size_t b = 0; b < splits.size(); ++b)
    std::printf("| outside of a ball of %.0f mm | %zu | %zu | %zu | %zu | %.3f s | %.3f s |\n",
                radii_m[b] * 1e3, splits[b].region_tets.size(), outside[b].interface.size(),
                outside[b].surface.size(), outside[b].vertices.size(), median(2 * (b + 1)),
                median(2 * (b + 1) + 1));
  return 0;
}
