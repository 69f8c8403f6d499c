// Counts the C++ heap allocations of the test binary, so that tests can
// check that a path allocates nothing (allocation_counter.hpp).

#include "allocation_counter.hpp"

#include <cstdlib>
#include <new>

namespace palpate::testing {
std::atomic<std::uint64_t> g_allocations{0};
namespace {
// Per thread: the other threads of a test (DDS's, a worker's) allocate as
// they please. Static TLS of the executable: reading it never allocates.
thread_local std::uint64_t t_heap_allocations = 0;
}  // namespace
std::uint64_t heap_allocations_on_this_thread() { return t_heap_allocations; }
}  // namespace palpate::testing

// malloc, calloc and realloc counted, then glibc's own (its free() takes
// what they return). A sanitizer's run time replaces these itself: GCC
// says so by __SANITIZE_*__, Clang by __has_feature.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PALPATE_SANITIZER_OWNS_MALLOC 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
#define PALPATE_SANITIZER_OWNS_MALLOC 1
#endif
#endif
#ifndef PALPATE_SANITIZER_OWNS_MALLOC
#define PALPATE_COUNTS_MALLOC 1
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void* malloc(std::size_t size) {
  ++palpate::testing::t_heap_allocations;
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) {
  ++palpate::testing::t_heap_allocations;
  return __libc_calloc(count, size);
}
void* realloc(void* p, std::size_t size) {
  ++palpate::testing::t_heap_allocations;
  return __libc_realloc(p, size);
}
}
#endif

namespace {
// operator new's memory: counted once, by g_allocations.
void* uncounted_malloc(std::size_t size) {
#ifdef PALPATE_COUNTS_MALLOC
  return __libc_malloc(size);
#else
  return std::malloc(size);
#endif
}
}  // namespace

void* operator new(std::size_t size) {
  palpate::testing::g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = uncounted_malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) { return operator new(size); }
void* operator new(std::size_t size, std::align_val_t alignment) {
  palpate::testing::g_allocations.fetch_add(1, std::memory_order_relaxed);
  const auto a = static_cast<std::size_t>(alignment);
  if (void* p = std::aligned_alloc(a, (size + a - 1) / a * a)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size, std::align_val_t alignment) {
  return operator new(size, alignment);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
// The nothrow forms too: a sanitizer's run time replaces every form it is not
// given, so memory from its nothrow new would reach the free() above (and
// escape the count).
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return operator new(size);
  } catch (const std::bad_alloc&) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, const std::nothrow_t& tag) noexcept {
  return operator new(size, tag);
}
void* operator new(std::size_t size, std::align_val_t alignment, const std::nothrow_t&) noexcept {
  try {
    return operator new(size, alignment);
  } catch (const std::bad_alloc&) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, std::align_val_t alignment,
                     const std::nothrow_t& tag) noexcept {
  return operator new(size, alignment, tag);
}
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
