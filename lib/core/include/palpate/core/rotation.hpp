#pragma once
/// @file
/// The rotation taking one direction onto another, compiled once: Eigen's
/// Quaternion::FromTwoVectors instantiates a 2 × 3 JacobiSVD (for opposite
/// vectors), about 6 s of compile time in every file that calls it.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace palpate {

/// The smallest rotation taking direction @p from onto direction @p to
/// (neither needs to be unit; both nonzero): Eigen's
/// Quaternion::FromTwoVectors. For opposite directions it turns by π about
/// an axis normal to both. A tool pointing along `axis` (its +z, the shaft
/// towards the tip, onto `axis`) is rotation_taking(Vector3d::UnitZ(), axis).
Eigen::Quaterniond rotation_taking(const Eigen::Vector3d& from, const Eigen::Vector3d& to);

}  // namespace palpate
