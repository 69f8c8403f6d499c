// palpate-client: a command-line client of palpated (docs/dds.md).
//   describe  print a model's description
//   request   send one constraint request, print the reply
//   demo      a scripted palpation at the haptic rate: press, pinch, slide, release
//   status    print one status heartbeat
//   watch     report palpated going and coming back (its heartbeat), until stopped

#include <fmt/format.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <thread>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/core/statistics.hpp"
#include "palpate/core/suggest.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/realtime.hpp"

namespace {

using namespace std::chrono_literals;
using palpate::ConstraintSpec;
using Clock = std::chrono::steady_clock;

std::array<double, 3> parse_vec3(const std::string& text, const std::string& what) {
  std::array<double, 3> v{};
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf", &v[0], &v[1], &v[2]) != 3)
    throw palpate::InputError(fmt::format("{} '{}': expected three numbers x,y,z", what, text));
  return v;
}

/// "V:x,y,z" (force, displacement) or "V:nx,ny,nz:depth" (normal displacement).
ConstraintSpec parse_constraint(const std::string& text, palpate::ConstraintKind kind,
                                const std::string& flag) {
  const auto colon = text.find(':');
  if (colon == std::string::npos)
    throw palpate::InputError(
        fmt::format("{} '{}': expected VERTEX:x,y,z{}", flag, text,
                    kind == palpate::ConstraintKind::kNormalDisplacement ? ":DEPTH" : ""));
  std::uint32_t vertex = 0;
  const std::string id = text.substr(0, colon);
  if (id.empty() || id.find_first_not_of("0123456789") != std::string::npos ||
      std::sscanf(id.c_str(), "%u", &vertex) != 1)
    throw palpate::InputError(fmt::format(
        "{} '{}': '{}' is not a vertex id (a mesh vertex id, 0 or more)", flag, text, id));
  std::string rest = text.substr(colon + 1);
  if (kind == palpate::ConstraintKind::kNormalDisplacement) {
    const auto second = rest.rfind(':');
    double depth = 0;
    if (second == std::string::npos || std::sscanf(rest.c_str() + second + 1, "%lf", &depth) != 1)
      throw palpate::InputError(fmt::format("{} '{}': expected VERTEX:nx,ny,nz:DEPTH", flag, text));
    return ConstraintSpec::normal_displacement(vertex, parse_vec3(rest.substr(0, second), flag),
                                               depth);
  }
  return {vertex, kind, parse_vec3(rest, flag), {}};
}

void print_reply(const palpate::Reply& reply) {
  std::printf("request %llu: %s", static_cast<unsigned long long>(reply.request_id),
              palpate::status_name(reply.status));
  if (!reply.message.empty()) std::printf(" — %s", reply.message.c_str());
  // A refused request was not solved: no estimate, time or force to show
  // (its message says why, with the estimate where that was the reason).
  if (reply.status != palpate::RequestStatus::kOk) {
    std::printf("\n");
    return;
  }
  std::printf("\n  condition estimate %.3g, solve %.1f µs, total force (%.6g, %.6g, %.6g) N\n",
              reply.condition_estimate, static_cast<double>(reply.solve_ns) * 1e-3,
              reply.total_force_n[0], reply.total_force_n[1], reply.total_force_n[2]);
  for (const auto& r : reply.results)
    std::printf("  vertex %u: force (%.6g, %.6g, %.6g) N, displacement (%.6g, %.6g, %.6g) m\n",
                r.vertex, r.force_n[0], r.force_n[1], r.force_n[2], r.displacement_m[0],
                r.displacement_m[1], r.displacement_m[2]);
  if (!reply.surface_displacement_m.empty()) {
    double largest = 0;
    for (std::size_t i = 0; i + 2 < reply.surface_displacement_m.size(); i += 3)
      largest = std::max(
          largest, std::hypot(reply.surface_displacement_m[i], reply.surface_displacement_m[i + 1],
                              reply.surface_displacement_m[i + 2]));
    std::printf("  surface: %zu vertices, largest displacement %.3f mm\n",
                reply.surface_displacement_m.size() / 3, largest * 1e3);
  }
}

/// The description of @p model_id; an unknown model is answered as soon as
/// palpated's heartbeat shows every served model was described (about 1 s).
palpate::ModelInfo describe_model(palpate::Client& client, const std::string& model_id,
                                  std::uint32_t domain) {
  const auto model = client.wait_for_model(model_id, 10s);
  if (model) return *model;
  const auto seen = client.models_seen();
  if (seen.empty())
    throw palpate::SystemError(fmt::format(
        "no palpated answered within 10 s: no model description on DDS domain {} (is palpated "
        "running, in this network namespace?)",
        domain));
  std::string ids;
  for (const auto& id : seen) ids += (ids.empty() ? "" : ", ") + id;
  throw palpate::InputError(
      fmt::format("model '{}' is not served by palpated; served: {} (use --model)", model_id, ids));
}

palpate::ModelInfo connect(palpate::Client& client, const std::string& model_id,
                           std::uint32_t domain) {
  const auto model = describe_model(client, model_id, domain);
  if (!client.wait_for_service(10s))
    throw palpate::SystemError("palpated does not answer requests within 10 s");
  return model;
}

/// The reply's surface field as CSV, one compliance vertex a row, written
/// atomically: vertex_id,x_m,y_m,z_m,ux_m,uy_m,uz_m.
void write_field(const std::string& file, const palpate::ModelInfo& model,
                 const palpate::Reply& reply) {
  const auto& s = model.surface;
  const auto n = static_cast<std::size_t>(s.compliance_vertex_count);
  if (reply.surface_displacement_m.size() != 3 * n)
    throw palpate::SystemError(
        fmt::format("the reply carries {} surface values for {} compliance vertices",
                    reply.surface_displacement_m.size(), n));
  palpate::AtomicOutput out(file);
  {
    std::FILE* f = std::fopen(out.temp_path().c_str(), "w");
    if (!f) throw palpate::SystemError(fmt::format("{}: cannot write it", file));
    std::fprintf(f, "vertex_id,x_m,y_m,z_m,ux_m,uy_m,uz_m\n");
    for (std::size_t v = 0; v < n; ++v) {
      const double* x = &s.rest_positions_m[3 * v];
      const double* u = &reply.surface_displacement_m[3 * v];
      std::fprintf(f, "%u,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", s.vertex_ids[v], x[0], x[1], x[2],
                   u[0], u[1], u[2]);
    }
    if (std::fclose(f) != 0) throw palpate::SystemError(fmt::format("{}: write failed", file));
  }
  out.commit();
}

std::atomic<bool> stop_requested{false};
extern "C" void on_stop_signal(int) { stop_requested = true; }

/// Prints a line when palpated goes or comes back (docs/faults.md).
class PresenceReport {
 public:
  explicit PresenceReport(palpate::Client& client)
      : client_(client), last_(client.daemon_presence()) {}
  /// Polls the heartbeat; prints a change; returns the presence now.
  const palpate::DaemonPresence& update() {
    const palpate::DaemonPresence now = client_.daemon_presence();
    if (const auto line = palpate::describe_presence_change(last_, now)) {
      std::printf("palpate-client: %s\n", line->c_str());
      std::fflush(stdout);
    }
    last_ = now;
    return last_;
  }

 private:
  palpate::Client& client_;
  palpate::DaemonPresence last_;
};

double percentile(std::vector<double> values, double q) {
  std::sort(values.begin(), values.end());
  return palpate::sorted_percentile(values, q);
}

/// Press the top of the organ, pinch a triangle, slide along the surface,
/// release: the gestures of docs/model/contact.md at the haptic rate, with the forces.
int demo(palpate::Client& client, const std::string& model_id, std::uint32_t domain, double rate_hz,
         int repeat) {
  const palpate::ModelInfo m = connect(client, model_id, domain);
  std::printf("model %s: %d compliance vertices, %zu triangles; %s\n", m.model_id.c_str(),
              m.surface.compliance_vertex_count, m.surface.triangles.size() / 3,
              m.material_summary.c_str());
  const int n = m.surface.compliance_vertex_count;
  const auto& p = m.surface.rest_positions_m;
  int top = 0;
  for (int i = 1; i < n; ++i)
    if (p[3 * i + 2] > p[3 * top + 2]) top = i;
  // Two neighbours of the top vertex that are free: a triangle to pinch.
  std::vector<int> triangle{top};
  for (std::size_t t = 0; t + 2 < m.surface.triangles.size() && triangle.size() < 3; t += 3) {
    const std::uint32_t* tri = &m.surface.triangles[t];
    if (std::find(tri, tri + 3, static_cast<std::uint32_t>(top)) == tri + 3) continue;
    for (int c = 0; c < 3; ++c)
      if (static_cast<int>(tri[c]) < n &&
          std::find(triangle.begin(), triangle.end(), static_cast<int>(tri[c])) == triangle.end())
        triangle.push_back(static_cast<int>(tri[c]));
  }
  triangle.resize(std::min<std::size_t>(triangle.size(), 3));
  const Eigen::MatrixX3d normals = palpate::vertex_normals(m.surface);
  std::vector<double> round_trip_us;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate_hz));
  auto next = Clock::now();

  PresenceReport presence(client);
  std::size_t resent = 0;
  // A request without a reply within 1 s is sent again until one comes:
  // palpated was killed, hung or restarted (requests in flight are lost; a
  // restarted palpated answers this same client). The lines say when it
  // goes and comes back.
  auto step = [&](const std::vector<ConstraintSpec>& constraints) {
    std::this_thread::sleep_until(next);
    next += period;
    for (;;) {
      const auto sent = Clock::now();
      auto reply = client.wait_reply(client.send(model_id, constraints), 1s);
      presence.update();
      if (!reply) {
        ++resent;
        next = Clock::now() + period;  // the schedule resumes when it answers
        continue;
      }
      round_trip_us.push_back(
          std::chrono::duration<double, std::micro>(Clock::now() - sent).count());
      if (reply->status != palpate::RequestStatus::kOk)
        throw palpate::SystemError(fmt::format(
            "request refused: {}: {}", palpate::status_name(reply->status), reply->message));
      return std::move(*reply);
    }
  };
  auto norm = [](const std::array<double, 3>& v) { return std::hypot(v[0], v[1], v[2]); };
  const int steps = static_cast<int>(rate_hz);  // one second per gesture

  for (int pass = 0; pass < repeat && !stop_requested; ++pass) {
    std::printf("\npress: vertex %u at the top, pushed 0 → 5 mm into the organ over 1 s\n",
                m.surface.vertex_ids[top]);
    for (int s = 1; s <= steps; ++s) {
      const double depth = 0.005 * s / steps;
      const auto reply = step({ConstraintSpec::displacement(
          m.surface.vertex_ids[top],
          {-depth * normals(top, 0), -depth * normals(top, 1), -depth * normals(top, 2)})});
      if (s % (steps / 5) == 0)
        std::printf("  depth %5.1f mm   reaction on the tool %7.3f N\n", depth * 1e3,
                    norm(reply.total_force_n));
    }

    std::printf("\npinch: vertices %u %u %u pulled out 5 mm together\n",
                m.surface.vertex_ids[triangle[0]],
                m.surface.vertex_ids[triangle[std::min<std::size_t>(1, triangle.size() - 1)]],
                m.surface.vertex_ids[triangle.back()]);
    for (int s = 1; s <= steps; ++s) {
      const double lift = 0.005 * s / steps;
      std::vector<ConstraintSpec> constraints;
      for (int v : triangle)
        constraints.push_back(ConstraintSpec::displacement(
            m.surface.vertex_ids[v],
            {lift * normals(top, 0), lift * normals(top, 1), lift * normals(top, 2)}));
      const auto reply = step(constraints);
      if (s % (steps / 5) == 0)
        std::printf("  lift  %5.1f mm   pull on the tool %7.3f N\n", lift * 1e3,
                    norm(reply.total_force_n));
    }

    // Slide: 4 mm normal indentation that moves from vertex to vertex along a path of neighbours.
    std::printf(
        "\nslide: 4 mm indentation gliding over the surface (normal imposed, tangential free)\n");
    int at = top;
    std::vector<int> visited{top};
    for (int s = 1; s <= steps; ++s) {
      if (s % (steps / 10) == 0) {
        // Move to the unvisited free neighbour farthest along +x.
        int best = -1;
        for (std::size_t t = 0; t + 2 < m.surface.triangles.size(); t += 3) {
          const std::uint32_t* tri = &m.surface.triangles[t];
          if (std::find(tri, tri + 3, static_cast<std::uint32_t>(at)) == tri + 3) continue;
          for (int c = 0; c < 3; ++c) {
            const int v = static_cast<int>(tri[c]);
            if (v < n && std::find(visited.begin(), visited.end(), v) == visited.end() &&
                (best < 0 || p[3 * v] > p[3 * best]))
              best = v;
          }
        }
        if (best >= 0) {
          at = best;
          visited.push_back(at);
        }
      }
      const std::array<double, 3> nn{normals(at, 0), normals(at, 1), normals(at, 2)};
      const auto reply =
          step({ConstraintSpec::normal_displacement(m.surface.vertex_ids[at], nn, -0.004)});
      if (s % (steps / 5) == 0)
        std::printf("  at vertex %5u   normal force %7.3f N\n", m.surface.vertex_ids[at],
                    norm(reply.total_force_n));
    }

    step({});
    std::printf("\nrelease: no constraint, the organ is back at rest\n");
  }
  if (resent > 0)
    std::printf("\n%zu requests sent again (no reply within 1 s: palpated was away)", resent);
  std::printf(
      "\n%zu requests at %.0f Hz; round trip seen by this client p50 %.0f µs, p99 %.0f µs, max "
      "%.0f µs\n",
      round_trip_us.size(), rate_hz, percentile(round_trip_us, 0.5),
      percentile(round_trip_us, 0.99), percentile(round_trip_us, 1.0));
  // The daemon's own view: its latest heartbeat (kept by the keep-last-1 reader).
  if (const auto s = client.wait_status(2s))
    std::printf(
        "palpated's last heartbeat: %.0f requests/s, solve p50 %.1f µs p99 %.1f µs, request→reply "
        "p50 %.0f µs "
        "p99 %.0f µs\n",
        s->request_rate_hz, s->solve.p50_us, s->solve.p99_us, s->request_to_reply.p50_us,
        s->request_to_reply.p99_us);
  return 0;
}

int run(int argc, char** argv) {
  CLI::App app{"palpate-client: talks to palpated over DDS (docs/dds.md)"};
  app.require_subcommand(1);
  std::string client_id = fmt::format("palpate-client-{}", ::getpid());
  std::uint32_t domain = 0;
  std::string dds_config;
  app.add_option("--client-id", client_id, "client id (names the reply partition)");
  app.add_option("--domain", domain, "DDS domain id");
  app.add_option("--dds-config", dds_config, "Cyclone DDS configuration (default: loopback only)");
  // Real-time operation of the requesting thread (docs/realtime.md).
  palpate::RealtimeOptions realtime;
  std::string cpus;
  bool busy_wait = false;
  app.add_flag("--busy-wait", busy_wait,
               "poll for each reply instead of sleeping on a waitset (keeps a core busy while "
               "waiting)");
  app.add_option("--rt-priority", realtime.priority,
                 "SCHED_FIFO priority (1-99) of the requesting thread and of Cyclone's receive "
                 "thread (default 0: normal scheduling)");
  app.add_option("--cpus", cpus,
                 "CPUs of the requesting thread and Cyclone's threads, as taskset -c");
  app.add_flag("--lock-memory", realtime.lock_memory, "lock the process's memory (mlockall)");
  app.fallthrough();

  std::string model_id = "sample-organ";
  auto* describe = app.add_subcommand("describe", "print a model's description");
  describe->add_option("--model", model_id, "model id")->capture_default_str();

  auto* request = app.add_subcommand("request", "send one request and print the reply");
  std::vector<std::string> forces, displacements, normals;
  bool surface = false, no_update = false;
  request->add_option("--model", model_id, "model id")->capture_default_str();
  request->add_option("--force", forces, "VERTEX:fx,fy,fz (N), repeatable");
  request->add_option("--displacement", displacements, "VERTEX:ux,uy,uz (m), repeatable");
  request->add_option("--normal-displacement", normals, "VERTEX:nx,ny,nz:DEPTH (m), repeatable");
  request->add_flag("--surface", surface, "ask for the displacement of every surface vertex");
  request->add_flag("--no-update", no_update, "do not change the state the model shows");
  std::string output;
  request
      ->add_option("--output", output,
                   "with --surface: write the field to this CSV file (vertex id, rest position and "
                   "displacement of every compliance vertex, m)")
      ->needs("--surface");

  auto* demo_command = app.add_subcommand("demo", "scripted palpation at the haptic rate");
  double rate_hz = 1000;
  demo_command->add_option("--model", model_id, "model id")->capture_default_str();
  demo_command->add_option("--rate", rate_hz, "requests per second (default 1000)")
      ->check(CLI::Range(10.0, 20000.0));
  int repeat = 1;
  demo_command->add_option("--repeat", repeat, "play the palpation this many times (default 1)")
      ->check(CLI::Range(1, 1000000));

  auto* watch = app.add_subcommand(
      "watch", "report palpated going and coming back (its status heartbeat) until SIGINT/SIGTERM");
  double watch_seconds = 0;
  watch->add_option("--seconds", watch_seconds, "stop after this many seconds (default: never)")
      ->check(CLI::NonNegativeNumber);

  auto* status = app.add_subcommand("status", "print one status heartbeat");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "palpate-client: error: %s%s (see --help)\n", e.what(),
                 palpate::flag_suggestions(std::vector<std::string>(argv + 1, argv + argc),
                                           palpate::long_flag_names(app))
                     .c_str());
    return static_cast<int>(palpate::ExitCode::kUsage);
  }

  if (!cpus.empty()) realtime.cpus = palpate::realtime::parse_cpu_list(cpus, "--cpus");
  palpate::realtime::validate(realtime, palpate::realtime::kFlagNames);
  palpate::realtime::check_permitted(realtime, palpate::realtime::kFlagNames);
  palpate::ClientOptions options{client_id, domain, dds_config, false,
                                 status->parsed() || demo_command->parsed()};
  options.busy_wait = busy_wait;
  options.realtime = {realtime.priority, realtime.cpus, /*lock_memory=*/false};
  palpate::Client client(options);
  palpate::realtime::lock_memory(realtime, palpate::realtime::kFlagNames);
  palpate::realtime::apply_to_this_thread(realtime, palpate::realtime::kFlagNames);
  if (*describe) {
    const palpate::ModelInfo m = describe_model(client, model_id, domain);
    std::printf(
        "model %s\n  units %s\n  material %s\n  input %s\n  %d compliance vertices, %zu drawn, %zu "
        "triangles\n",
        m.model_id.c_str(), m.units.c_str(), m.material_summary.c_str(), m.input_hash.c_str(),
        m.surface.compliance_vertex_count, m.surface.vertex_ids.size(),
        m.surface.triangles.size() / 3);
    if (m.max_displacement_m > 0)
      std::printf("  a request may impose at most %.4g m and give at most %.4g N per vertex\n",
                  m.max_displacement_m, m.max_force_n);
    return 0;
  }
  if (*request) {
    std::vector<ConstraintSpec> constraints;
    for (const auto& f : forces)
      constraints.push_back(parse_constraint(f, palpate::ConstraintKind::kForce, "--force"));
    for (const auto& d : displacements)
      constraints.push_back(
          parse_constraint(d, palpate::ConstraintKind::kDisplacement, "--displacement"));
    for (const auto& d : normals)
      constraints.push_back(parse_constraint(d, palpate::ConstraintKind::kNormalDisplacement,
                                             "--normal-displacement"));
    if (!output.empty() && output.ends_with(".h5"))
      throw palpate::InputError(
          fmt::format("--output {}: the field is written as CSV; name the file .csv", output));
    if (!output.empty()) palpate::require_output_directory(output);
    const palpate::ModelInfo model = connect(client, model_id, domain);
    const auto reply = client.request(model_id, constraints, surface, !no_update);
    print_reply(reply);
    if (!output.empty() && reply.status == palpate::RequestStatus::kOk) {
      write_field(output, model, reply);
      std::printf("  surface field written to %s\n", output.c_str());
    }
    return reply.status == palpate::RequestStatus::kOk
               ? 0
               : static_cast<int>(palpate::ExitCode::kUsage);
  }
  if (*demo_command) return demo(client, model_id, domain, rate_hz, repeat);
  if (*watch) {
    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    PresenceReport presence(client);
    bool seen = false;
    const auto until = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(watch_seconds));
    while (!stop_requested && (watch_seconds == 0 || Clock::now() < until)) {
      const auto& p = presence.update();
      if (!seen && p.state == palpate::DaemonState::kPresent) {
        seen = true;
        std::printf("palpate-client: palpated present (up %.1f s)\n", p.uptime_s);
        std::fflush(stdout);
      }
      std::this_thread::sleep_for(20ms);
    }
    return 0;
  }
  const auto s = client.wait_status(10s);
  if (!s) throw palpate::SystemError("no status heartbeat within 10 s (is palpated running?)");
  std::printf(
      "daemon %s: up %.1f s, %llu requests (%llu refused), %.0f requests/s, %.1f surface "
      "samples/s\n"
      "  solve p50 %.1f µs p99 %.1f µs p99.9 %.1f µs; request→reply p50 %.1f µs p99 %.1f µs\n"
      "  %u models, %u clients\n",
      s->daemon_id.c_str(), static_cast<double>(s->uptime_ns) * 1e-9,
      static_cast<unsigned long long>(s->requests_served),
      static_cast<unsigned long long>(s->error_replies), s->request_rate_hz, s->surface_rate_hz,
      s->solve.p50_us, s->solve.p99_us, s->solve.p999_us, s->request_to_reply.p50_us,
      s->request_to_reply.p99_us, s->models, s->clients);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Line by line into a file or a pipe too: a log of the demo or of `watch`
  // shows each line as it happens (and keeps it if the client is killed).
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  try {
    return run(argc, argv);
  } catch (...) {
    return palpate::report_current_exception("palpate-client");
  }
}
