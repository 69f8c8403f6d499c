#pragma once
// Expects `f` to throw `Error` with a one-line message holding every fragment.

#include <gtest/gtest.h>

#include <initializer_list>
#include <string>

namespace palpate::testing {

template <typename Error, typename F>
void expect_error(F f, std::initializer_list<std::string> fragments) {
  try {
    f();
    ADD_FAILURE() << "no error thrown";
  } catch (const Error& e) {
    const std::string msg = e.what();
    for (const auto& frag : fragments)
      EXPECT_NE(msg.find(frag), std::string::npos) << msg << "\n  lacks: " << frag;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "one line: " << msg;
  }
}

}  // namespace palpate::testing
