#pragma once
/// @file
/// palpated's configuration: config/palpated.toml, then command-line
/// overrides (docs/configuration.md, "palpated").

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "palpate/runtime/constraint_solver.hpp"
#include "palpate/runtime/tool_geometry.hpp"
#include "palpate/transport/realtime.hpp"

namespace palpate {

/// One compliance file to serve.
struct ModelEntry {
  std::string id;              ///< what requests name; 1..63 characters [A-Za-z0-9_.-]
  std::filesystem::path file;  ///< compliance file (HDF5)
  /// Large rotations: the linear model, or warped compliance for its
  /// requests, its tools and its surface stream (docs/model/warped.md, "Large
  /// rotations: warped compliance").
  bool warped = false;
};

/// Which thread serves poses and requests (docs/realtime.md, docs/dds.md
/// "Threads"): Cyclone's receive thread in the readers' data-available
/// listeners; or palpated's own serving thread, sleeping on a waitset of the
/// readers or polling them without sleeping (it keeps its core busy).
enum class ServeMode { kListener, kWaitset, kBusy };
/// "listener", "waitset", "busy".
const char* serve_mode_name(ServeMode mode);
/// The mode of @p name (the key's or flag's value); @throws InputError
/// naming @p what and the accepted values.
ServeMode parse_serve_mode(const std::string& name, std::string_view what);

struct DaemonConfig {
  std::string daemon_id = "palpated";  ///< key of the status topic
  std::string log_level = "info";      ///< trace, debug, info, warn, error
  std::uint32_t domain_id = 0;         ///< DDS domain
  std::string dds_config;       ///< Cyclone XML file, file:// URI or fragment; empty: loopback
  double surface_rate_hz = 60;  ///< surface stream, at most this many samples per model per second
  double status_rate_hz = 1;    ///< status heartbeat
  /// Constraints per request, cache, condition; the surface field of replies
  /// on two threads when the machine has two cores or more.
  SolverLimits limits{.surface_threads = std::thread::hardware_concurrency() >= 2 ? 2 : 1};
  /// Requests only (not tools): an imposed displacement longer than this
  /// fraction of the organ's size (its bounding-box diagonal) is refused
  /// (displacement_too_large); a given force above max_force_n
  /// (force_too_large). Both appear in the model description.
  double max_displacement_fraction = 0.1;
  double max_force_n = 50;
  int max_clients = 64;  ///< reply writers kept at once
  std::vector<ModelEntry> models;
  /// Haptic tools ([[tools]]); "left" and "right" with the default geometry
  /// when the configuration names none.
  std::vector<ToolGeometry> tools = default_tools();
  ContactSettings contact;                 ///< [contact]
  std::filesystem::path record_directory;  ///< [recording] directory; empty: no recording
  /// [realtime]: the serving thread, and the real-time options of the
  /// threads that serve poses and requests (the serving thread, or
  /// Cyclone's receive thread in listener mode) and of Cyclone's receive thread.
  ServeMode serve = ServeMode::kListener;
  RealtimeOptions realtime;

  static std::vector<ToolGeometry> default_tools();
};

/// Reads @p file (TOML). Relative model paths are taken from its directory.
/// @throws InputError naming the file, line and key.
DaemonConfig read_daemon_config(const std::filesystem::path& file);

/// Parses "ID=PATH" (the --model flag). @throws InputError.
ModelEntry parse_model_flag(const std::string& text);

/// Checks ranges and model ids, that every model file exists, and the
/// [realtime] values (realtime::validate; not whether the process may use
/// them: palpated checks that when it starts).
/// @throws InputError saying what is wrong and what is accepted.
void validate(const DaemonConfig& config);

}  // namespace palpate
