// palpate_play_gesture: plays a gesture file through ToolContactEngine in
// process (no DDS, simulated time at 1 kHz) with palpated's default tools
// and writes what each tool feels as a CSV trace (docs/tools.md, "The feel
// under regression tests"). scripts/regenerate-feel-traces.sh writes the
// reference traces of tests/feel/reference/ with it.
//
// Usage: palpate_play_gesture MODEL.h5 GESTURE.toml -o TRACE.csv [--stride 10]
//            [--compare REFERENCE.csv] [--stiffness-scale S] [--friction MU]
//            [--compliance-noise REL [--seed N]]
//
// --stiffness-scale S plays an organ S times as stiff (G / S: for linear
// elasticity, E × S with the same Poisson ratio) and --friction MU sets both
// tools' friction: perturbations that show what the test rejects;
// --compliance-noise REL moves each entry of G by up to REL relative, as a
// different BLAS kernel would at ~1e-12.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <optional>

#include "feel/feel_compare.hpp"
#include "feel/feel_trace.hpp"
#include "palpate/core/error.hpp"
#include "palpate/core/system_info.hpp"

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  palpate::set_blas_threads(1);  // as palpated
  CLI::App app{"Plays a gesture in process and writes what the tools feel (CSV)"};
  std::string model_path, gesture_path, output, reference;
  int stride = 10;
  double stiffness_scale = 1;
  std::optional<double> friction;
  double noise = 0;
  unsigned seed = 17;
  app.add_option("model", model_path, "compliance file (HDF5)")->required();
  app.add_option("gesture", gesture_path, "gesture file (TOML, docs/pliers.md)")->required();
  app.add_option("-o,--output", output, "trace to write (CSV)");
  app.add_option("--stride", stride, "keep every N-th tick, plus transitions (default 10)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--compare", reference,
                 "compare with this reference trace; exit 1 when outside the tolerance");
  app.add_option("--stiffness-scale", stiffness_scale, "an organ this many times as stiff")
      ->check(CLI::PositiveNumber);
  app.add_option("--friction", friction, "both tools' friction (default 0.3)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--compliance-noise", noise,
                 "move each entry of G by up to this much, relative (symmetric, seeded): "
                 "what round-off does to the feel")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--seed", seed, "of --compliance-noise (default 17)");
  CLI11_PARSE(app, argc, argv);
  try {
    palpate::SurfaceModel model = palpate::load_surface_model("organ", model_path);
    if (stiffness_scale != 1) model.G /= stiffness_scale;
    if (noise > 0) palpate::feel::perturb_compliance(model, noise, seed);
    const palpate::Gesture gesture = palpate::read_gesture_file(gesture_path);
    auto setup = palpate::feel::FeelSetup::palpated_defaults();
    if (friction)
      for (auto& tool : setup.tools) tool.friction = *friction;
    const palpate::feel::FeelTrace trace = palpate::feel::play(model, gesture, setup);
    if (trace.failed_solves > 0)
      std::fprintf(stderr, "palpate_play_gesture: %s: %d failed solves (output repeated)\n",
                   gesture.name.c_str(), trace.failed_solves);
    if (!output.empty()) {
      // The reference's horizon: where round-off alone changes the trace.
      palpate::feel::FeelTrace written = trace;
      palpate::feel::find_horizon(written, model, gesture, setup);
      for (std::size_t k = 0; k < written.tools.size(); ++k)
        if (written.horizon[k] < written.ticks)
          std::printf("%s: %s: round-off changes the trace from %.3f s: compared until then\n",
                      gesture.name.c_str(), written.tools[k].c_str(),
                      written.horizon[k] / setup.rate_hz);
      palpate::feel::write_csv(
          output, written, stride,
          "palpated's default tools on the sample organ (tests/feel/make_organ.sh), 1 kHz");
    }
    if (!reference.empty()) {
      const auto c = palpate::feel::compare(palpate::feel::read_csv(reference), trace);
      std::printf("%s: %s: %s\n", gesture.name.c_str(), c.passed() ? "same feel" : "CHANGED",
                  c.summary().c_str());
      return c.passed() ? 0 : 1;
    }
    return 0;
  } catch (...) {
    return palpate::report_current_exception("palpate_play_gesture");
  }
}
