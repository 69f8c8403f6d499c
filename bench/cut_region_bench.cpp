// The cuttable region (issue 20): what the outside's compliance on its
// boundary (Γ and its part of the organ's surface) costs against the whole
// organ's surface compliance, by the same method in the same run, and how
// the interface Γ grows with the region (a ball of three radii) on the
// sample organ (BENCHMARKS.md, "The cuttable region").
//
//   build/bench/palpate_cut_region_bench [mesh_size_m] [repetitions]
//
// A small timed program: each compliance is computed `repetitions` times
// (default 3) and the median is printed.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <unistd.h>
#include <vector>

#include "palpate/core/system_info.hpp"
#include "palpate/offline/compliance.hpp"
#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/fem.hpp"
#include "palpate/offline/mesh_io.hpp"

namespace {

using namespace palpate;

double median_seconds(int repetitions, const std::function<void()>& run) {
  std::vector<double> t;
  for (int r = 0; r < repetitions; ++r) {
    const auto start = std::chrono::steady_clock::now();
    run();
    t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
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
  std::printf("# blas: %s\n# sample organ, mesh size %.4g m: %ld vertices, %ld tetrahedra; "
              "median of %d\n",
              blas_description().c_str(), size_m, static_cast<long>(mesh.vertices.rows()),
              static_cast<long>(mesh.tetrahedra.rows()), repetitions);

  const DofMap whole_dofs = make_dof_map(extract_boundary(mesh).on_surface, fixed);
  const SparseMatrixd K =
      assemble_stiffness(mesh.vertices, mesh.tetrahedra, material, materials, whole_dofs);
  const int m = whole_dofs.surface_dofs();
  ComplianceOptions quiet;
  quiet.check_columns = 2;
  const double whole_solves = median_seconds(
      repetitions, [&] { compliance_by_solves(K, m, quiet, nullptr); });
  const double whole_condensation = median_seconds(
      repetitions, [&] { compliance_by_condensation(K, m, quiet, nullptr); });
  std::printf("| model | region tets | free Γ | outside S | G's vertices | solves | condensation |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  std::printf("| whole organ (baseline) | 0 | 0 | %d | %d | %.3f s | %.3f s |\n", m / 3, m / 3,
              whole_solves, whole_condensation);

  // Balls about a point under the surface at the far end from the attachment.
  const Eigen::Vector3d centre_m(0.065, 0, 0.015);
  for (const double radius_m : {0.010, 0.015, 0.020}) {
    const RegionSplit split = split_region(mesh, RegionSpec::sphere(centre_m, radius_m), fixed);
    for (const auto& w : split.warnings) std::printf("# warning: %s\n", w.c_str());
    OutsideCompliance out;
    const double solves = median_seconds(repetitions, [&] {
      out = outside_compliance(split, material, materials, OutsideMethod::solves, quiet);
    });
    const double condensation = median_seconds(repetitions, [&] {
      out = outside_compliance(split, material, materials, OutsideMethod::condensation, quiet);
    });
    std::printf("| outside of a ball of %.0f mm | %zu | %zu | %zu | %zu | %.3f s | %.3f s |\n",
                radius_m * 1e3, split.region_tets.size(), out.interface.size(),
                out.surface.size(), out.vertices.size(), solves, condensation);
  }
  return 0;
}
