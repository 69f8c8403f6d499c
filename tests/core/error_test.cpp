// One exit code per error class (core/error.hpp, docs/errors.md), and the
// one line a program prints.
#include "palpate/core/error.hpp"

#include <gtest/gtest.h>

#include <new>
#include <stdexcept>

namespace palpate {
namespace {

int code_of(auto&& raise) {
  try {
    raise();
  } catch (...) {
    return report_current_exception("error_test");
  }
  return -1;
}

TEST(Errors, EachClassHasItsExitCode) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(code_of([] { throw InputError("bad key"); }), 2);
  EXPECT_EQ(code_of([] { throw NumericalError("not positive definite"); }), 3);
  EXPECT_EQ(code_of([] { throw ResourceError("too big"); }), 4);
  EXPECT_EQ(code_of([] { throw SystemError("disk full"); }), 5);
  EXPECT_EQ(code_of([] { throw std::bad_alloc(); }), 4);
  EXPECT_EQ(code_of([] { throw std::logic_error("a bug"); }), 1);
  const std::string printed = testing::internal::GetCapturedStderr();
  EXPECT_NE(printed.find("error_test: error: bad key\n"), std::string::npos) << printed;
  EXPECT_NE(printed.find("error_test: error: disk full\n"), std::string::npos) << printed;
}

TEST(Errors, DemandNamesTheConditionAndWhere) {
  try {
    PALPATE_DEMAND(1 + 1 == 3);
    FAIL() << "no throw";
  } catch (const std::logic_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("internal error: 1 + 1 == 3"), std::string::npos) << message;
    EXPECT_NE(message.find("error_test.cpp:"), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace palpate
