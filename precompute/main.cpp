// palpate-precompute: organ mesh + material + attachment → verified surface
// compliance file (HDF5). Argument parsing and wiring only; the work is in
// the palpate library (precompute.hpp).

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>

#include "palpate/core/error.hpp"
#include "palpate/core/suggest.hpp"
#include "palpate/core/system_info.hpp"
#include "palpate/core/units.hpp"
#include "palpate/core/version.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/xdmf.hpp"
#include "palpate/offline/inspect.hpp"
#include "palpate/offline/mesh_io.hpp"
#include "palpate/offline/precompute.hpp"
#include "progress_bar.hpp"

namespace {

using palpate::ExitCode;

Eigen::Vector3d vec3(const std::vector<double>& v, size_t offset) {
  return {v[offset], v[offset + 1], v[offset + 2]};
}

/// For the fault tests (tests/faults, docs/faults.md): with
/// PALPATE_PRECOMPUTE_STOP_AT=<phase> the process stops itself (SIGSTOP) as
/// that phase starts; with <phase>@half, halfway through a phase that
/// reports progress (condensation, solves, write file). The test then kills
/// it there, deterministically, whatever the machine's speed.
class StopPoint {
 public:
  StopPoint() {
    if (const char* at = std::getenv("PALPATE_PRECOMPUTE_STOP_AT")) {
      const std::string_view v(at);
      const auto half = v.find("@half");
      halfway_ = half != std::string_view::npos;
      phase_ = std::string(v.substr(0, half));
    }
  }
  void at_phase(const std::string& phase) const {
    if (!halfway_ && !phase_.empty() && phase == phase_) stop();
  }
  /// Wraps @p inner (may be empty) for the progress of @p label ("1098 solves").
  palpate::ProgressFn progress(const std::string& label, palpate::ProgressFn inner) const {
    if (!halfway_ || phase_.empty() || !label.ends_with(phase_)) return inner;
    auto stopped = std::make_shared<std::atomic<bool>>(false);
    return [inner = std::move(inner), stopped](long done, long total) {
      if (inner) inner(done, total);
      if (2 * done >= total && !stopped->exchange(true)) stop();
    };
  }

 private:
  static void stop() {
    std::fflush(stderr);
    std::raise(SIGSTOP);
  }
  std::string phase_;
  bool halfway_ = false;
};

int run(int argc, char** argv) {
  CLI::App app{
      "palpate-precompute: surface compliance of an elastic organ (Cotin, Delingette & "
      "Ayache 1999), computed with CHOLMOD by 3N_S solves and by condensation, "
      "cross-checked, written to one HDF5 file"};
  app.set_version_flag("--version", "palpate-precompute " PALPATE_VERSION);

  std::string job_file, mesh, mesh_unit, fix_ids, method, precision, output, save_job, shard,
      columns;
  std::vector<std::string> fix_groups, materials;
  std::vector<double> box, sphere, half_space, cut_box, cut_sphere;
  std::string cut_group;
  double young = 0, poisson = 0, fill_size = 0, tolerance = 0, memory_gb = 0, cut_density = 0,
         cut_damping = 0;
  int block_columns = 0;
  bool json_out = false, quiet = false, xdmf = true, phases = false, reuse = false;

  app.add_option("-j,--job", job_file, "TOML job file (config/*.toml); flags override it");
  app.add_option("--mesh", mesh,
                 "tetrahedral mesh (.msh v2/v4, .mesh, .vtk) or closed surface (.stl)");
  app.add_option("--mesh-unit", mesh_unit, "unit of the mesh coordinates: m, cm or mm (default m)");
  app.add_option(
      "--fill-size", fill_size,
      "STL only: target tetrahedron size, in the mesh unit (default: 1/20 of the diagonal)");
  app.add_option("-E,--young-modulus", young, "Young's modulus of the organ, Pa");
  app.add_option("--poisson-ratio,--nu", poisson, "Poisson ratio of the organ, in (-1, 0.5)");
  app.add_option("--group-material", materials,
                 "material of a physical volume: NAME:E_PA:NU (repeatable)");
  app.add_option("--fix-ids", fix_ids,
                 "file of 0-based vertex indices to fix, one per line (mesh file node order)");
  app.add_option("--fix-group", fix_groups,
                 "fix the vertices of a Gmsh physical group (repeatable)");
  app.add_option("--fix-box", box,
                 "fix vertices in a box: XMIN YMIN ZMIN XMAX YMAX ZMAX (mesh unit)")
      ->expected(6);
  app.add_option("--fix-sphere", sphere, "fix vertices in a ball: CX CY CZ R (mesh unit)")
      ->expected(4);
  app.add_option("--fix-half-space", half_space,
                 "fix vertices with (x-p).n >= 0: PX PY PZ NX NY NZ (mesh unit)")
      ->expected(6);
  app.add_option("--cut-box", cut_box,
                 "cuttable region: the tetrahedra whose centroid is in a box: XMIN YMIN ZMIN XMAX "
                 "YMAX ZMAX (mm)")
      ->expected(6);
  app.add_option("--cut-sphere", cut_sphere,
                 "cuttable region: the tetrahedra whose centroid is in a ball: CX CY CZ R (mm)")
      ->expected(4);
  app.add_option("--cut-group", cut_group, "cuttable region: a 3-D physical group of the mesh");
  app.add_option("--cut-density", cut_density,
                 "density of the cuttable region, kg/m³ (default 1060, soft tissue)");
  app.add_option("--cut-damping", cut_damping,
                 "mass-proportional damping of the cuttable region, 1/s (default 20)");
  app.add_option("--method", method,
                 "solves, condensation or both (default both: computes both and cross-checks)");
  app.add_option("--precision", precision, "storage of G: float64 (default) or float32");
  app.add_option("--block-columns", block_columns,
                 "right-hand sides per blocked solve (default 64)");
  app.add_option("--tolerance", tolerance,
                 "largest accepted relative difference between the methods (default 1e-8)");
  app.add_option("--memory-limit-gb", memory_gb,
                 "refuse jobs needing more than this (default: available memory)");
  app.add_option("-o,--output", output, "compliance file to write (HDF5, written atomically)");
  app.add_option(
      "--shard", shard,
      "compute only shard INDEX/COUNT of G's columns (0-based, whole blocks) into "
      "OUTPUT-stem.part-BEGIN-END.h5, for merge (docs/precompute.md, \"Batch precomputation\")");
  app.add_option("--columns", columns,
                 "compute only columns BEGIN:END of G (BEGIN a multiple of --block-columns) into "
                 "a shard file, for merge");
  app.add_flag("--reuse", reuse,
               "keep the output if it already holds this problem (same input hash and precision, "
               "intact) instead of computing it again");
  app.add_flag("--xdmf,!--no-xdmf", xdmf,
               "write (default) or not the XDMF sidecar X.xdmf next to X.h5, for ParaView");
  app.add_option("--save-job", save_job, "write the effective job as TOML (to reproduce the run)");
  app.add_flag("--json", json_out, "print the report as JSON on stdout");
  app.add_flag("-q,--quiet", quiet, "no progress or report text on stderr (warnings still)");
  app.add_flag(
      "--phases", phases,
      "print a line on stderr as each phase starts (for logs; a terminal shows progress bars)");

  app.fallthrough();  // -q and friends also after the subcommand
  auto* sample =
      app.add_subcommand("make-sample", "write palpate's sample organ (Gmsh .msh, metres)");
  std::string sample_out;
  double sample_size = 0.012;
  sample
      ->add_option("-o,--output", sample_out,
                   "mesh file to write (format from the extension: .msh, .mesh, .vtk...)")
      ->required();
  sample->add_option("--size", sample_size, "target tetrahedron size, m (default 0.012)");

  auto* inspect = app.add_subcommand(
      "inspect",
      "look at a mesh before choosing its unit, attachment and method: counts, size in each "
      "unit, groups, quality, what G and each method would cost (with --json: as JSON)");
  std::string inspect_mesh;
  inspect->add_option("mesh", inspect_mesh, "the mesh file (as --mesh)")->required();
  inspect->footer(
      "Also: --mesh-unit U (m, cm or mm: the unit its quality and box in metres assume), "
      "--fill-size L (an STL's tetrahedron size, mesh unit), --json (print as JSON); e.g. "
      "palpate-precompute inspect liver.msh --mesh-unit mm");

  auto* merge = app.add_subcommand(
      "merge",
      "assemble the shards of one job (--shard/--columns) into the compliance file, "
      "identical to a single run");
  std::string merge_out;
  std::vector<std::string> merge_shards;
  merge->add_option("-o,--output", merge_out, "compliance file to write")->required();
  merge->add_option("shards", merge_shards, "the shard files, e.g. liver.part-*.h5")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every usage error exits 2 with one line.
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "palpate-precompute: error: %s%s (see --help)\n", e.what(),
                 palpate::flag_suggestions(std::vector<std::string>(argv + 1, argv + argc),
                                           palpate::long_flag_names(app))
                     .c_str());
    return static_cast<int>(ExitCode::kUsage);
  }

  auto log = spdlog::stderr_color_mt("palpate");
  log->set_pattern("palpate-precompute: %l: %v");
  // -q hides progress and the report, never a warning: a value the user
  // probably did not mean must be seen (docs/errors.md, "Warnings").
  log->set_level(quiet ? spdlog::level::warn : spdlog::level::info);

  if (*sample) {
    palpate::write_sample_organ(sample_out, sample_size);
    if (!quiet) log->info("sample organ written to {}", sample_out);
    return 0;
  }

  palpate::PrecomputeHooks hooks;
  hooks.warn = [&](const std::string& s) { log->warn("{}", s); };
  hooks.info = [&](const std::string& s) { log->info("{}", s); };
  const bool bars = !quiet && palpate::precompute::ProgressBar::wanted();
  const StopPoint stop_point;
  hooks.phase = [&](const std::string& s) {
    if (phases) {
      std::fprintf(stderr, "palpate-precompute: phase: %s\n", s.c_str());
      std::fflush(stderr);
    } else if (!quiet && !bars) {
      log->debug("{}", s);
    }
    stop_point.at_phase(s);
  };
  hooks.progress = [&](const std::string& label) -> palpate::ProgressFn {
    return stop_point.progress(label,
                               bars ? palpate::ProgressFn(palpate::precompute::ProgressBar(label))
                                    : palpate::ProgressFn{});
  };

  if (*inspect) {
    const palpate::MeshReadOptions read_options{
        palpate::parse_length_unit(mesh_unit.empty() ? "m" : mesh_unit), fill_size};
    const auto inspection = palpate::inspect_mesh(inspect_mesh, read_options);
    if (json_out)
      std::cout << palpate::inspection_json(inspection) << std::endl;
    else
      std::cout << palpate::format_inspection(inspection);
    return 0;
  }

  if (*merge) {
    palpate::MergeJob job;
    job.output = merge_out;
    for (const auto& s : merge_shards) job.shards.emplace_back(s);
    if (app.count("--xdmf")) job.write_xdmf = xdmf;
    if (app.count("--memory-limit-gb")) job.memory_limit_bytes = 1e9 * memory_gb;
    for (const auto& target : {job.output, palpate::xdmf_sidecar_path(job.output),
                               palpate::xdmf_surface_sidecar_path(job.output)})
      for (const auto& stale : palpate::remove_stale_temporaries(target))
        log->warn("removed {}, left by an interrupted run (process {} is gone)",
                  stale.path.string(), stale.pid);
    palpate::install_interrupt_cleanup();
    const auto report = palpate::merge_shards(job, hooks);
    if (json_out) std::cout << palpate::to_json(report, 2) << std::endl;
    if (!quiet) std::cerr << palpate::format_report(report);
    return 0;
  }

  palpate::PrecomputeJob job;
  if (!job_file.empty()) job = palpate::read_job_file(job_file);
  if (!mesh.empty()) job.mesh_file = mesh;
  if (!mesh_unit.empty()) job.mesh_unit = mesh_unit;
  const double unit = palpate::parse_length_unit(job.mesh_unit).to_metres;
  if (app.count("--fill-size")) job.fill_size = fill_size;
  if (app.count("--young-modulus")) job.young_modulus_pa = young;
  if (app.count("--poisson-ratio")) job.poisson_ratio = poisson;
  for (const auto& spec : materials) {
    const auto a = spec.find(':'), b = spec.rfind(':');
    if (a == std::string::npos || a == b)
      throw palpate::InputError(fmt::format("--group-material '{}': expected NAME:E_PA:NU", spec));
    try {
      job.group_materials.push_back({spec.substr(0, a), std::stod(spec.substr(a + 1, b - a - 1)),
                                     std::stod(spec.substr(b + 1))});
    } catch (const std::logic_error&) {
      throw palpate::InputError(
          fmt::format("--group-material '{}': expected NAME:E_PA:NU with numbers", spec));
    }
  }
  if (!fix_ids.empty()) job.attachment.ids_file = fix_ids;
  for (const auto& g : fix_groups) job.attachment.groups.push_back(g);
  if (!box.empty() || !sphere.empty() || !half_space.empty())
    job.attachment.unit = job.mesh_unit.empty() ? "m" : job.mesh_unit;
  if (!box.empty()) job.attachment.boxes.push_back({unit * vec3(box, 0), unit * vec3(box, 3)});
  if (!sphere.empty()) job.attachment.spheres.push_back({unit * vec3(sphere, 0), unit * sphere[3]});
  if (!half_space.empty())
    job.attachment.half_spaces.push_back({unit * vec3(half_space, 0), vec3(half_space, 3)});
  // A shape flag replaces the job file's region shape; its density and
  // damping stay unless flags give them too.
  const int cut_shapes =
      (cut_box.empty() ? 0 : 1) + (cut_sphere.empty() ? 0 : 1) + (app.count("--cut-group") ? 1 : 0);
  if (cut_shapes > 1)
    throw palpate::InputError(
        "--cut-box, --cut-sphere and --cut-group each give the cut region: give one");
  if (cut_shapes == 1) {
    if (!job.cut_region) job.cut_region.emplace();
    const auto mm = [](const Eigen::Vector3d& v) {
      return Eigen::Vector3d(v.unaryExpr([](double x) { return palpate::millimetres(x); }));
    };
    palpate::RegionSpec& spec = job.cut_region->spec;
    if (!cut_box.empty())
      spec = palpate::RegionSpec::box(mm(vec3(cut_box, 0)), mm(vec3(cut_box, 3)));
    else if (!cut_sphere.empty())
      spec =
          palpate::RegionSpec::sphere(mm(vec3(cut_sphere, 0)), palpate::millimetres(cut_sphere[3]));
    else
      spec = palpate::RegionSpec::physical_group(cut_group);
  }
  if ((app.count("--cut-density") || app.count("--cut-damping")) && !job.cut_region)
    throw palpate::InputError(
        "--cut-density and --cut-damping describe a cut region: give one with --cut-box, "
        "--cut-sphere, --cut-group or [cut_region]");
  if (app.count("--cut-density")) job.cut_region->density_kg_m3 = cut_density;
  if (app.count("--cut-damping")) job.cut_region->damping_per_s = cut_damping;
  if (!method.empty()) job.method = palpate::parse_method(method);
  if (!precision.empty()) job.precision = palpate::parse_precision(precision);
  if (app.count("--block-columns")) job.block_columns = block_columns;
  if (app.count("--tolerance")) job.tolerance = tolerance;
  if (app.count("--memory-limit-gb")) job.memory_limit_bytes = 1e9 * memory_gb;
  if (!output.empty()) job.output = output;
  if (app.count("--xdmf")) job.write_xdmf = xdmf;  // either spelling
  job.reuse = reuse;
  if (!shard.empty() && !columns.empty())
    throw palpate::InputError("--shard and --columns both given: use one");
  if (!shard.empty()) palpate::parse_shard(shard, &job.shard);
  if (!columns.empty()) palpate::parse_shard(columns, &job.shard);
  if (!shard.empty() && job.shard.count == 0)
    throw palpate::InputError(fmt::format("--shard '{}': expected INDEX/COUNT, e.g. 0/4", shard));
  if (!columns.empty() && job.shard.begin < 0)
    throw palpate::InputError(
        fmt::format("--columns '{}': expected BEGIN:END, e.g. 0:1024", columns));

  if (!save_job.empty()) {
    palpate::AtomicOutput out(save_job);
    std::ofstream(out.temp_path()) << palpate::to_toml(job);
    out.commit();
  }

  // Temporaries of earlier runs of this output that were killed (SIGKILL:
  // no handler could remove them; docs/compliance-file.md, "Atomic writing").
  for (const auto& target : {job.output, palpate::xdmf_sidecar_path(job.output),
                             palpate::xdmf_surface_sidecar_path(job.output)})
    for (const auto& stale : palpate::remove_stale_temporaries(target))
      log->warn("removed {}, left by an interrupted run (process {} is gone)", stale.path.string(),
                stale.pid);

  palpate::install_interrupt_cleanup();
  const auto report = palpate::run_precompute(job, hooks);
  if (json_out) std::cout << palpate::to_json(report, 2) << std::endl;
  if (!quiet) std::cerr << palpate::format_report(report);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  try {
    return run(argc, argv);
  } catch (...) {
    return palpate::report_current_exception("palpate-precompute");
  }
}
