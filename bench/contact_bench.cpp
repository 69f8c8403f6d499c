#include <benchmark/benchmark.h>
// placeholder: being written
BENCHMARK_MAIN();
