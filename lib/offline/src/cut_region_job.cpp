#include "cut_region_job.hpp"

#include <fmt/format.h>

#include <cmath>

#include "palpate/core/units.hpp"

namespace palpate::detail {

namespace {

constexpr const char* kShapes =
    "box_min_mm and box_max_mm, or sphere_center_mm and sphere_radius_mm, or group";

// A TOML float as short as reads back the same (as precompute_job.cpp's).
std::string number(double value) {
  std::string text = fmt::format("{}", value);
  if (text.find_first_of(".einf") == std::string::npos) text += ".0";
  return text;
}

// Metres written back as millimetres.
std::string mm(double metres) { return number(metres / millimetres(1)); }

Eigen::Vector3d from_mm(const Eigen::Vector3d& v_mm) {
  return v_mm.unaryExpr([](double v) { return millimetres(v); });
}

std::string mm3(const Eigen::Vector3d& v) {
  return fmt::format("[{}, {}, {}]", mm(v.x()), mm(v.y()), mm(v.z()));
}

}  // namespace

CutRegionJob read_cut_region_table(const toml::node& node, const TomlReader& r) {
  const toml::table& t = r.table(node, "cut_region");
  r.only_keys(t, "cut_region",
              {"box_min_mm", "box_max_mm", "sphere_center_mm", "sphere_radius_mm", "group",
               "density_kg_m3", "damping_per_s"});
  const auto* box_min = t.get("box_min_mm");
  const auto* box_max = t.get("box_max_mm");
  const auto* center = t.get("sphere_center_mm");
  const auto* radius = t.get("sphere_radius_mm");
  const auto* group = t.get("group");
  const int shapes = (box_min || box_max ? 1 : 0) + (center || radius ? 1 : 0) + (group ? 1 : 0);
  if (shapes != 1)
    r.fail(&t, "cut_region",
           fmt::format("{}: give exactly one shape: {}",
                       shapes == 0 ? "no shape given" : "more than one shape given", kShapes));

  CutRegionJob job;
  if (box_min || box_max) {
    if (!box_min || !box_max)
      r.fail(&t, box_min ? "cut_region.box_max_mm" : "cut_region.box_min_mm",
             "missing: a box needs both corners, box_min_mm and box_max_mm = [x, y, z] (mm)");
    const Eigen::Vector3d lo = r.vec3(*box_min, "cut_region.box_min_mm");
    const Eigen::Vector3d hi = r.vec3(*box_max, "cut_region.box_max_mm");
    for (int i = 0; i < 3; ++i)
      if (!std::isfinite(lo[i]) || !std::isfinite(hi[i]) || !(lo[i] <= hi[i]))
        r.fail(box_max, "cut_region.box_max_mm",
               fmt::format("[{}, {}, {}] is not above box_min_mm [{}, {}, {}] on axis {}: the "
                           "corners must be finite, with min ≤ max on every axis (mm)",
                           hi.x(), hi.y(), hi.z(), lo.x(), lo.y(), lo.z(), "xyz"[i]));
    job.spec = RegionSpec::box(from_mm(lo), from_mm(hi));
  } else if (center || radius) {
    if (!center || !radius)
      r.fail(&t, center ? "cut_region.sphere_radius_mm" : "cut_region.sphere_center_mm",
             "missing: a sphere needs sphere_center_mm = [x, y, z] and sphere_radius_mm (mm)");
    const Eigen::Vector3d c = r.vec3(*center, "cut_region.sphere_center_mm");
    const double rad = r.number(*radius, "cut_region.sphere_radius_mm");
    if (!c.allFinite())
      r.fail(center, "cut_region.sphere_center_mm", "expected 3 finite numbers [x, y, z] (mm)");
    if (!(rad > 0) || !std::isfinite(rad))
      r.fail(radius, "cut_region.sphere_radius_mm",
             fmt::format("{} is not accepted: use a finite number > 0 (mm)", rad));
    job.spec = RegionSpec::sphere(from_mm(c), millimetres(rad));
  } else {
    const std::string name = r.string(*group, "cut_region.group");
    if (name.empty())
      r.fail(group, "cut_region.group",
             "expected the name of a 3-D physical group of the mesh (or \"#tag\")");
    job.spec = RegionSpec::physical_group(name);
  }
  if (const auto* n = t.get("density_kg_m3")) {
    job.density_kg_m3 = r.number(*n, "cut_region.density_kg_m3");
    if (!(job.density_kg_m3 > 0) || !std::isfinite(job.density_kg_m3))
      r.fail(n, "cut_region.density_kg_m3",
             fmt::format("{} is not accepted: use a finite number > 0 (kg/m³; soft tissue "
                         "about {})",
                         job.density_kg_m3, kSoftTissueDensityKgM3));
  }
  if (const auto* n = t.get("damping_per_s")) {
    job.damping_per_s = r.number(*n, "cut_region.damping_per_s");
    if (!(job.damping_per_s >= 0) || !std::isfinite(job.damping_per_s))
      r.fail(n, "cut_region.damping_per_s",
             fmt::format("{} is not accepted: use a finite number ≥ 0 (1/s; default {})",
                         job.damping_per_s, kDefaultRegionDampingPerS));
  }
  return job;
}

std::string cut_region_toml(const CutRegionJob& region) {
  const RegionSpec& s = region.spec;
  std::string t = "\n[cut_region]\n";
  switch (s.kind) {
    case RegionSpec::Kind::box:
      t += fmt::format("box_min_mm = {}\nbox_max_mm = {}\n", mm3(s.min_m), mm3(s.max_m));
      break;
    case RegionSpec::Kind::sphere:
      t += fmt::format("sphere_center_mm = {}\nsphere_radius_mm = {}\n", mm3(s.center_m),
                       mm(s.radius_m));
      break;
    case RegionSpec::Kind::group: {
      // A TOML basic string: quotes, backslashes and control characters escaped.
      std::string quoted;
      for (const char c : s.group) {
        if (c == '"' || c == '\\')
          quoted += {'\\', c};
        else if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
          quoted += fmt::format("\\u{:04x}", static_cast<unsigned char>(c));
        else
          quoted += c;
      }
      t += fmt::format("group = \"{}\"\n", quoted);
      break;
    }
  }
  t += fmt::format("density_kg_m3 = {}\ndamping_per_s = {}\n", number(region.density_kg_m3),
                   number(region.damping_per_s));
  return t;
}

}  // namespace palpate::detail
