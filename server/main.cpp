// palpated: serves precomputed organ compliance over Cyclone DDS.
// Flags override config/palpated.toml; docs/configuration.md lists both,
// docs/dds.md the topics, docs/errors.md the exit codes.

#include <fcntl.h>
#include <semaphore.h>
#include <signal.h>
#include <spawn.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <thread>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/core/organ_size.hpp"
#include "palpate/core/suggest.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/core/version.hpp"
#include "palpate/daemon/daemon_config.hpp"
#include "palpate/daemon/service.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/realtime.hpp"

namespace {

sem_t stop_semaphore;
std::atomic<int> received_signal{0};

extern "C" void on_stop_signal(int signal) {
  received_signal.store(signal);
  sem_post(&stop_semaphore);
}

// Debian's libhdf5 (1.10.8) can crash or hang on a damaged file before
// palpate's own checks see it (docs/fuzzing.md: a 2 KB file makes H5Aread
// segfault). So each compliance file is first read whole by a child palpated
// (`--probe-model FILE`, stderr discarded): if the child dies by a signal or
// hangs, the file is refused with one message; otherwise the daemon reads it
// itself, and a damaged file gets palpate's own message from that read.
// Costs one more read of each file at start-up.
void probe_compliance_file(const palpate::ModelEntry& entry) {
  const std::string file = entry.file.string();
  std::string self = "/proc/self/exe", flag = "--probe-model";
  std::vector<char*> argv{self.data(), flag.data(), const_cast<char*>(file.c_str()), nullptr};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  pid_t child = 0;
  const int rc = posix_spawn(&child, self.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0)
    throw palpate::SystemError("model " + entry.id +
                               ": cannot start the reader process: " + std::strerror(rc));
  // Generous: the child hashes every byte (docs/compliance-file.md); a slow
  // disk reads 20 MB/s.
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(entry.file, ec);
  const auto limit = std::chrono::seconds(60 + (ec ? 0 : bytes / 20'000'000));
  const auto deadline = std::chrono::steady_clock::now() + limit;
  int status = 0;
  while (waitpid(child, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill(child, SIGKILL);
      waitpid(child, &status, 0);
      throw palpate::InputError(
          "model " + entry.id + ": " + file + ": reading it did not end within " +
          std::to_string(limit.count()) +
          " s; the HDF5 library loops on some damaged files: check it with h5dump, or "
          "precompute it again");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (WIFSIGNALED(status))
    throw palpate::InputError("model " + entry.id + ": " + file +
                              ": the HDF5 library crashed reading it (signal " +
                              std::to_string(WTERMSIG(status)) +
                              "): the file is damaged; precompute it again or restore a copy");
}

int run(int argc, char** argv) {
  CLI::App app{
      "palpated: answers force and imposed-displacement requests on precomputed organ models over "
      "DDS"};
  app.set_version_flag("--version", "palpated " PALPATE_VERSION);
  std::string config_file;
  std::vector<std::string> model_flags, warp_flags;
  bool check_only = false;
  palpate::DaemonConfig overrides;
  app.add_option("-c,--config", config_file,
                 "configuration file (TOML, e.g. config/palpated.toml)");
  app.add_option("-m,--model", model_flags,
                 "serve a compliance file as ID=PATH (repeatable; adds to the configuration)");
  app.add_option("--warp", warp_flags,
                 "serve model ID with warped compliance for large rotations (repeatable; as "
                 "[[model]] warping = \"warped\")");
  app.add_option("--id", overrides.daemon_id, "daemon id in the status topic");
  app.add_option("--domain", overrides.domain_id, "DDS domain id");
  app.add_option(
      "--dds-config", overrides.dds_config,
      "Cyclone DDS configuration: XML file, file:// URI or XML fragment (default: loopback only)");
  app.add_option("--surface-hz", overrides.surface_rate_hz, "surface stream rate per model, Hz");
  app.add_option("--status-hz", overrides.status_rate_hz, "status heartbeat rate, Hz");
  app.add_option("--max-constraints", overrides.limits.max_constraints,
                 "constrained vertices per request");
  app.add_option("--max-condition", overrides.limits.max_condition,
                 "largest accepted condition estimate");
  app.add_option("--max-displacement-fraction", overrides.max_displacement_fraction,
                 "longest imposed displacement a request may give, as a fraction of the organ's "
                 "size (default 0.1)");
  app.add_option("--max-force", overrides.max_force_n,
                 "largest force a request may give, N (default 50)");
  app.add_option("--log-level", overrides.log_level, "trace, debug, info, warn or error");
  std::string record_directory;
  app.add_option("--record", record_directory,
                 "record tool sessions (poses, forces, contacts) to HDF5 files in this directory");
  std::string serve_mode, cpus;
  app.add_option("--serve", serve_mode,
                 "which thread serves poses and requests: listener (Cyclone's receive thread), "
                 "waitset or busy (palpated's serving thread, sleeping or polling); as "
                 "realtime.serve");
  app.add_option("--rt-priority", overrides.realtime.priority,
                 "SCHED_FIFO priority (1-99) of the threads serving poses and requests and of "
                 "Cyclone's receive thread; 0: normal scheduling; as realtime.priority");
  app.add_option("--cpus", cpus,
                 "CPUs of those threads, as taskset -c (1, 0,2, 0-3); as realtime.cpus");
  app.add_flag("--lock-memory", overrides.realtime.lock_memory,
               "lock the process's memory once started (mlockall); as realtime.lock_memory");
  app.add_flag("--check-config", check_only,
               "check the configuration and the compliance files, then exit");
  bool print_dds_config = false;
  app.add_flag(
      "--print-dds-config", print_dds_config,
      "print the Cyclone DDS configuration palpated would use (the built-in loopback one "
      "unless --dds-config or CYCLONEDDS_URI gives another), for CYCLONEDDS_URI, then exit");
  std::string probe_file;
  app.add_option("--probe-model", probe_file)->group("");  // internal: see probe_compliance_file
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "palpated: error: %s%s (see --help)\n", e.what(),
                 palpate::flag_suggestions(std::vector<std::string>(argv + 1, argv + argc),
                                           palpate::long_flag_names(app))
                     .c_str());
    return static_cast<int>(palpate::ExitCode::kUsage);
  }

  if (!probe_file.empty()) {
    palpate::load_surface_model("probe", probe_file, /*keep_float32=*/true);
    return 0;
  }

  palpate::DaemonConfig config;
  if (!config_file.empty()) config = palpate::read_daemon_config(config_file);
  if (app.count("--serve")) config.serve = palpate::parse_serve_mode(serve_mode, "--serve");
  if (app.count("--rt-priority")) config.realtime.priority = overrides.realtime.priority;
  if (app.count("--cpus")) config.realtime.cpus = palpate::realtime::parse_cpu_list(cpus, "--cpus");
  if (app.count("--lock-memory")) config.realtime.lock_memory = true;
  if (print_dds_config) {
    // With the real-time priority of Cyclone's receive thread, if any: what
    // a benchmark gives ddsperf to compare like with like.
    const auto dds = palpate::dds::resolve_domain_config(
        app.count("--dds-config") ? overrides.dds_config : config.dds_config, config.realtime);
    std::printf("%s\n", dds.text.c_str());
    return 0;
  }
  if (app.count("--id")) config.daemon_id = overrides.daemon_id;
  if (app.count("--domain")) config.domain_id = overrides.domain_id;
  if (app.count("--dds-config")) config.dds_config = overrides.dds_config;
  if (app.count("--surface-hz")) config.surface_rate_hz = overrides.surface_rate_hz;
  if (app.count("--status-hz")) config.status_rate_hz = overrides.status_rate_hz;
  if (app.count("--max-constraints"))
    config.limits.max_constraints = overrides.limits.max_constraints;
  if (app.count("--max-condition")) config.limits.max_condition = overrides.limits.max_condition;
  if (app.count("--max-displacement-fraction"))
    config.max_displacement_fraction = overrides.max_displacement_fraction;
  if (app.count("--max-force")) config.max_force_n = overrides.max_force_n;
  if (app.count("--log-level")) config.log_level = overrides.log_level;
  if (app.count("--record")) config.record_directory = record_directory;
  for (const auto& flag : model_flags) config.models.push_back(palpate::parse_model_flag(flag));
  for (const auto& id : warp_flags) {
    auto entry = std::find_if(config.models.begin(), config.models.end(),
                              [&](const palpate::ModelEntry& m) { return m.id == id; });
    if (entry == config.models.end()) {
      std::string served;
      for (const auto& m : config.models) served += (served.empty() ? "" : ", ") + m.id;
      throw palpate::InputError("--warp " + id + ": no model of that id is served (served: " +
                                (served.empty() ? "none" : served) + ")");
    }
    entry->warped = true;
  }
  palpate::validate(config);
  // A priority this process may not use stops it here, --check-config too.
  palpate::realtime::check_permitted(config.realtime);

  // Structured logs on stderr, one event per line: ts level event=... key=value.
  auto log = spdlog::stderr_logger_mt("palpated");
  log->set_pattern("ts=%Y-%m-%dT%H:%M:%S.%fZ level=%l %v", spdlog::pattern_time_type::utc);
  log->set_level(spdlog::level::from_str(config.log_level));
  log->flush_on(spdlog::level::info);
  spdlog::set_default_logger(log);

  for (const auto& entry : config.models) probe_compliance_file(entry);
  if (check_only) {
    for (const auto& entry : config.models) {
      const auto model = palpate::load_surface_model(entry.id, entry.file);
      std::printf("model %s: %s, %d compliance vertices, %s\n", model.id.c_str(),
                  entry.file.c_str(), model.compliance_vertex_count(),
                  model.material_summary.c_str());
      if (const double across = palpate::bounding_diagonal_m(model.surface.rest_positions_m);
          !palpate::plausible_organ_size(across))
        std::fprintf(stderr,
                     "palpated: warning: model %s: the organ is %.3g m across, not an organ's "
                     "size (%g to %g m): was the mesh in other units (palpate-precompute "
                     "--mesh-unit)?\n",
                     model.id.c_str(), across, palpate::kPlausibleOrganMinM,
                     palpate::kPlausibleOrganMaxM);
      if (!model.cut_region_spec.empty() && entry.warped)
        std::fprintf(stderr, "palpated: warning: model %s: its cut region (%s): %s\n",
                     model.id.c_str(), model.cut_region_spec.c_str(),
                     palpate::kCutRegionNotSimulated);
      else if (!model.cut_region_spec.empty())
        std::printf("model %s: its cut region (%s) is stepped beside the rest\n", model.id.c_str(),
                    model.cut_region_spec.c_str());
    }
    const auto dds = palpate::dds::resolve_domain_config(config.dds_config);
    std::string serving;  // only when not the default
    if (config.serve != palpate::ServeMode::kListener || config.realtime.any()) {
      serving = std::string("; serving: ") + palpate::serve_mode_name(config.serve);
      if (config.realtime.priority > 0)
        serving += ", SCHED_FIFO " + std::to_string(config.realtime.priority);
      if (!config.realtime.cpus.empty())
        serving += ", CPUs " + palpate::realtime::format_cpu_list(config.realtime.cpus);
      if (config.realtime.lock_memory) serving += ", memory locked";
    }
    std::printf("configuration OK: %zu model(s), domain %u, DDS configuration: %s%s\n",
                config.models.size(), config.domain_id, dds.origin.c_str(), serving.c_str());
    return 0;
  }

  spdlog::info("event=starting version={} daemon_id={} blas=\"{}\"", PALPATE_VERSION,
               config.daemon_id, palpate::blas_description());
  // SIGINT and SIGTERM post a semaphore (async-signal-safe); a thread
  // waits on it and stops the service. A handler rather than sigwait because
  // libraries start threads before main (OpenBLAS) whose masks we do not set.
  // Installed before the models load: a signal during loading stops the
  // daemon as soon as it is up, with exit 0.
  sem_init(&stop_semaphore, 0, 0);
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  palpate::Service service(config);
  std::thread signal_thread([&] {
    while (sem_wait(&stop_semaphore) != 0) {
    }
    if (const int signal = received_signal.load(); signal != 0)
      spdlog::info("event=signal signal={}", signal == SIGINT ? "SIGINT" : "SIGTERM");
    service.request_stop();
  });
  auto stop_signal_thread = [&] {
    sem_post(&stop_semaphore);
    signal_thread.join();
  };
  try {
    service.run();
  } catch (...) {
    stop_signal_thread();
    throw;
  }
  stop_signal_thread();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  palpate::set_blas_threads(1);  // small solves on the haptic and request threads
  try {
    return run(argc, argv);
  } catch (...) {
    return palpate::report_current_exception("palpated");
  }
}
