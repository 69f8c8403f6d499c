#include "palpate/offline/precompute_job.hpp"

#include <fmt/format.h>
#include <toml++/toml.h>

#include <charconv>
#include <cmath>
#include <sstream>

#include "cut_region_job.hpp"
#include "palpate/core/detail/toml_reader.hpp"
#include "palpate/core/error.hpp"
#include "palpate/core/version.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/xdmf.hpp"
#include "palpate/offline/mesh_io.hpp"

namespace palpate {

namespace {
constexpr int kMaxBlockColumns = 100000;
}  // namespace

Method parse_method(const std::string& name) {
  if (name == "solves") return Method::kSolves;
  if (name == "condensation") return Method::kCondensation;
  if (name == "both") return Method::kBoth;
  throw InputError(
      fmt::format("method '{}' is not accepted: use solves, condensation or both", name));
}

std::string to_string(Method method) {
  switch (method) {
    case Method::kSolves:
      return "solves";
    case Method::kCondensation:
      return "condensation";
    case Method::kBoth:
      return "both";
  }
  return "?";
}

Precision parse_precision(const std::string& name) {
  if (name == "float64") return Precision::kFloat64;
  if (name == "float32") return Precision::kFloat32;
  throw InputError(fmt::format("precision '{}' is not accepted: use float64 or float32", name));
}

std::string to_string(Precision precision) {
  return precision == Precision::kFloat32 ? "float32" : "float64";
}

void parse_shard(const std::string& text, ColumnShard* shard) {
  auto number = [&](std::string_view digits, int* out) {
    const auto [rest, status] = std::from_chars(digits.data(), digits.data() + digits.size(), *out);
    return status == std::errc() && rest == digits.data() + digits.size() && !digits.empty();
  };
  const auto slash = text.find('/'), colon = text.find(':');
  const std::string_view t(text);
  if (slash != std::string::npos && colon == std::string::npos) {
    ColumnShard s;
    if (number(t.substr(0, slash), &s.index) && number(t.substr(slash + 1), &s.count) &&
        s.count > 0 && s.index >= 0 && s.index < s.count) {
      *shard = s;
      return;
    }
    throw InputError(
        fmt::format("shard '{}' is not accepted: use INDEX/COUNT with 0 ≤ INDEX < "
                    "COUNT, e.g. 0/4 … 3/4",
                    text));
  }
  if (colon != std::string::npos && slash == std::string::npos) {
    ColumnShard s;
    if (number(t.substr(0, colon), &s.begin) && number(t.substr(colon + 1), &s.end) &&
        s.begin >= 0 && s.begin < s.end) {
      *shard = s;
      return;
    }
  }
  throw InputError(
      fmt::format("columns '{}' are not accepted: use BEGIN:END with 0 ≤ BEGIN < END "
                  "(columns of G, END excluded), or a shard INDEX/COUNT",
                  text));
}

using detail::relative_to;

PrecomputeJob read_job_file(const std::filesystem::path& file) {
  const toml::table root = detail::parse_toml_file(file);
  const detail::TomlReader r(file.string());
  const auto base = std::filesystem::absolute(file).parent_path();
  PrecomputeJob job;
  r.only_keys(root, "", {"mesh", "material", "attachment", "cut_region", "compute", "output"});

  double unit = 1.0;
  if (const auto* mesh = root.get("mesh")) {
    const auto& t = r.table(*mesh, "mesh");
    r.only_keys(t, "mesh", {"file", "unit", "fill_size"});
    if (const auto* n = t.get("file")) job.mesh_file = relative_to(base, r.string(*n, "mesh.file"));
    if (const auto* n = t.get("unit")) {
      job.mesh_unit = r.string(*n, "mesh.unit");
      try {
        unit = parse_length_unit(job.mesh_unit).to_metres;
      } catch (const InputError& e) {
        r.fail(n, "mesh.unit", e.what());
      }
    }
    if (const auto* n = t.get("fill_size")) job.fill_size = r.number(*n, "mesh.fill_size");
  }
  if (const auto* material = root.get("material")) {
    const auto& t = r.table(*material, "material");
    r.only_keys(t, "material", {"young_modulus_pa", "poisson_ratio", "group"});
    if (const auto* n = t.get("young_modulus_pa"))
      job.young_modulus_pa = r.number(*n, "material.young_modulus_pa");
    if (const auto* n = t.get("poisson_ratio"))
      job.poisson_ratio = r.number(*n, "material.poisson_ratio");
    if (const auto* groups = t.get("group"))
      r.each_table(*groups, "material.group", [&](const toml::table& g) {
        r.only_keys(g, "material.group", {"name", "young_modulus_pa", "poisson_ratio"});
        GroupMaterial gm;
        const auto* name = g.get("name");
        const auto* E = g.get("young_modulus_pa");
        const auto* nu = g.get("poisson_ratio");
        if (!name || !E || !nu)
          r.fail(&g, "material.group", "needs name, young_modulus_pa and poisson_ratio");
        gm.group = r.string(*name, "material.group.name");
        gm.young_modulus_pa = r.number(*E, "material.group.young_modulus_pa");
        gm.poisson_ratio = r.number(*nu, "material.group.poisson_ratio");
        job.group_materials.push_back(gm);
      });
  }
  if (const auto* attachment = root.get("attachment")) {
    const auto& t = r.table(*attachment, "attachment");
    r.only_keys(t, "attachment", {"groups", "ids_file", "boxes", "spheres", "half_spaces"});
    auto& a = job.attachment;
    if (const auto* n = t.get("groups")) {
      const auto* arr = n->as_array();
      if (!arr) r.fail(n, "attachment.groups", "expected an array of group names");
      for (const auto& g : *arr) a.groups.push_back(r.string(g, "attachment.groups"));
    }
    if (const auto* n = t.get("ids_file"))
      a.ids_file = relative_to(base, r.string(*n, "attachment.ids_file"));
    a.unit = job.mesh_unit.empty() ? "m" : job.mesh_unit;
    if (const auto* n = t.get("boxes"))
      r.each_table(*n, "attachment.boxes", [&](const toml::table& b) {
        r.only_keys(b, "attachment.boxes", {"min", "max"});
        if (!b.get("min") || !b.get("max")) r.fail(&b, "attachment.boxes", "needs min and max");
        a.boxes.push_back({unit * r.vec3(*b.get("min"), "attachment.boxes.min"),
                           unit * r.vec3(*b.get("max"), "attachment.boxes.max")});
      });
    if (const auto* n = t.get("spheres"))
      r.each_table(*n, "attachment.spheres", [&](const toml::table& s) {
        r.only_keys(s, "attachment.spheres", {"center", "radius"});
        if (!s.get("center") || !s.get("radius"))
          r.fail(&s, "attachment.spheres", "needs center and radius");
        a.spheres.push_back({unit * r.vec3(*s.get("center"), "attachment.spheres.center"),
                             unit * r.number(*s.get("radius"), "attachment.spheres.radius")});
      });
    if (const auto* n = t.get("half_spaces"))
      r.each_table(*n, "attachment.half_spaces", [&](const toml::table& h) {
        r.only_keys(h, "attachment.half_spaces", {"point", "normal"});
        if (!h.get("point") || !h.get("normal"))
          r.fail(&h, "attachment.half_spaces", "needs point and normal");
        a.half_spaces.push_back({unit * r.vec3(*h.get("point"), "attachment.half_spaces.point"),
                                 r.vec3(*h.get("normal"), "attachment.half_spaces.normal")});
      });
  }
  // Millimetres whatever the mesh's unit: the keys say their unit.
  if (const auto* region = root.get("cut_region"))
    job.cut_region = detail::read_cut_region_table(*region, r);
  if (const auto* compute = root.get("compute")) {
    const auto& t = r.table(*compute, "compute");
    r.only_keys(t, "compute",
                {"method", "precision", "block_columns", "tolerance", "memory_limit_gb"});
    if (const auto* n = t.get("method")) {
      try {
        job.method = parse_method(r.string(*n, "compute.method"));
      } catch (const InputError& e) {
        r.fail(n, "compute.method", e.what());
      }
    }
    if (const auto* n = t.get("precision")) {
      try {
        job.precision = parse_precision(r.string(*n, "compute.precision"));
      } catch (const InputError& e) {
        r.fail(n, "compute.precision", e.what());
      }
    }
    if (const auto* n = t.get("block_columns")) {
      const auto v = n->value<int64_t>();
      if (!v || *v < 1 || *v > kMaxBlockColumns)
        r.fail(n, "compute.block_columns",
               fmt::format("expected an integer from 1 to {}", kMaxBlockColumns));
      job.block_columns = static_cast<int>(*v);
    }
    if (const auto* n = t.get("tolerance")) job.tolerance = r.number(*n, "compute.tolerance");
    if (const auto* n = t.get("memory_limit_gb"))
      job.memory_limit_bytes = 1e9 * r.number(*n, "compute.memory_limit_gb");
  }
  if (const auto* output = root.get("output")) {
    const auto& t = r.table(*output, "output");
    r.only_keys(t, "output", {"file", "xdmf"});
    if (const auto* n = t.get("file")) job.output = relative_to(base, r.string(*n, "output.file"));
    if (const auto* n = t.get("xdmf")) job.write_xdmf = r.boolean(*n, "output.xdmf");
  }
  return job;
}

namespace {

/// A TOML number as short as reads back the same (fmt's "{}": 0.45, not
/// toml++'s 0.45000000000000001), always with a point or an exponent so that
/// it reads as a float.
std::string toml_number(double value) {
  std::string text = fmt::format("{}", value);
  if (text.find_first_of(".einf") == std::string::npos) text += ".0";
  return text;
}

/// A TOML basic string: quotes, backslashes and control characters escaped.
std::string toml_string(std::string_view text) {
  std::string out = "\"";
  for (const char c : text) {
    if (c == '"' || c == '\\')
      out += {'\\', c};
    else if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
      out += fmt::format("\\u{:04x}", static_cast<unsigned char>(c));
    else
      out += c;
  }
  return out + "\"";
}

std::string toml_vector(const Eigen::Vector3d& v, double scale) {
  return fmt::format("[{}, {}, {}]", toml_number(v.x() / scale), toml_number(v.y() / scale),
                     toml_number(v.z() / scale));
}

}  // namespace

std::string to_toml(const PrecomputeJob& job) {
  const double unit = parse_length_unit(job.mesh_unit).to_metres;
  auto absolute = [](const std::filesystem::path& p) {
    return toml_string(std::filesystem::absolute(p).string());
  };
  std::string t = "# palpate-precompute job (written by palpate-precompute " PALPATE_VERSION ")\n";
  auto line = [&t](std::string_view key, const std::string& value) {
    t += fmt::format("{} = {}\n", key, value);
  };
  // An empty path is left out: `file = ""` would read back as the job's directory.
  t += "\n[mesh]\n";
  if (!job.mesh_file.empty()) line("file", absolute(job.mesh_file));
  line("unit", toml_string(job.mesh_unit));
  if (job.fill_size > 0) line("fill_size", toml_number(job.fill_size));

  t += "\n[material]\n";
  if (job.young_modulus_pa) line("young_modulus_pa", toml_number(*job.young_modulus_pa));
  if (job.poisson_ratio) line("poisson_ratio", toml_number(*job.poisson_ratio));
  for (const auto& g : job.group_materials) {
    t += "\n[[material.group]]\n";
    line("name", toml_string(g.group));
    line("young_modulus_pa", toml_number(g.young_modulus_pa));
    line("poisson_ratio", toml_number(g.poisson_ratio));
  }

  const auto& a = job.attachment;
  t += "\n[attachment]\n";
  if (!a.groups.empty()) {
    std::string groups;
    for (const auto& name : a.groups) groups += (groups.empty() ? "" : ", ") + toml_string(name);
    line("groups", "[" + groups + "]");
  }
  if (!a.ids_file.empty()) line("ids_file", absolute(a.ids_file));
  for (const auto& b : a.boxes) {
    t += "\n[[attachment.boxes]]\n";
    line("min", toml_vector(b.min, unit));
    line("max", toml_vector(b.max, unit));
  }
  for (const auto& sphere : a.spheres) {
    t += "\n[[attachment.spheres]]\n";
    line("center", toml_vector(sphere.center, unit));
    line("radius", toml_number(sphere.radius / unit));
  }
  for (const auto& h : a.half_spaces) {
    t += "\n[[attachment.half_spaces]]\n";
    line("point", toml_vector(h.point, unit));
    line("normal", toml_vector(h.normal, 1.0));
  }

  if (job.cut_region) t += detail::cut_region_toml(*job.cut_region);

  t += "\n[compute]\n";
  line("method", toml_string(to_string(job.method)));
  line("precision", toml_string(to_string(job.precision)));
  line("block_columns", std::to_string(job.block_columns));
  line("tolerance", toml_number(job.tolerance));
  if (job.memory_limit_bytes > 0)
    line("memory_limit_gb", toml_number(job.memory_limit_bytes / 1e9));

  t += "\n[output]\n";
  if (!job.output.empty()) line("file", absolute(job.output));
  line("xdmf", job.write_xdmf ? "true" : "false");
  return t;
}

void validate_job(const PrecomputeJob& job) {
  if (job.mesh_file.empty())
    throw InputError("no mesh given: use --mesh FILE or [mesh] file in the job file");
  if (job.output.empty())
    throw InputError("no output file given: use -o FILE.h5 or [output] file in the job file");
  if (!job.young_modulus_pa)
    throw InputError(
        "no Young's modulus given: use --young-modulus PA or [material] young_modulus_pa");
  if (!job.poisson_ratio)
    throw InputError("no Poisson ratio given: use --poisson-ratio NU or [material] poisson_ratio");
  require_output_directory(job.output);
  if (job.write_xdmf) check_xdmf_sidecar_name(job.output);
  if (job.attachment.empty())
    throw InputError(
        "no attachment given: the organ must be held somewhere; use --fix-ids, "
        "--fix-group, --fix-box, --fix-sphere, --fix-half-space or [attachment]");
  if (job.block_columns < 1 || job.block_columns > kMaxBlockColumns)
    throw InputError(fmt::format("block columns {} is not accepted: use 1 to {}", job.block_columns,
                                 kMaxBlockColumns));
  if (!(job.tolerance > 0))
    throw InputError(fmt::format("tolerance {} is not accepted: use a number > 0", job.tolerance));
  if (!(job.memory_limit_bytes >= 0))
    throw InputError("memory limit must be ≥ 0 (0: available memory)");
  parse_length_unit(job.mesh_unit);
  // The region's data joins the model on the in-memory path only: a
  // streamed run's checkpoint and shards do not carry it (docs/precompute.md,
  // "A cuttable region").
  if (job.cut_region) {
    // The job file's reader checks these with their line; flags land here.
    const double rho = job.cut_region->density_kg_m3, gamma = job.cut_region->damping_per_s;
    if (!(rho > 0) || !std::isfinite(rho))
      throw InputError(fmt::format(
          "cut region density {} kg/m³ is not accepted: use a finite number > 0 (soft tissue "
          "about {})",
          rho, kSoftTissueDensityKgM3));
    if (!(gamma >= 0) || !std::isfinite(gamma))
      throw InputError(fmt::format(
          "cut region damping {} 1/s is not accepted: use a finite number ≥ 0 (default {})", gamma,
          kDefaultRegionDampingPerS));
  }
  if (job.cut_region && (job.method == Method::kSolves || job.shard.any()))
    throw InputError(
        "a cut region ([cut_region]) is computed in memory only: use --method both (the "
        "default) or condensation, without --shard or --columns");
}

}  // namespace palpate
