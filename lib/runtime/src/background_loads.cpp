#include "background_loads.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "palpate/core/error.hpp"

namespace palpate::detail {

void BackgroundLoads::reserve(int count, int compliance_count, std::size_t tool_loads) {
  const auto n = static_cast<std::size_t>(std::max(count, 0));
  index_.resize(n);
  force_.resize(3 * n);
  merged_index_.resize(tool_loads + n);
  merged_force_.resize(3 * (tool_loads + n));
  u_.assign(static_cast<std::size_t>(compliance_count), Eigen::Vector3d::Zero());
  u_epoch_.assign(static_cast<std::size_t>(compliance_count), 0);
}

void BackgroundLoads::set(std::span<const int> indices, std::span<const double> forces_n,
                          double energy_j) {
  if (indices.size() > index_.size() || forces_n.size() != 3 * indices.size())
    throw InputError(fmt::format(
        "{} background loads with {} forces; at most {} (reserve_background_loads), 3 forces "
        "each, are accepted",
        indices.size(), forces_n.size(), index_.size()));
  for (const int v : indices)
    if (v < 0 || v >= static_cast<int>(u_.size()))
      throw InputError(fmt::format("background load on compliance vertex {}; 0..{} are accepted", v,
                                   static_cast<int>(u_.size()) - 1));
  count_ = static_cast<int>(indices.size());
  std::copy(indices.begin(), indices.end(), index_.begin());
  std::copy(forces_n.begin(), forces_n.end(), force_.begin());
  energy_j_ = std::max(energy_j, 0.0);
  if (++epoch_ == 0) {
    std::fill(u_epoch_.begin(), u_epoch_.end(), 0);
    epoch_ = 1;
  }
}

const Eigen::Vector3d& BackgroundLoads::at(const SurfaceModel& model, int v) {
  const auto slot = static_cast<std::size_t>(v);
  if (u_epoch_[slot] != epoch_) {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int j = 0; j < count_; ++j)
      u += model.G_block(v, index_[static_cast<std::size_t>(j)]) *
           Eigen::Map<const Eigen::Vector3d>(&force_[3 * static_cast<std::size_t>(j)]);
    u_[slot] = u;
    u_epoch_[slot] = epoch_;
  }
  return u_[slot];
}

int BackgroundLoads::merge(int tool_count, const int* tool_index, const double* tool_force,
                           double tool_energy, const int*& index, const double*& force,
                           double& energy) {
  std::copy_n(tool_index, tool_count, merged_index_.begin());
  std::copy_n(tool_force, 3 * tool_count, merged_force_.begin());
  std::copy_n(index_.begin(), count_, merged_index_.begin() + tool_count);
  std::copy_n(force_.begin(), 3 * count_, merged_force_.begin() + 3 * tool_count);
  const double root = std::sqrt(tool_energy) + std::sqrt(energy_j_);
  index = merged_index_.data();
  force = merged_force_.data();
  energy = root * root;
  return tool_count + count_;
}

}  // namespace palpate::detail
