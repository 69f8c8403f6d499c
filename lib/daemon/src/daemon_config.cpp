#include "palpate/daemon/daemon_config.hpp"

#include <sched.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <numbers>
#include <set>

#include "palpate/core/detail/toml_reader.hpp"
#include "palpate/core/ids.hpp"

namespace palpate {

DaemonConfig read_daemon_config(const std::filesystem::path& file) {
  const toml::table root = detail::parse_toml_file(file);
  const detail::TomlReader r(file.string());
  const auto base = std::filesystem::absolute(file).parent_path();
  DaemonConfig config;
  r.only_keys(
      root, "",
      {"daemon", "dds", "rates", "limits", "model", "tools", "contact", "recording", "realtime"});

  auto integer = [&](const toml::node& node, const std::string& key, std::int64_t lo,
                     std::int64_t hi) {
    const auto v = node.value<std::int64_t>();
    if (!v || *v < lo || *v > hi)
      r.fail(&node, key, fmt::format("expected an integer in [{}, {}]", lo, hi));
    return *v;
  };
  auto positive = [&](const toml::node& node, const std::string& key) {
    const double v = r.number(node, key);
    if (!(v > 0) || !std::isfinite(v)) r.fail(&node, key, "expected a positive number");
    return v;
  };

  if (const auto* n = root.get("daemon")) {
    const auto& t = r.table(*n, "daemon");
    r.only_keys(t, "daemon", {"id", "log_level"});
    if (const auto* v = t.get("id")) config.daemon_id = r.string(*v, "daemon.id");
    if (const auto* v = t.get("log_level")) config.log_level = r.string(*v, "daemon.log_level");
  }
  if (const auto* n = root.get("dds")) {
    const auto& t = r.table(*n, "dds");
    r.only_keys(t, "dds", {"domain", "config"});
    if (const auto* v = t.get("domain"))
      config.domain_id = static_cast<std::uint32_t>(integer(*v, "dds.domain", 0, 232));
    if (const auto* v = t.get("config")) {
      config.dds_config = r.string(*v, "dds.config");
      // A path (not XML, not a URI) is relative to the configuration file.
      if (!config.dds_config.empty() && config.dds_config.find('<') == std::string::npos &&
          config.dds_config.rfind("file://", 0) != 0)
        config.dds_config = detail::relative_to(base, config.dds_config).string();
    }
  }
  if (const auto* n = root.get("rates")) {
    const auto& t = r.table(*n, "rates");
    r.only_keys(t, "rates", {"surface_hz", "status_hz"});
    if (const auto* v = t.get("surface_hz"))
      config.surface_rate_hz = positive(*v, "rates.surface_hz");
    if (const auto* v = t.get("status_hz")) config.status_rate_hz = positive(*v, "rates.status_hz");
  }
  if (const auto* n = root.get("limits")) {
    const auto& t = r.table(*n, "limits");
    r.only_keys(t, "limits",
                {"max_constraints", "max_condition", "cache_slots", "max_clients",
                 "surface_threads", "max_displacement_fraction", "max_force_n"});
    if (const auto* v = t.get("max_constraints"))
      config.limits.max_constraints =
          static_cast<int>(integer(*v, "limits.max_constraints", 1, 1024));
    if (const auto* v = t.get("max_condition"))
      config.limits.max_condition = positive(*v, "limits.max_condition");
    if (const auto* v = t.get("cache_slots"))
      config.limits.cache_slots = static_cast<int>(integer(*v, "limits.cache_slots", 1, 256));
    if (const auto* v = t.get("surface_threads"))
      config.limits.surface_threads = static_cast<int>(integer(*v, "limits.surface_threads", 1, 2));
    if (const auto* v = t.get("max_displacement_fraction"))
      config.max_displacement_fraction = positive(*v, "limits.max_displacement_fraction");
    if (const auto* v = t.get("max_force_n"))
      config.max_force_n = positive(*v, "limits.max_force_n");
    if (const auto* v = t.get("max_clients"))
      config.max_clients = static_cast<int>(integer(*v, "limits.max_clients", 1, 4096));
  }
  if (const auto* n = root.get("model")) {
    r.each_table(*n, "model", [&](const toml::table& m) {
      r.only_keys(m, "model", {"id", "file", "warping"});
      if (!m.get("id") || !m.get("file")) r.fail(&m, "model", "needs id and file");
      bool warped = false;
      if (const auto* w = m.get("warping")) {
        const std::string mode = r.string(*w, "model.warping");
        if (mode != "linear" && mode != "warped")
          r.fail(w, "model.warping",
                 fmt::format("'{}' is not a mode; accepted: \"linear\" or \"warped\"", mode));
        warped = mode == "warped";
      }
      config.models.push_back({r.string(*m.get("id"), "model.id"),
                               detail::relative_to(base, r.string(*m.get("file"), "model.file")),
                               warped});
    });
  }
  auto non_negative = [&](const toml::node& node, const std::string& key) {
    const double v = r.number(node, key);
    if (!(v >= 0) || !std::isfinite(v)) r.fail(&node, key, "expected a number ≥ 0");
    return v;
  };
  if (const auto* n = root.get("tools")) {
    config.tools.clear();
    r.each_table(*n, "tools", [&](const toml::table& t) {
      r.only_keys(t, "tools",
                  {"id", "tip", "tip_radius_mm", "tip_length_mm", "friction", "jaw_length_mm",
                   "jaw_width_mm", "grasp_angle_deg", "release_angle_deg", "max_jaw_angle_deg",
                   "force_limit_n", "max_force_rate_n_per_s", "cutting"});
      ToolGeometry g;
      if (!t.get("id")) r.fail(&t, "tools", "needs an id");
      g.id = r.string(*t.get("id"), "tools.id");
      const std::string key = "tools." + g.id + ".";
      if (const auto* v = t.get("tip")) {
        const std::string tip = r.string(*v, key + "tip");
        if (tip == "sphere") {
          g.tip = TipShape::kSphere;
          g.tip_length_m = 0;
        } else if (tip != "capsule") {
          r.fail(v, key + "tip", "expected \"sphere\" or \"capsule\"");
        }
      }
      if (const auto* v = t.get("tip_radius_mm"))
        g.tip_radius_m = millimetres(positive(*v, key + "tip_radius_mm"));
      if (const auto* v = t.get("tip_length_mm")) {
        if (g.tip == TipShape::kSphere)
          r.fail(v, key + "tip_length_mm", "a sphere tip has no length (use tip = \"capsule\")");
        g.tip_length_m = millimetres(non_negative(*v, key + "tip_length_mm"));
      }
      if (const auto* v = t.get("friction")) g.friction = non_negative(*v, key + "friction");
      if (const auto* v = t.get("jaw_length_mm"))
        g.jaw_length_m = millimetres(non_negative(*v, key + "jaw_length_mm"));
      if (const auto* v = t.get("jaw_width_mm"))
        g.jaw_width_m = millimetres(non_negative(*v, key + "jaw_width_mm"));
      if (const auto* v = t.get("grasp_angle_deg"))
        g.grasp_angle_rad = degrees(positive(*v, key + "grasp_angle_deg"));
      if (const auto* v = t.get("release_angle_deg"))
        g.release_angle_rad = degrees(positive(*v, key + "release_angle_deg"));
      if (const auto* v = t.get("max_jaw_angle_deg"))
        g.max_jaw_angle_rad = degrees(positive(*v, key + "max_jaw_angle_deg"));
      if (const auto* v = t.get("force_limit_n"))
        g.force_limit_n = positive(*v, key + "force_limit_n");
      if (const auto* v = t.get("max_force_rate_n_per_s"))
        g.max_force_rate_n_per_s = positive(*v, key + "max_force_rate_n_per_s");
      if (const auto* v = t.get("cutting")) g.cutting = r.boolean(*v, key + "cutting");
      config.tools.push_back(std::move(g));
    });
  }
  if (const auto* n = root.get("contact")) {
    const auto& t = r.table(*n, "contact");
    r.only_keys(t, "contact",
                {"watchdog_timeout_ms", "watchdog_ramp_ms", "search_margin_mm",
                 "max_contacts_per_tool", "max_iterations", "workspace_margin_mm"});
    auto& c = config.contact;
    if (const auto* v = t.get("watchdog_timeout_ms"))
      c.watchdog_timeout_s = 1e-3 * positive(*v, "contact.watchdog_timeout_ms");
    if (const auto* v = t.get("watchdog_ramp_ms"))
      c.watchdog_ramp_s = 1e-3 * positive(*v, "contact.watchdog_ramp_ms");
    if (const auto* v = t.get("search_margin_mm"))
      c.search_margin_m = millimetres(non_negative(*v, "contact.search_margin_mm"));
    if (const auto* v = t.get("max_contacts_per_tool"))
      c.max_contacts_per_tool =
          static_cast<int>(integer(*v, "contact.max_contacts_per_tool", 1, 1024));
    if (const auto* v = t.get("max_iterations"))
      c.max_iterations = static_cast<int>(integer(*v, "contact.max_iterations", 1, 16));
    if (const auto* v = t.get("workspace_margin_mm"))
      c.workspace_margin_m = millimetres(positive(*v, "contact.workspace_margin_mm"));
  }
  if (const auto* n = root.get("recording")) {
    const auto& t = r.table(*n, "recording");
    r.only_keys(t, "recording", {"directory"});
    if (const auto* v = t.get("directory")) {
      const std::string dir = r.string(*v, "recording.directory");
      if (!dir.empty()) config.record_directory = detail::relative_to(base, dir);
    }
  }
  if (const auto* n = root.get("realtime")) {
    const auto& t = r.table(*n, "realtime");
    r.only_keys(t, "realtime", {"serve", "priority", "cpus", "lock_memory"});
    // The parsers' messages start with the name they are given: the
    // reader's start with the file, the line and the key instead.
    auto after = [](const InputError& e, std::string_view name) {
      return std::string(e.what()).substr(name.size() + 1);
    };
    if (const auto* v = t.get("serve")) {
      try {
        config.serve = parse_serve_mode(r.string(*v, "realtime.serve"), "realtime.serve");
      } catch (const InputError& e) {
        r.fail(v, "realtime.serve", after(e, "realtime.serve"));
      }
    }
    if (const auto* v = t.get("priority"))
      config.realtime.priority =
          static_cast<int>(integer(*v, "realtime.priority", 0, realtime::kMaxPriority));
    if (const auto* v = t.get("cpus")) {
      // An array of CPU numbers, or a CPU list as taskset -c takes it.
      if (const auto* list = v->as_array()) {
        std::vector<int> cpus;
        for (const auto& cpu : *list)
          cpus.push_back(static_cast<int>(integer(cpu, "realtime.cpus", 0, CPU_SETSIZE - 1)));
        std::sort(cpus.begin(), cpus.end());
        cpus.erase(std::unique(cpus.begin(), cpus.end()), cpus.end());
        config.realtime.cpus = std::move(cpus);
      } else if (const auto text = v->value<std::string>()) {
        try {
          config.realtime.cpus = realtime::parse_cpu_list(*text, "realtime.cpus");
        } catch (const InputError& e) {
          r.fail(v, "realtime.cpus", after(e, "realtime.cpus"));
        }
      } else {
        r.fail(v, "realtime.cpus",
               "expected an array of CPU numbers, e.g. [1], or a CPU list string, e.g. \"0-1\"");
      }
    }
    if (const auto* v = t.get("lock_memory"))
      config.realtime.lock_memory = r.boolean(*v, "realtime.lock_memory");
  }
  return config;
}

const char* serve_mode_name(ServeMode mode) {
  switch (mode) {
    case ServeMode::kWaitset:
      return "waitset";
    case ServeMode::kBusy:
      return "busy";
    case ServeMode::kListener:
      break;
  }
  return "listener";
}

ServeMode parse_serve_mode(const std::string& name, std::string_view what) {
  for (const ServeMode mode : {ServeMode::kListener, ServeMode::kWaitset, ServeMode::kBusy})
    if (name == serve_mode_name(mode)) return mode;
  throw InputError(
      fmt::format("{} '{}': expected \"listener\" (Cyclone's receive thread serves), "
                  "\"waitset\" (palpated's serving thread, woken by the data) or \"busy\" (its "
                  "serving thread polls, keeping a core busy)",
                  what, name));
}

std::vector<ToolGeometry> DaemonConfig::default_tools() {
  ToolGeometry left;
  left.id = "left";
  ToolGeometry right = left;
  right.id = "right";
  return {left, right};
}

ModelEntry parse_model_flag(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw InputError("--model '" + text + "': expected ID=PATH, e.g. liver=out/liver.h5");
  return {text.substr(0, eq), std::filesystem::path(text.substr(eq + 1))};
}

void validate(const DaemonConfig& config) {
  if (!is_valid_id(config.daemon_id))
    throw InputError("daemon.id '" + config.daemon_id +
                     "': expected 1 to 63 characters among A-Z a-z 0-9 _ - .");
  static const std::set<std::string> levels{"trace", "debug", "info", "warn", "error"};
  if (!levels.contains(config.log_level))
    throw InputError("daemon.log_level '" + config.log_level +
                     "': expected trace, debug, info, warn or error");
  if (config.domain_id > 232)
    throw InputError(
        fmt::format("dds.domain {}: expected a DDS domain id in [0, 232]", config.domain_id));
  if (!(config.surface_rate_hz > 0 && config.surface_rate_hz <= 1000))
    throw InputError(fmt::format("rates.surface_hz {}: expected a rate in (0, 1000] Hz",
                                 config.surface_rate_hz));
  if (!(config.status_rate_hz > 0 && config.status_rate_hz <= 100))
    throw InputError(
        fmt::format("rates.status_hz {}: expected a rate in (0, 100] Hz", config.status_rate_hz));
  if (!(config.limits.max_condition >= 1))
    throw InputError(
        fmt::format("limits.max_condition {}: expected a number ≥ 1", config.limits.max_condition));
  if (config.limits.max_constraints < 1 || config.limits.max_constraints > 1024)
    throw InputError(fmt::format("limits.max_constraints {}: expected 1 to 1024",
                                 config.limits.max_constraints));
  if (!(config.max_displacement_fraction > 0 && config.max_displacement_fraction <= 1))
    throw InputError(fmt::format(
        "limits.max_displacement_fraction {}: expected a fraction of the organ's size in (0, 1]",
        config.max_displacement_fraction));
  if (!(config.max_force_n > 0) || !std::isfinite(config.max_force_n))
    throw InputError(
        fmt::format("limits.max_force_n {}: expected a force > 0 in N", config.max_force_n));
  if (config.limits.cache_slots < 1 || config.limits.cache_slots > 256)
    throw InputError(
        fmt::format("limits.cache_slots {}: expected 1 to 256", config.limits.cache_slots));
  if (config.limits.surface_threads != 1 && config.limits.surface_threads != 2)
    throw InputError(
        fmt::format("limits.surface_threads {}: expected 1 or 2", config.limits.surface_threads));
  if (config.max_clients < 1 || config.max_clients > 4096)
    throw InputError(fmt::format("limits.max_clients {}: expected 1 to 4096", config.max_clients));
  if (config.tools.empty() || config.tools.size() > 64)
    throw InputError(
        fmt::format("{} tools configured: expected 1 to 64 [[tools]] tables", config.tools.size()));
  std::set<std::string> tool_ids;
  for (const auto& g : config.tools) {
    if (!is_valid_id(g.id))
      throw InputError("tool id '" + g.id +
                       "': expected 1 to 63 characters among A-Z a-z 0-9 _ - .");
    if (!tool_ids.insert(g.id).second) throw InputError("tool id '" + g.id + "' is given twice");
    if (!(g.grasp_angle_rad < g.release_angle_rad && g.release_angle_rad <= g.max_jaw_angle_rad &&
          g.max_jaw_angle_rad < std::numbers::pi))
      throw InputError(fmt::format(
          "tool '{}': jaw angles grasp {:.1f}°, release {:.1f}°, max {:.1f}°: expected grasp < "
          "release ≤ max < 180° (the hysteresis between grasp and release keeps a grip stable)",
          g.id, g.grasp_angle_rad * 180 / std::numbers::pi,
          g.release_angle_rad * 180 / std::numbers::pi,
          g.max_jaw_angle_rad * 180 / std::numbers::pi));
    if (!(g.tip_radius_m > 0 && g.force_limit_n > 0 && g.max_force_rate_n_per_s > 0 &&
          g.friction >= 0 && g.tip_length_m >= 0 && g.jaw_length_m >= 0 && g.jaw_width_m >= 0))
      throw InputError("tool '" + g.id +
                       "': radius, force limit and force rate must be positive; lengths, width "
                       "and friction ≥ 0");
  }
  if (config.limits.max_constraints < static_cast<int>(config.tools.size()))
    throw InputError(fmt::format(
        "limits.max_constraints {} is below the number of tools ({}): every tool needs room for "
        "its contacts in the joint solve",
        config.limits.max_constraints, config.tools.size()));
  if (!config.record_directory.empty() && !std::filesystem::is_directory(config.record_directory))
    throw InputError("recording.directory " + config.record_directory.string() +
                     " is not a directory (create it, or leave the key empty to not record)");
  realtime::validate(config.realtime);
  if (config.models.empty())
    throw InputError(
        "no model to serve: add a [[model]] table (id, file) to the configuration or --model "
        "ID=PATH");
  std::set<std::string> ids;
  for (const auto& model : config.models) {
    if (!is_valid_id(model.id))
      throw InputError("model id '" + model.id +
                       "': expected 1 to 63 characters among A-Z a-z 0-9 _ - .");
    if (!ids.insert(model.id).second)
      throw InputError("model id '" + model.id + "' is given twice");
    if (!std::filesystem::is_regular_file(model.file))
      throw InputError("model '" + model.id + "': compliance file " + model.file.string() +
                       " does not exist (make one with palpate-precompute)");
  }
}

}  // namespace palpate
