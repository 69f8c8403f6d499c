#include "palpate/daemon_config.hpp"

#include <cctype>
#include <cmath>
#include <set>

#include "toml_reader.hpp"

namespace palpate {

DaemonConfig read_daemon_config(const std::filesystem::path& file) {
  const toml::table root = detail::parse_toml_file(file);
  const detail::TomlReader r(file.string());
  const auto base = std::filesystem::absolute(file).parent_path();
  DaemonConfig config;
  r.only_keys(root, "", {"daemon", "dds", "rates", "limits", "model"});

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
    r.only_keys(
        t, "limits",
        {"max_constraints", "max_condition", "cache_slots", "max_clients", "surface_threads"});
    if (const auto* v = t.get("max_constraints"))
      config.limits.max_constraints =
          static_cast<int>(integer(*v, "limits.max_constraints", 1, 1024));
    if (const auto* v = t.get("max_condition"))
      config.limits.max_condition = positive(*v, "limits.max_condition");
    if (const auto* v = t.get("cache_slots"))
      config.limits.cache_slots = static_cast<int>(integer(*v, "limits.cache_slots", 1, 256));
    if (const auto* v = t.get("surface_threads"))
      config.limits.surface_threads = static_cast<int>(integer(*v, "limits.surface_threads", 1, 2));
    if (const auto* v = t.get("max_clients"))
      config.max_clients = static_cast<int>(integer(*v, "limits.max_clients", 1, 4096));
  }
  if (const auto* n = root.get("model")) {
    r.each_table(*n, "model", [&](const toml::table& m) {
      r.only_keys(m, "model", {"id", "file"});
      if (!m.get("id") || !m.get("file")) r.fail(&m, "model", "needs id and file");
      config.models.push_back({r.string(*m.get("id"), "model.id"),
                               detail::relative_to(base, r.string(*m.get("file"), "model.file"))});
    });
  }
  return config;
}

ModelEntry parse_model_flag(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw InputError("--model '" + text + "': expected ID=PATH, e.g. liver=out/liver.h5");
  return {text.substr(0, eq), std::filesystem::path(text.substr(eq + 1))};
}

bool is_valid_id(std::string_view id) {
  if (id.empty() || id.size() > 63) return false;
  for (char c : id)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'))
      return false;
  return true;
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
  if (config.limits.cache_slots < 1 || config.limits.cache_slots > 256)
    throw InputError(
        fmt::format("limits.cache_slots {}: expected 1 to 256", config.limits.cache_slots));
  if (config.limits.surface_threads != 1 && config.limits.surface_threads != 2)
    throw InputError(
        fmt::format("limits.surface_threads {}: expected 1 or 2", config.limits.surface_threads));
  if (config.max_clients < 1 || config.max_clients > 4096)
    throw InputError(fmt::format("limits.max_clients {}: expected 1 to 4096", config.max_clients));
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
