// examples/devices/device_frames.h: the rotations the device SDKs give (a
// column-major 4 x 4 transform in mm, a row-major 3 x 3 matrix) to the
// position and quaternion palpate/device.h takes.

#include "device_frames.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

namespace {

// Round-off of Shepperd's method on a unit quaternion: a few ulp.
constexpr double kTolerance = 1e-12;

/// q and −q are the same rotation.
double distance(const Eigen::Quaterniond& a, const double q[4]) {
  const Eigen::Vector4d x(q[0], q[1], q[2], q[3]), y(a.w(), a.x(), a.y(), a.z());
  return std::min((x - y).norm(), (x + y).norm());
}

TEST(DeviceFrames, EveryBranchOfShepperdsMethodGivesTheRotationBack) {
  std::mt19937 random(19);
  std::normal_distribution<double> normal;
  // Random rotations, and the half turns that take each of its branches.
  std::vector<Eigen::Quaterniond> rotations = {
      Eigen::Quaterniond::Identity(), Eigen::Quaterniond(0, 1, 0, 0),
      Eigen::Quaterniond(0, 0, 1, 0), Eigen::Quaterniond(0, 0, 0, 1),
      Eigen::Quaterniond(0.5, 0.5, 0.5, 0.5)};
  for (int i = 0; i < 200; ++i)
    rotations.emplace_back(
        Eigen::Quaterniond(normal(random), normal(random), normal(random), normal(random))
            .normalized());
  for (const auto& expected : rotations) {
    const Eigen::Matrix3d R = expected.toRotationMatrix();
    double rows[3][3], q[4];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) rows[i][j] = R(i, j);
    palpate_quaternion_of_rows(rows, q);
    EXPECT_LT(distance(expected, q), kTolerance) << R;
    EXPECT_NEAR(Eigen::Vector4d(q[0], q[1], q[2], q[3]).norm(), 1.0, kTolerance);
  }
}

TEST(DeviceFrames, AnOpenHapticsTransformIsColumnMajorInMillimetres) {
  const Eigen::Quaterniond expected =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()));
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = expected.toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(12.5, -40, 88);  // mm
  double m[16];
  Eigen::Map<Eigen::Matrix4d> view(m);  // Eigen's default storage: column-major, as OpenGL's
  view = T;
  ASSERT_EQ(m[12], 12.5);
  double p[3], q[4];
  palpate_pose_of_hd_transform(m, p, q);
  EXPECT_NEAR(p[0], 0.0125, 1e-15);
  EXPECT_NEAR(p[1], -0.040, 1e-15);
  EXPECT_NEAR(p[2], 0.088, 1e-15);
  EXPECT_LT(distance(expected, q), kTolerance);
}

TEST(DeviceFrames, OpenHapticsAxesTurnOntoXTowardsTheUserYRightZUp) {
  // (0.5, 0.5, 0.5, 0.5): the HD frame's x (right) becomes y, y (up)
  // becomes z, z (towards the user) becomes x.
  const Eigen::Quaterniond r(0.5, 0.5, 0.5, 0.5);
  EXPECT_LT((r * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), kTolerance);
  EXPECT_LT((r * Eigen::Vector3d::UnitY() - Eigen::Vector3d::UnitZ()).norm(), kTolerance);
  EXPECT_LT((r * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitX()).norm(), kTolerance);
}

}  // namespace
