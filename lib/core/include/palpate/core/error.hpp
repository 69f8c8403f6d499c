#pragma once
/// @file
/// Error types shared by the palpate library and its programs.
///
/// Every error a user can cause (a file, a configuration value, a request)
/// is an InputError whose message says what is wrong, where (file, line,
/// vertex or element index) and what would be accepted. Programs print the
/// message on one line and exit with the code of its class (docs/errors.md).

#include <stdexcept>
#include <string>

namespace palpate {

/// Bad user input: a file, a configuration key, a command-line value.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The input is well formed but the physics or the numerics fail on it
/// (stiffness not positive definite, methods that disagree).
class NumericalError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The job does not fit the machine (memory) or a limit the user set.
class ResourceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A failure of a system component (HDF5, CHOLMOD, the file system).
class SystemError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Process exit codes, one per error class (documented in docs/errors.md).
enum class ExitCode : int {
  kOk = 0,
  kInternal = 1,   ///< a bug: an invariant failed
  kUsage = 2,      ///< bad command line or configuration, bad input file
  kNumerical = 3,  ///< not positive definite, methods disagree
  kResource = 4,   ///< not enough memory or disk for the job
  kSystem = 5,     ///< I/O or library failure
  kInterrupted = 130,
};

/// Maps the exception being handled to its exit code after printing
/// "<program>: error: <message>" on stderr. Call it in a catch (...) block.
int report_current_exception(const char* program) noexcept;

/// Internal invariant: a violation is a bug in palpate, never a user error.
#define PALPATE_DEMAND(condition)                                                               \
  do {                                                                                          \
    if (!(condition))                                                                           \
      throw std::logic_error(std::string("internal error: ") + #condition + " at " + __FILE__ + \
                             ":" + std::to_string(__LINE__));                                   \
  } while (false)

}  // namespace palpate
