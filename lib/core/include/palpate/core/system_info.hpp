#pragma once
/// @file
/// Facts about the running process and machine, for reports and limits.

#include <string>

namespace palpate {

/// Peak resident memory (bytes) since start or since the last reset_peak_rss().
double peak_rss_bytes();
/// Resets the kernel's peak-RSS mark (Linux: /proc/self/clear_refs), so that
/// peak_rss_bytes() measures one phase. Returns false if not supported.
bool reset_peak_rss();
/// Current resident memory (bytes).
double current_rss_bytes();
/// Memory the kernel says is available for a new allocation (MemAvailable).
double available_memory_bytes();
/// The BLAS library actually loaded in this process (resolved path), with
/// OpenBLAS's own configuration and thread count when it is OpenBLAS.
std::string blas_description();
/// Debian 12's OpenBLAS 0.3.21 does not know recent CPU models and then runs
/// its generic "Prescott" kernels, several times slower than the AVX2 or
/// AVX-512 ones the CPU supports. If that happened and the user has not set
/// OPENBLAS_CORETYPE, re-executes the program (/proc/self/exe, same argv)
/// with OPENBLAS_CORETYPE naming the best core the CPU supports. Call first
/// in main(); returns when no re-execution is needed (or possible).
void ensure_optimized_blas(char** argv);
/// Sets OpenBLAS's thread count (no effect with another BLAS). palpated runs
/// LAPACK only on the small systems of requests and tool ticks, where
/// OpenBLAS's worker threads cost more than they give (a 64-point solve
/// takes ~20 µs longer with them, docs/benchmarks-history.md "Contact with the surface")
/// and spin on the cores the haptic loop needs: it sets 1.
void set_blas_threads(int count);

/// "2026-11-21T18:00:00Z".
std::string utc_timestamp();
/// Bytes as "1.23 GB" (powers of 1000).
std::string format_bytes(double bytes);

}  // namespace palpate
