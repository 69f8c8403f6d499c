#include "palpate/offline/plausibility.hpp"

#include <fmt/format.h>

#include <cmath>

#include "palpate/offline/mesh_io.hpp"

namespace palpate {

namespace {

/// "85 Pa" read as what the user may have meant, e.g. "85 kPa = 85e3 Pa".
std::string scaled_guess(double e_pa) {
  if (e_pa < kPlausibleYoungModulusMinPa && e_pa * 1e3 >= kPlausibleYoungModulusMinPa &&
      e_pa * 1e3 <= kPlausibleYoungModulusMaxPa)
    return fmt::format("; if it is in kPa, give {:g}e3 Pa", e_pa);
  return "";
}

}  // namespace

std::optional<std::string> young_modulus_warning(double e, std::string_view what) {
  if (e >= kPlausibleYoungModulusMinPa && e <= kPlausibleYoungModulusMaxPa) return std::nullopt;
  return fmt::format(
      "{}: Young's modulus {:g} Pa is outside what soft tissues and their phantoms have "
      "({:g} Pa to {:g} MPa; liver 10 to 170 kPa){}: check the unit (Pa)",
      what, e, kPlausibleYoungModulusMinPa, kPlausibleYoungModulusMaxPa / 1e6, scaled_guess(e));
}

std::optional<std::string> poisson_ratio_warning(double nu, std::string_view what) {
  if (nu > kLockingPoissonRatio)
    return fmt::format(
        "{}: Poisson ratio {:g} is so close to 0.5 that linear tetrahedra lock (λ/μ = {:.0f}): "
        "the organ will be much too stiff in pressing and bending; soft tissue models use "
        "0.45 to {:g}",
        what, nu, 2 * nu / (1 - 2 * nu), kLockingPoissonRatio);
  if (nu < 0)
    return fmt::format(
        "{}: Poisson ratio {:g} is negative (a material that thickens when stretched); soft "
        "tissues are 0.45 to 0.49",
        what, nu);
  return std::nullopt;
}

std::optional<std::string> density_warning(double rho) {
  if (rho >= kPlausibleDensityMinKgM3 && rho <= kPlausibleDensityMaxKgM3) return std::nullopt;
  return fmt::format(
      "cut region: density {:g} kg/m³ is outside what soft tissues have ({:g} to {:g} kg/m³; "
      "liver about 1,060){}: check the unit (kg/m³)",
      rho, kPlausibleDensityMinKgM3, kPlausibleDensityMaxKgM3,
      rho < kPlausibleDensityMinKgM3 && rho * 1e3 >= kPlausibleDensityMinKgM3 &&
              rho * 1e3 <= kPlausibleDensityMaxKgM3
          ? fmt::format("; if it is in g/cm³, give {:g}", rho * 1e3)
          : std::string());
}

std::vector<UnitReading> unit_readings(double diagonal) {
  std::vector<UnitReading> readings;
  for (const char* name : {"m", "cm", "mm"}) {
    const double d = diagonal * parse_length_unit(name).to_metres;
    readings.push_back({name, d, plausible_organ_size(d)});
  }
  return readings;
}

std::string likely_unit(double diagonal) {
  std::string best = "m";
  double best_distance = INFINITY;
  for (const auto& r : unit_readings(diagonal))
    if (const double d = std::abs(std::log(r.diagonal_m / 0.2)); d < best_distance) {
      best_distance = d;
      best = r.unit;
    }
  return best;
}

std::optional<std::string> organ_size_warning(double diagonal_m, std::string_view unit,
                                              std::string_view source) {
  if (plausible_organ_size(diagonal_m)) return std::nullopt;
  const double in_file = diagonal_m / parse_length_unit(std::string(unit)).to_metres;
  const std::string guess = likely_unit(in_file);
  const double with_guess = in_file * parse_length_unit(guess).to_metres;
  return fmt::format(
      "{}: the organ is {:.3g} m across with --mesh-unit {} ({:g} in the file's numbers), not "
      "an organ's size ({:g} to {:g} m){}",
      source, diagonal_m, unit, in_file, kPlausibleOrganMinM, kPlausibleOrganMaxM,
      guess != unit ? fmt::format("; with --mesh-unit {} it is {:.3g} m", guess, with_guess)
                    : std::string());
}

}  // namespace palpate
