#pragma once
/// @file
/// Named unit conversions for the edges (configuration files, gesture files,
/// command lines): palpate computes in SI (m, N, Pa, rad, s) inside.

namespace palpate {

/// Millimetres to metres.
constexpr double millimetres(double mm) { return mm * 1e-3; }
/// Degrees to radians.
constexpr double degrees(double deg) { return deg * 3.14159265358979323846 / 180; }
/// Radians to degrees, for messages.
constexpr double in_degrees(double rad) { return rad * 180 / 3.14159265358979323846; }

}  // namespace palpate
