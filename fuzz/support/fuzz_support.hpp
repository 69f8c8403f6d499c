#pragma once
// What every palpate fuzz target shares: a per-process scratch directory,
// the small real compliance model the request, pose and gesture targets run
// on, and the rule for which outcomes are acceptable (docs/fuzzing.md).

#include <cstddef>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

#include "palpate/core/error.hpp"
#include "palpate/runtime/surface_model.hpp"

namespace palpate::fuzz {

/// A directory private to this process (removed at normal exit): inputs that
/// the code under test only takes as files are written there.
const std::filesystem::path& scratch_dir();

/// Writes @p bytes to `scratch_dir() / name` (replacing it); returns the path.
std::filesystem::path write_scratch_file(const std::string& name,
                                         std::span<const std::uint8_t> bytes);

/// The compliance file of a 100 × 50 × 40 mm box (2 × 2 × 2 cubes, clamped
/// on x = 0), made once per process by the real pipeline (run_precompute on
/// a Gmsh 2.2 mesh), and the model loaded from it.
const std::filesystem::path& box_compliance_file();
const SurfaceModel& box_model();

/// What palpated does with a model it loaded, with its invariants checked:
/// the drawing tables are consistent, one request (1 mm on the first
/// compliance vertex) and one tool pose on it solve or fail with a status,
/// and give finite results.
void serve(const SurfaceModel& model);

/// Prints @p what and aborts: libFuzzer records the input as a crash.
[[noreturn]] void fail(std::string_view what);

#define PALPATE_FUZZ_CHECK(condition)                                         \
  do {                                                                        \
    if (!(condition)) ::palpate::fuzz::fail("invariant failed: " #condition); \
  } while (false)

/// Runs @p f and returns true when it returns. An InputError (bad input, the
/// documented outcome of every parser and loader) returns false; any other
/// exception is a finding: it aborts with its type and message.
template <typename F>
bool accepted(F&& f) {
  try {
    f();
    return true;
  } catch (const InputError&) {
    return false;
  } catch (const std::exception& e) {
    fail(std::string("undocumented exception (") + typeid(e).name() + "): " + e.what());
  } catch (...) {
    fail("undocumented exception of a non-std type");
  }
}

}  // namespace palpate::fuzz
