#include "palpate/runtime/rotation_field.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "palpate/core/error.hpp"

namespace palpate {

namespace {

using Matrix9d = Eigen::Matrix<double, 9, 9>;
using Matrix39d = Eigen::Matrix<double, 3, 9>;

/// The axial vector of skew(A) = (A − Aᵀ)/2, A stored row-major in 9 values.
Matrix39d axial_of_skew() {
  Matrix39d s = Matrix39d::Zero();
  s(0, 7) = 0.5;  // (A₂₁ − A₁₂)/2
  s(0, 5) = -0.5;
  s(1, 2) = 0.5;  // (A₀₂ − A₂₀)/2
  s(1, 6) = -0.5;
  s(2, 3) = 0.5;  // (A₁₀ − A₀₁)/2
  s(2, 1) = -0.5;
  return s;
}

/// The 3 × 9 rows that give A e from A row-major: (A e)_i = Σ_k A_ik e_k.
Matrix39d rows_of(const Eigen::Vector3d& e) {
  Matrix39d c = Matrix39d::Zero();
  for (int i = 0; i < 3; ++i) c.block<1, 3>(i, 3 * i) = e.transpose();
  return c;
}

/// The ring of every drawn vertex: the vertices sharing a triangle with it.
std::vector<std::vector<int>> rings(const DrawnSurface& surface) {
  std::vector<std::vector<int>> ring(static_cast<std::size_t>(surface.vertex_count()));
  for (int t = 0; t < surface.triangle_count(); ++t) {
    const std::uint32_t* v = &surface.triangles[3 * static_cast<std::size_t>(t)];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (i != j) ring[v[i]].push_back(static_cast<int>(v[j]));
  }
  for (auto& r : ring) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }
  return ring;
}

}  // namespace

RotationField::RotationField(const DrawnSurface& surface, double smoothing_radius_m)
    : n_(surface.compliance_vertex_count), radius_(smoothing_radius_m) {
  if (!(smoothing_radius_m > 0) || !std::isfinite(smoothing_radius_m))
    throw InputError(
        fmt::format("warping: smoothing radius {:g} m; a positive length in metres is accepted",
                    smoothing_radius_m));
  const auto normals = vertex_normals(surface);
  const auto ring = rings(surface);
  const Matrix39d skew = axial_of_skew();

  // Ω: one least-squares gradient fit per compliance vertex.
  fit_start_.assign(1, 0);
  for (int v = 0; v < n_; ++v) {
    const auto& r = ring[static_cast<std::size_t>(v)];
    const Eigen::Vector3d n = normals.row(v).transpose();
    if (r.size() >= 2 && n.squaredNorm() > 0.5) {
      const Eigen::Vector3d p = surface.rest_position(v);
      double h2 = 0;
      for (const int j : r) h2 += (surface.rest_position(j) - p).squaredNorm();
      const double h = std::sqrt(h2 / static_cast<double>(r.size()));
      // h ½ (A n + Aᵀ n) = 0: three rows, weighted like one edge.
      Matrix39d c_normal = Matrix39d::Zero();
      for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) {
          c_normal(i, 3 * i + k) += 0.5 * h * n[k];
          c_normal(i, 3 * k + i) += 0.5 * h * n[k];
        }
      Matrix9d normal_matrix = c_normal.transpose() * c_normal;
      for (const int j : r) {
        const Matrix39d c = rows_of(surface.rest_position(j) - p);
        normal_matrix += c.transpose() * c;
      }
      const Eigen::LLT<Matrix9d> llt(normal_matrix);
      if (llt.info() == Eigen::Success) {
        Eigen::Matrix3d self = Eigen::Matrix3d::Zero();
        for (const int j : r) {
          // ω = S_x A, A = M⁻¹ Σ_j C_jᵀ (u_j − u_v).
          const Eigen::Matrix3d block =
              skew * llt.solve(rows_of(surface.rest_position(j) - p).transpose());
          self -= block;
          if (j < n_) {  // a fixed neighbour does not move
            fit_vertex_.push_back(j);
            fit_block_.insert(fit_block_.end(), block.data(), block.data() + 9);
          }
        }
        fit_vertex_.push_back(v);
        fit_block_.insert(fit_block_.end(), self.data(), self.data() + 9);
      }
    }
    fit_start_.push_back(static_cast<int>(fit_vertex_.size()));
  }

  // S: Gaussian weights within 2ρ, found by a sweep along x.
  std::vector<int> order(static_cast<std::size_t>(n_));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return surface.rest_positions_m[3 * static_cast<std::size_t>(a)] <
           surface.rest_positions_m[3 * static_cast<std::size_t>(b)];
  });
  std::vector<int> rank(static_cast<std::size_t>(n_));
  for (int k = 0; k < n_; ++k)
    rank[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])] = k;
  const double reach = 2 * radius_, reach2 = reach * reach;
  smooth_start_.assign(1, 0);
  for (int v = 0; v < n_; ++v) {
    const Eigen::Vector3d p = surface.rest_position(v);
    const auto begin = smooth_vertex_.size();
    double total = 0;
    auto visit = [&](int k) {
      const int w = order[static_cast<std::size_t>(k)];
      const Eigen::Vector3d q = surface.rest_position(w);
      if (std::abs(q.x() - p.x()) > reach) return false;
      const double d2 = (q - p).squaredNorm();
      if (d2 <= reach2) {
        const double weight = std::exp(-d2 / (radius_ * radius_));
        smooth_vertex_.push_back(w);
        smooth_weight_.push_back(weight);
        total += weight;
      }
      return true;
    };
    for (int k = rank[static_cast<std::size_t>(v)]; k < n_ && visit(k); ++k) {
    }
    for (int k = rank[static_cast<std::size_t>(v)] - 1; k >= 0 && visit(k); --k) {
    }
    for (auto i = begin; i < smooth_weight_.size(); ++i) smooth_weight_[i] /= total;
    smooth_start_.push_back(static_cast<int>(smooth_vertex_.size()));
  }
  fitted_.assign(3 * static_cast<std::size_t>(n_), 0.0);
}

double default_smoothing_radius(const DrawnSurface& surface, double edges) {
  std::vector<double> lengths;
  for (int t = 0; t < surface.triangle_count(); ++t) {
    const std::uint32_t* v = &surface.triangles[3 * static_cast<std::size_t>(t)];
    for (int i = 0; i < 3; ++i) {
      const auto a = static_cast<int>(v[i]), b = static_cast<int>(v[(i + 1) % 3]);
      if (a < surface.compliance_vertex_count && b < surface.compliance_vertex_count)
        lengths.push_back((surface.rest_position(a) - surface.rest_position(b)).norm());
    }
  }
  if (lengths.empty()) return 1e-3;
  std::nth_element(lengths.begin(),
                   lengths.begin() + static_cast<std::ptrdiff_t>(lengths.size() / 2),
                   lengths.end());
  return edges * lengths[lengths.size() / 2];
}

void RotationField::support(int v, std::vector<char>& mark, std::vector<int>& out) const {
  for (int k = smooth_start_[static_cast<std::size_t>(v)];
       k < smooth_start_[static_cast<std::size_t>(v) + 1]; ++k) {
    const int b = smooth_vertex_[static_cast<std::size_t>(k)];
    for (int i = fit_start_[static_cast<std::size_t>(b)];
         i < fit_start_[static_cast<std::size_t>(b) + 1]; ++i) {
      const int j = fit_vertex_[static_cast<std::size_t>(i)];
      if (!mark[static_cast<std::size_t>(j)]) {
        mark[static_cast<std::size_t>(j)] = 1;
        out.push_back(j);
      }
    }
  }
}

Eigen::Vector3d RotationField::rotation_at(int v, std::span<const double> u_m) const {
  const auto u = [&](int j) {
    return Eigen::Map<const Eigen::Vector3d>(&u_m[3 * static_cast<std::size_t>(j)]);
  };
  return smoothed_at(v, [&](int b) { return fitted_at(b, u); });
}

double RotationField::mean_neighbourhood() const {
  return n_ > 0 ? static_cast<double>(smooth_vertex_.size()) / n_ : 0.0;
}

void RotationField::rotations(std::span<const double> u_m, std::span<double> omega) const {
  // Ω u once per vertex, then S: the two steps of rotation_at() over the
  // whole surface.
  const auto u = [&](int j) {
    return Eigen::Map<const Eigen::Vector3d>(&u_m[3 * static_cast<std::size_t>(j)]);
  };
  for (int v = 0; v < n_; ++v) {
    Eigen::Map<Eigen::Vector3d> fitted(&fitted_[3 * static_cast<std::size_t>(v)]);
    fitted = fitted_at(v, u);
  }
  const auto fitted = [&](int b) {
    return Eigen::Map<const Eigen::Vector3d>(&fitted_[3 * static_cast<std::size_t>(b)]);
  };
  for (int v = 0; v < n_; ++v) {
    Eigen::Map<Eigen::Vector3d> w(&omega[3 * static_cast<std::size_t>(v)]);
    w = smoothed_at(v, fitted);
  }
}

namespace {
Eigen::Matrix3d cross_matrix(const Eigen::Vector3d& w) {
  Eigen::Matrix3d k;
  k << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return k;
}
}  // namespace

Eigen::Matrix3d rotation_matrix(const Eigen::Vector3d& omega) {
  const double a = omega.norm();
  const Eigen::Matrix3d k = cross_matrix(omega);
  // Series below 1e-4 rad: the closed forms lose digits to cancellation.
  const double s = a < 1e-4 ? 1 - a * a / 6 : std::sin(a) / a;
  const double c = a < 1e-4 ? 0.5 - a * a / 24 : (1 - std::cos(a)) / (a * a);
  return Eigen::Matrix3d::Identity() + s * k + c * k * k;
}

Eigen::Matrix3d integrated_rotation(const Eigen::Vector3d& omega) {
  const double a = omega.norm();
  const Eigen::Matrix3d k = cross_matrix(omega);
  const double c = a < 1e-4 ? 0.5 - a * a / 24 : (1 - std::cos(a)) / (a * a);
  const double s = a < 1e-4 ? 1.0 / 6 - a * a / 120 : (a - std::sin(a)) / (a * a * a);
  return Eigen::Matrix3d::Identity() + c * k + s * k * k;
}

}  // namespace palpate
