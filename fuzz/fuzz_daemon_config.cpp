// palpated's configuration: read_daemon_config on fuzzed TOML, then what
// palpated does with a configuration it read: validate(), and for a valid
// one the contact engine built from its tools, contact settings and limits
// (on a small real model, model files pointed at it). InputError is the only
// accepted failure; a configuration that validates must build an engine.

#include <cstdint>
#include <span>

#include "fuzz_support.hpp"
#include "palpate/daemon/daemon_config.hpp"
#include "palpate/runtime/tool_contact.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const palpate::SurfaceModel& model = palpate::fuzz::box_model();
  const auto file = palpate::fuzz::write_scratch_file("palpated.toml", {data, size});
  palpate::DaemonConfig config;
  if (!palpate::fuzz::accepted([&] { config = palpate::read_daemon_config(file); })) return 0;
  // Model files are checked for existence only; let validation go past them.
  for (auto& m : config.models) m.file = palpate::fuzz::box_compliance_file();
  if (!palpate::fuzz::accepted([&] { palpate::validate(config); })) return 0;

  // Two threads per solver only where the machine has them; one here.
  config.limits.surface_threads = 1;
  palpate::ToolContactEngine engine(model, config.tools, config.contact, config.limits);
  PALPATE_FUZZ_CHECK(engine.tool_count() == static_cast<int>(config.tools.size()));
  // One pose per tool, pressing the top face (z = 40 mm) with the jaws shut.
  for (int t = 0; t < engine.tool_count(); ++t) {
    palpate::ToolPoseInput pose;
    pose.sequence = 1;
    pose.position_m = {0.05, 0.025, 0.04 + engine.tool(t).tip_length_m};
    pose.orientation = Eigen::Quaterniond(0, 1, 0, 0);  // shaft pointing down
    if (engine.check(t, pose) != palpate::PoseProblem::kNone) continue;
    engine.update(t, pose, 0.001 * t);
    PALPATE_FUZZ_CHECK(engine.output(t).force_n.allFinite());
    PALPATE_FUZZ_CHECK(engine.output(t).force_n.norm() <=
                       engine.tool(t).force_limit_n * (1 + 1e-9));
  }
  return 0;
}
