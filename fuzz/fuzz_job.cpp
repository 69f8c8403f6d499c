// The precompute job file: read_job_file on fuzzed TOML, then to_toml (the
// job palpate-precompute stores in every compliance file, "enough to run it
// again") read back: it must give the same job.

#include <cmath>
#include <cstdint>
#include <string>

#include "fuzz_support.hpp"
#include "palpate/offline/precompute.hpp"

namespace {

// Equal, or both NaN, or within a few roundings (lengths in mm or cm are
// scaled to metres and back).
bool same(double a, double b) {
  if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b);
  if (a == b) return true;
  return std::abs(a - b) <= 1e-14 * std::max(std::abs(a), std::abs(b)) + 1e-300;
}
bool same(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return same(a.x(), b.x()) && same(a.y(), b.y()) && same(a.z(), b.z());
}
bool same(const std::optional<double>& a, const std::optional<double>& b) {
  return a.has_value() == b.has_value() && (!a || same(*a, *b));
}

void check_same(const palpate::PrecomputeJob& a, const palpate::PrecomputeJob& b) {
  PALPATE_FUZZ_CHECK(a.mesh_file == b.mesh_file);
  PALPATE_FUZZ_CHECK(a.mesh_unit == b.mesh_unit);
  // Written only when > 0, like the memory limit below.
  PALPATE_FUZZ_CHECK(same(a.fill_size, b.fill_size) || (!(a.fill_size > 0) && b.fill_size == 0));
  PALPATE_FUZZ_CHECK(same(a.young_modulus_pa, b.young_modulus_pa));
  PALPATE_FUZZ_CHECK(same(a.poisson_ratio, b.poisson_ratio));
  PALPATE_FUZZ_CHECK(a.group_materials.size() == b.group_materials.size());
  for (std::size_t i = 0; i < a.group_materials.size(); ++i) {
    PALPATE_FUZZ_CHECK(a.group_materials[i].group == b.group_materials[i].group);
    PALPATE_FUZZ_CHECK(
        same(a.group_materials[i].young_modulus_pa, b.group_materials[i].young_modulus_pa));
    PALPATE_FUZZ_CHECK(
        same(a.group_materials[i].poisson_ratio, b.group_materials[i].poisson_ratio));
  }
  const auto &x = a.attachment, &y = b.attachment;
  PALPATE_FUZZ_CHECK(x.groups == y.groups);
  PALPATE_FUZZ_CHECK(x.ids_file == y.ids_file);
  PALPATE_FUZZ_CHECK(x.boxes.size() == y.boxes.size());
  for (std::size_t i = 0; i < x.boxes.size(); ++i)
    PALPATE_FUZZ_CHECK(same(x.boxes[i].min, y.boxes[i].min) &&
                       same(x.boxes[i].max, y.boxes[i].max));
  PALPATE_FUZZ_CHECK(x.spheres.size() == y.spheres.size());
  for (std::size_t i = 0; i < x.spheres.size(); ++i)
    PALPATE_FUZZ_CHECK(same(x.spheres[i].center, y.spheres[i].center) &&
                       same(x.spheres[i].radius, y.spheres[i].radius));
  PALPATE_FUZZ_CHECK(x.half_spaces.size() == y.half_spaces.size());
  for (std::size_t i = 0; i < x.half_spaces.size(); ++i)
    PALPATE_FUZZ_CHECK(same(x.half_spaces[i].point, y.half_spaces[i].point) &&
                       same(x.half_spaces[i].normal, y.half_spaces[i].normal));
  PALPATE_FUZZ_CHECK(a.method == b.method);
  PALPATE_FUZZ_CHECK(a.precision == b.precision);
  PALPATE_FUZZ_CHECK(a.block_columns == b.block_columns);
  PALPATE_FUZZ_CHECK(same(a.tolerance, b.tolerance));
  // Written only when > 0 (0: the machine's memory; below or NaN, refused at run time).
  PALPATE_FUZZ_CHECK(same(a.memory_limit_bytes, b.memory_limit_bytes) ||
                     (!(a.memory_limit_bytes > 0) && b.memory_limit_bytes == 0));
  PALPATE_FUZZ_CHECK(a.output == b.output);
  PALPATE_FUZZ_CHECK(a.write_xdmf == b.write_xdmf);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = palpate::fuzz::write_scratch_file("job.toml", {data, size});
  palpate::PrecomputeJob job;
  if (!palpate::fuzz::accepted([&] { job = palpate::read_job_file(file); })) return 0;
  std::string text;
  PALPATE_FUZZ_CHECK(palpate::fuzz::accepted([&] { text = palpate::to_toml(job); }));
  const auto again = palpate::fuzz::write_scratch_file(
      "job-again.toml", {reinterpret_cast<const std::uint8_t*>(text.data()), text.size()});
  palpate::PrecomputeJob reread;
  if (!palpate::fuzz::accepted([&] { reread = palpate::read_job_file(again); }))
    palpate::fuzz::fail("to_toml wrote a job read_job_file refuses:\n" + text);
  check_same(job, reread);
  return 0;
}
