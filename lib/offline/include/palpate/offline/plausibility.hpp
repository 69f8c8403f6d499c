#pragma once
/// @file
/// Values a user could mean but probably did not: a Young's modulus typed in
/// kPa as Pa, a mesh in millimetres read as metres, a Poisson ratio so close
/// to 0.5 that linear tetrahedra lock. Each is a warning (docs/errors.md,
/// "Warnings"), printed even with -q; the run goes on.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "palpate/core/organ_size.hpp"

namespace palpate {

/// Young's moduli of soft tissues and their phantoms, Pa: from about 1 kPa
/// (brain, fat) to 1 MPa (cartilage, stiff silicone); liver 10 to 170 kPa.
inline constexpr double kPlausibleYoungModulusMinPa = 1e3;
inline constexpr double kPlausibleYoungModulusMaxPa = 1e6;
/// Above this Poisson ratio, linear (P1) tetrahedra lock: λ/μ = 2ν/(1 − 2ν)
/// passes 49, and the element is much too stiff in pressing and bending.
inline constexpr double kLockingPoissonRatio = 0.49;
// Organ sizes (kPlausibleOrganMinM, kPlausibleOrganMaxM): palpate/core/organ_size.hpp,
// which palpated checks too.

/// Densities of soft tissues, kg/m³: fat about 950, liver and muscle about
/// 1,060, cortical bone 1,900; outside this range a density was probably
/// typed in another unit (g/cm³ gives 1.06).
inline constexpr double kPlausibleDensityMinKgM3 = 500;
inline constexpr double kPlausibleDensityMaxKgM3 = 2000;

/// A warning when @p density_kg_m3 (the cut region's) is outside what
/// tissues have.
std::optional<std::string> density_warning(double density_kg_m3);

/// A warning when @p young_modulus_pa is outside what tissues and phantoms
/// have; @p what names the material ("organ", a group).
std::optional<std::string> young_modulus_warning(double young_modulus_pa, std::string_view what);

/// A warning when @p poisson_ratio locks linear tetrahedra (> 0.49) or is
/// negative (no soft tissue is auxetic).
std::optional<std::string> poisson_ratio_warning(double poisson_ratio, std::string_view what);

/// The size a mesh's bounding-box diagonal (given in the file's numbers)
/// would have in one length unit.
struct UnitReading {
  std::string unit;   ///< "m", "cm", "mm"
  double diagonal_m;  ///< the diagonal in metres with that unit
  bool plausible;     ///< within [kPlausibleOrganMinM, kPlausibleOrganMaxM]
};
/// The readings of @p diagonal (file units) in m, cm and mm.
std::vector<UnitReading> unit_readings(double diagonal);
/// The unit that makes @p diagonal (file units) most like an organ (nearest
/// to 0.2 m on a log scale).
std::string likely_unit(double diagonal);

/// A warning when the organ, @p diagonal_m across with unit @p unit, is not
/// an organ's size; it suggests the unit that would make it one.
/// @p source names the mesh file.
std::optional<std::string> organ_size_warning(double diagonal_m, std::string_view unit,
                                              std::string_view source);

}  // namespace palpate
