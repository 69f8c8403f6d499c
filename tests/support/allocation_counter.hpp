#pragma once
// The heap allocations made so far in the test binary that links
// allocation_counter.cpp, for tests that check an allocation-free path.

#include <atomic>
#include <cstdint>

namespace palpate::testing {
/// operator new, every thread.
extern std::atomic<std::uint64_t> g_allocations;
/// malloc, calloc and realloc (Eigen's temporaries among them), the calling
/// thread only (other threads, DDS's or a worker's, allocate as they
/// please). Counted where the test binary may replace malloc: not under
/// AddressSanitizer or ThreadSanitizer, whose run times own it (always 0
/// there).
std::uint64_t heap_allocations_on_this_thread();
/// operator new (every thread), what a path through Cyclone DDS (whose C
/// allocations are its own) must not change.
inline std::uint64_t allocations() { return g_allocations.load(std::memory_order_relaxed); }
/// Both counts: what an allocation-free path of palpate's own code, run on
/// this thread, must not change.
inline std::uint64_t allocations_here() {
  return allocations() + heap_allocations_on_this_thread();
}
}  // namespace palpate::testing
