#include "box_job.hpp"

#include <algorithm>
#include <cmath>

#include "test_meshes.hpp"

namespace palpate::testing {

PrecomputeJob clamped_job(const TetMesh& mesh, const std::filesystem::path& dir,
                          const std::string& name, double young_modulus_pa) {
  write_msh22(mesh, dir / (name + ".msh"));
  PrecomputeJob job;
  job.mesh_file = dir / (name + ".msh");
  job.young_modulus_pa = young_modulus_pa;
  job.poisson_ratio = 0.45;
  job.attachment.half_spaces.push_back({{0.001, 0, 0}, {-1, 0, 0}});
  job.output = dir / (name + ".h5");
  return job;
}

std::filesystem::path write_clamped_compliance(const TetMesh& mesh,
                                               const std::filesystem::path& dir,
                                               const std::string& name, double young_modulus_pa) {
  const PrecomputeJob job = clamped_job(mesh, dir, name, young_modulus_pa);
  run_precompute(job, {});
  return job.output;
}

PrecomputeJob box_job(const std::filesystem::path& dir, const std::string& name, int cells,
                      double young_modulus_pa) {
  const int side = std::max(2, cells / 2);
  return clamped_job(box_mesh(0.1, 0.05, 0.04, cells, side, side), dir, name, young_modulus_pa);
}

std::filesystem::path write_box_compliance(const std::filesystem::path& dir,
                                           const std::string& name, int cells,
                                           double young_modulus_pa) {
  const PrecomputeJob job = box_job(dir, name, cells, young_modulus_pa);
  run_precompute(job, {});
  return job.output;
}

int box_top_vertex(std::span<const double> rest_positions_m, int compliance_vertex_count,
                   double x_mm, double y_mm) {
  int best = -1;
  double best_d = 1e9;
  for (int j = 0; j < compliance_vertex_count; ++j) {
    const double* p = &rest_positions_m[3 * static_cast<std::size_t>(j)];
    if (std::abs(p[2] - 0.040) > 1e-9) continue;
    const double d = std::hypot(p[0] - x_mm * 1e-3, p[1] - y_mm * 1e-3);
    if (d < best_d) best_d = d, best = j;
  }
  return best;
}

}  // namespace palpate::testing
