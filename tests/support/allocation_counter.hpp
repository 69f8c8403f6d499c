#pragma once
// The number of C++ heap allocations (operator new) made so far by the test
// binary that links allocation_counter.cpp.

#include <atomic>
#include <cstdint>

namespace palpate::testing {
extern std::atomic<std::uint64_t> g_allocations;
inline std::uint64_t allocations() { return g_allocations.load(std::memory_order_relaxed); }
}  // namespace palpate::testing
