// The compliance-file loader on raw bytes: load_surface_model on whatever
// the input is, written to a file (HDF5 opens files by name). Exercises
// Debian's libhdf5 (not instrumented: its crashes show up, its branches do
// not guide the fuzzer) and palpate's checks behind it; fuzz_compliance_struct
// reaches those more directly. A loaded model must be servable.

#include <cstdint>
#include <span>

#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = palpate::fuzz::write_scratch_file("model.h5", {data, size});
  palpate::SurfaceModel model;
  if (!palpate::fuzz::accepted([&] { model = palpate::load_surface_model("fuzz", file); }))
    return 0;
  palpate::fuzz::serve(model);
  return 0;
}
