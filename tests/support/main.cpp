// Test main: the same BLAS set-up as palpate's programs, then GoogleTest.
#include <gtest/gtest.h>

#include "palpate/core/system_info.hpp"

int main(int argc, char** argv) {
  palpate::ensure_optimized_blas(argv);
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
