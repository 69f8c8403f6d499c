#include "palpate/core/rotation.hpp"

#include <Eigen/SVD>

namespace palpate {

Eigen::Quaterniond rotation_taking(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  return Eigen::Quaterniond::FromTwoVectors(from, to);
}

}  // namespace palpate
