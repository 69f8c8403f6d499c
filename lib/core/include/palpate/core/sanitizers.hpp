#pragma once
/// @file
/// PALPATE_SHADOW_MEMORY is defined when this translation unit is built
/// under AddressSanitizer or ThreadSanitizer (GCC's __SANITIZE_*__ macros,
/// clang's __has_feature): their terabytes of reserved shadow memory are
/// why locking the process's memory is refused there (docs/realtime.md,
/// docs/sanitizers.md), and why the tests expect that refusal.

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PALPATE_SHADOW_MEMORY 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define PALPATE_SHADOW_MEMORY 1
#endif
#endif
