#pragma once
// What the served hybrid region's tests share (hybrid_serving_test,
// hybrid_dynamics_test): a box organ with a cuttable region, precomputed,
// loaded as palpated loads it, and the rest's vertex nearest a point.

#include <Eigen/Core>

#include "palpate/offline/cut_region.hpp"
#include "palpate/offline/precompute.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "support/box_job.hpp"
#include "support/test_meshes.hpp"

namespace palpate::testing {

// A 96 × 64 × 48 mm box, 12 × 8 × 8 cells (8 × 8 × 6 mm), clamped on x = 0;
// the region is the block of cells i ≥ 8, 2 ≤ j < 6, k ≥ 4: under the top
// face at the free end, 384 tetrahedra.
inline constexpr double kLx = 0.096, kLy = 0.064, kLz = 0.048;
inline constexpr int kNx = 12, kNy = 8, kNz = 8;
inline constexpr double kE = 85e3, kNu = 0.45;

struct Organ {
  TempDir dir;
  TetMesh mesh = box_mesh(kLx, kLy, kLz, kNx, kNy, kNz);
  SurfaceModel model;

  Organ() {
    PrecomputeJob job = clamped_job(mesh, dir.path(), "organ", kE);
    job.cut_region =
        CutRegionJob{RegionSpec::box({0.064, 0.016, 0.024}, {kLx, 0.048, kLz}), 1060, 20};
    run_precompute(job, {});
    model = load_surface_model("organ", job.output);
  }
};

/// The rest's compliance vertex nearest @p x.
inline int rest_vertex_near(const SurfaceModel& m, const Eigen::Vector3d& x) {
  int best = 0;
  for (int a = 1; a < m.compliance_vertex_count(); ++a)
    if ((m.surface.rest_position(a) - x).norm() < (m.surface.rest_position(best) - x).norm())
      best = a;
  return best;
}

}  // namespace palpate::testing
