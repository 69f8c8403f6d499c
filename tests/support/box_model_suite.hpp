#pragma once
// A GoogleTest fixture whose test suite shares one served model of the
// clamped box (box_job: 100 × 50 × 40 mm, clamped on x = 0, soft tissue
// unless told otherwise), computed once per suite through the real
// precompute pipeline.

#include <gtest/gtest.h>

#include <Eigen/Core>

#include "palpate/runtime/surface_model.hpp"
#include "support/box_job.hpp"
#include "support/test_meshes.hpp"

namespace palpate::testing {

/// @tparam Cells cubes along x (12.5 mm cubes at 8).
/// @tparam YoungModulusKpa the material's Young modulus, kPa (85: liver).
template <int Cells = 8, int YoungModulusKpa = 85>
class BoxModelSuite : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    model_ = new SurfaceModel(load_surface_model(
        "box", write_box_compliance(dir_->path(), "box", Cells, YoungModulusKpa * 1e3)));
  }
  static void TearDownTestSuite() {
    delete model_;
    model_ = nullptr;
    delete dir_;
    dir_ = nullptr;
  }
  static const SurfaceModel& model() { return *model_; }
  static const std::filesystem::path& directory() { return dir_->path(); }

  /// The compliance vertex of the top face (z = 40 mm) nearest (x, y) in mm.
  static int top_vertex(double x_mm, double y_mm) {
    return box_top_vertex(model().surface.rest_positions_m, model().compliance_vertex_count(), x_mm,
                          y_mm);
  }
  /// Drawn vertex @p j at rest, m.
  static Eigen::Vector3d rest(int j) {
    return Eigen::Map<const Eigen::Vector3d>(
        &model().surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
  }

 private:
  inline static TempDir* dir_ = nullptr;
  inline static SurfaceModel* model_ = nullptr;
};

}  // namespace palpate::testing
