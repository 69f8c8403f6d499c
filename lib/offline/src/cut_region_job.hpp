#pragma once
// Private to palpate_offline: the job file's [cut_region] table
// (docs/configuration.md), read and written back (precompute_job.cpp).

#include <toml++/toml.h>

#include <string>

#include "palpate/core/detail/toml_reader.hpp"
#include "palpate/offline/precompute_job.hpp"

namespace palpate::detail {

/// The [cut_region] table @p node: exactly one shape (box_min_mm and
/// box_max_mm, sphere_center_mm and sphere_radius_mm, or group), lengths in
/// millimetres converted to metres; density_kg_m3 and damping_per_s.
/// @throws InputError "file:line: cut_region.key: what is accepted".
CutRegionJob read_cut_region_table(const toml::node& node, const TomlReader& r);

/// The table as TOML, "[cut_region]" and its keys, lengths in millimetres.
std::string cut_region_toml(const CutRegionJob& region);

}  // namespace palpate::detail
