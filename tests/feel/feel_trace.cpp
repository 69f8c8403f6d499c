#include "feel/feel_trace.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>

#include "palpate/core/error.hpp"
#include "palpate/daemon/daemon_config.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace palpate::feel {

FeelSetup FeelSetup::palpated_defaults() {
  const DaemonConfig daemon;
  FeelSetup setup;
  setup.tools = daemon.tools;
  setup.contact = daemon.contact;
  setup.limits = daemon.limits;
  // The surface field of request replies only; the tools' forces do not use it.
  setup.limits.surface_threads = 1;
  return setup;
}

FeelTrace play(const SurfaceModel& model, const Gesture& gesture, const FeelSetup& setup) {
  const GesturePlayer player(gesture, place_gesture(gesture, model.surface));
  ToolContactEngine engine(model, setup.tools, setup.contact, setup.limits);
  FeelTrace trace;
  trace.gesture = gesture.name;
  std::vector<int> engine_tool;
  for (int t = 0; t < player.tool_count(); ++t) {
    trace.tools.push_back(player.tool_id(t));
    engine_tool.push_back(engine.tool_index(player.tool_id(t)));
    if (engine_tool.back() < 0)
      throw InputError(fmt::format("{}: tool '{}' is not one of palpated's default tools",
                                   gesture.source, player.tool_id(t)));
  }
  // palpate-pliers: floor(duration · rate) + 1 ticks, pose i at i / rate.
  const double period_s = 1.0 / setup.rate_hz;
  trace.ticks = static_cast<int>(std::floor(player.duration_s() * setup.rate_hz + 1e-9)) + 1;
  trace.horizon.assign(trace.tools.size(), trace.ticks);
  trace.samples.reserve(static_cast<std::size_t>(trace.ticks) * trace.tools.size());
  for (int i = 0; i < trace.ticks; ++i) {
    const double t = static_cast<double>(i) * period_s;
    for (int k = 0; k < player.tool_count(); ++k) {
      const GesturePose p = player.sample(k, t);
      ToolPoseInput pose;
      pose.sequence = static_cast<std::uint64_t>(i) + 1;
      pose.position_m = p.hinge_m;
      pose.orientation = p.orientation;
      pose.jaw_angle_rad = p.jaw_angle_rad;
      const int tool = engine_tool[static_cast<std::size_t>(k)];
      if (engine.check(tool, pose) != PoseProblem::kNone)
        throw InputError(fmt::format("{}: pose {} of tool '{}' refused: {}", gesture.source, i + 1,
                                     player.tool_id(k), engine.problem_message()));
      // A failed solve keeps the last contacts and repeats the last output,
      // as palpated does: the trace records what the tool would feel.
      if (engine.update(tool, pose, t) != RequestStatus::kOk) ++trace.failed_solves;
      const ToolOutput& out = engine.output(tool);
      FeelSample s;
      s.tick = i;
      s.time_s = t;
      s.tool = k;
      s.force_n = out.force_n;
      s.torque_nm = out.torque_nm;
      s.grip_n = out.grip_n;
      s.contacts = out.contacts;
      s.held = out.held;
      s.state = out.state;
      trace.samples.push_back(s);
    }
  }
  return trace;
}

void perturb_compliance(SurfaceModel& model, double relative, unsigned seed) {
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> unit(-1, 1);
  Eigen::MatrixXd& G = model.G;
  for (Eigen::Index j = 0; j < G.cols(); ++j)
    for (Eigen::Index i = 0; i <= j; ++i) {
      G(i, j) *= 1 + relative * unit(random);
      G(j, i) = G(i, j);
    }
}

namespace {

bool same_discrete(const FeelSample& a, const FeelSample& b) {
  return a.state == b.state && a.contacts == b.contacts && a.held == b.held;
}

constexpr const char* kHeader =
    "tick,time_s,tool,fx_n,fy_n,fz_n,tx_nm,ty_nm,tz_nm,grip_n,contacts,held,state";

}  // namespace

void write_csv(const std::filesystem::path& file, const FeelTrace& trace, int stride,
               const std::string& comment) {
  const std::size_t n_tools = trace.tools.size();
  std::vector<bool> keep(trace.samples.size(), false);
  for (std::size_t j = 0; j < trace.samples.size(); ++j) {
    const FeelSample& s = trace.samples[j];
    if (s.tick % stride == 0 || s.tick == trace.ticks - 1) keep[j] = true;
    // The same tool one tick earlier is n_tools samples back.
    if (j >= n_tools && !same_discrete(s, trace.samples[j - n_tools]))
      keep[j] = keep[j - n_tools] = true;
  }
  std::ofstream out(file);
  if (!out) throw InputError(fmt::format("{}: cannot write", file.string()));
  out << "# palpate feel trace: " << comment << "\n";
  out << "# gesture " << trace.gesture << "\n# ticks " << trace.ticks << "\n# stride " << stride
      << "\n# tools";
  for (const auto& id : trace.tools) out << ' ' << id;
  out << '\n';
  for (std::size_t k = 0; k < n_tools; ++k)
    out << "# horizon " << trace.tools[k] << ' '
        << (k < trace.horizon.size() ? trace.horizon[k] : trace.ticks) << '\n';
  out << kHeader << '\n';
  for (std::size_t j = 0; j < trace.samples.size(); ++j) {
    if (!keep[j]) continue;
    const FeelSample& s = trace.samples[j];
    // Seven significant digits: far below the test's tolerance (0.5 %).
    out << fmt::format("{},{:.3f},{},{:.7g},{:.7g},{:.7g},{:.7g},{:.7g},{:.7g},{:.7g},{},{},{}\n",
                       s.tick, s.time_s, trace.tools[static_cast<std::size_t>(s.tool)],
                       s.force_n.x(), s.force_n.y(), s.force_n.z(), s.torque_nm.x(),
                       s.torque_nm.y(), s.torque_nm.z(), s.grip_n, s.contacts, s.held,
                       tool_state_name(s.state));
  }
  if (!out.flush()) throw InputError(fmt::format("{}: write failed", file.string()));
}

FeelTrace read_csv(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in)
    throw InputError(
        fmt::format("{}: no such trace (regenerate with "
                    "scripts/regenerate-feel-traces.sh)",
                    file.string()));
  FeelTrace trace;
  std::string line;
  int number = 0;
  auto fail = [&](const std::string& what) {
    throw InputError(fmt::format("{}:{}: {} (a trace written by palpate_play_gesture: {})",
                                 file.string(), number, what, kHeader));
  };
  bool header = false;
  std::vector<std::pair<std::string, int>> horizons;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    if (line[0] == '#') {
      std::istringstream words(line.substr(1));
      std::string key;
      words >> key;
      if (key == "gesture") words >> trace.gesture;
      if (key == "ticks") words >> trace.ticks;
      if (key == "stride") words >> trace.stride;
      if (key == "tools")
        for (std::string id; words >> id;) trace.tools.push_back(id);
      if (key == "horizon") {
        std::string id;
        int tick = -1;
        words >> id >> tick;
        horizons.emplace_back(id, tick);
      }
      continue;
    }
    if (!header) {
      if (line != kHeader) fail("not the header");
      header = true;
      continue;
    }
    std::istringstream fields(line);
    std::vector<std::string> f;
    for (std::string cell; std::getline(fields, cell, ',');) f.push_back(cell);
    if (f.size() != 13) fail(fmt::format("{} fields, expected 13", f.size()));
    FeelSample s;
    try {
      s.tick = std::stoi(f[0]);
      s.time_s = std::stod(f[1]);
      s.force_n = {std::stod(f[3]), std::stod(f[4]), std::stod(f[5])};
      s.torque_nm = {std::stod(f[6]), std::stod(f[7]), std::stod(f[8])};
      s.grip_n = std::stod(f[9]);
      s.contacts = std::stoi(f[10]);
      s.held = std::stoi(f[11]);
    } catch (const std::exception&) {
      fail("a number that does not parse");
    }
    const auto tool = std::find(trace.tools.begin(), trace.tools.end(), f[2]);
    if (tool == trace.tools.end()) fail("tool '" + f[2] + "' not in the '# tools' line");
    s.tool = static_cast<int>(tool - trace.tools.begin());
    bool known = false;
    for (const ToolState state : {ToolState::kFree, ToolState::kTouching, ToolState::kGrasping})
      if (f[12] == tool_state_name(state)) {
        s.state = state;
        known = true;
      }
    if (!known) fail("state '" + f[12] + "' (accepted: free, touching, grasping)");
    trace.samples.push_back(s);
  }
  if (!header || trace.ticks <= 0 || trace.tools.empty() || trace.stride <= 0)
    fail("missing '# ticks', '# stride', '# tools' or the header");
  trace.horizon.assign(trace.tools.size(), trace.ticks);
  for (const auto& [id, tick] : horizons) {
    const auto tool = std::find(trace.tools.begin(), trace.tools.end(), id);
    if (tool == trace.tools.end() || tick < 0 || tick > trace.ticks)
      fail(fmt::format("'# horizon {} {}': expected a tool of '# tools' and 0 to {} ticks", id,
                       tick, trace.ticks));
    trace.horizon[static_cast<std::size_t>(tool - trace.tools.begin())] = tick;
  }
  return trace;
}

}  // namespace palpate::feel
