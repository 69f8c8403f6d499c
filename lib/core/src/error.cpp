#include "palpate/core/error.hpp"

#include <cstdio>
#include <exception>
#include <new>

namespace palpate {

int report_current_exception(const char* program) noexcept {
  auto print = [program](const char* message, const char* suffix = "") {
    std::fprintf(stderr, "%s: error: %s%s\n", program, message, suffix);
  };
  try {
    throw;
  } catch (const InputError& e) {
    print(e.what());
    return static_cast<int>(ExitCode::kUsage);
  } catch (const NumericalError& e) {
    print(e.what());
    return static_cast<int>(ExitCode::kNumerical);
  } catch (const ResourceError& e) {
    print(e.what());
    return static_cast<int>(ExitCode::kResource);
  } catch (const SystemError& e) {
    print(e.what());
    return static_cast<int>(ExitCode::kSystem);
  } catch (const std::bad_alloc&) {
    print("out of memory");
    return static_cast<int>(ExitCode::kResource);
  } catch (const std::exception& e) {
    print(e.what(), " (a bug in palpate: please report it)");
    return static_cast<int>(ExitCode::kInternal);
  } catch (...) {
    print("unknown exception", " (a bug in palpate: please report it)");
    return static_cast<int>(ExitCode::kInternal);
  }
}

}  // namespace palpate
