# PALPATE_SANITIZE (e.g. address,undefined or thread): compile and link every
# target with those sanitizers. PALPATE_FUZZ: instrument for libFuzzer's
# coverage what the fuzz targets exercise (the libraries and fuzz/, through
# palpate_fuzz_coverage(); clang only); the fuzz targets themselves link
# -fsanitize=fuzzer (fuzz/CMakeLists.txt). scripts/sanitize.sh configures both.
if(PALPATE_SANITIZE)
  add_compile_options(-fsanitize=${PALPATE_SANITIZE} -fno-omit-frame-pointer
                      -fno-sanitize-recover=all)
  add_link_options(-fsanitize=${PALPATE_SANITIZE})
endif()
if(PALPATE_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR
      "PALPATE_FUZZ needs clang's libFuzzer: configure with CC=clang CXX=clang++ "
      "(Debian packages clang and libclang-rt-14-dev)")
  endif()
endif()
# Coverage instrumentation for libFuzzer on TARGET, when PALPATE_FUZZ is on.
# Only code a fuzz target runs needs it; instrumenting the tests, the clients
# and the viewer as well made the sanitizer build slower for nothing. Nor
# does Eigen's and the standard library's template code, which is most of
# what the instrumented tests run (fuzz_coverage_ignore.txt says why).
set(PALPATE_FUZZ_COVERAGE_FLAGS -fsanitize=fuzzer-no-link
    -fsanitize-coverage-ignorelist=${CMAKE_CURRENT_LIST_DIR}/fuzz_coverage_ignore.txt)
function(palpate_fuzz_coverage target)
  if(PALPATE_FUZZ)
    target_compile_options(${target} PRIVATE ${PALPATE_FUZZ_COVERAGE_FLAGS})
  endif()
endfunction()

# Front-ends whose code is argument parsing, printing and (the viewer)
# Boost.Beast templates are compiled at -O0 in sanitizer builds: their
# compile time was a quarter of the ASan build (palpate_viewer.cpp alone
# 100 s at -O1, 25 s at -O0) and their run time in the tests is negligible.
# The sanitizers check them just the same.
function(palpate_sanitizer_front_end)
  if(PALPATE_SANITIZE)
    set_source_files_properties(${ARGN} DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}
                                PROPERTIES COMPILE_OPTIONS -O0)
  endif()
endfunction()

# The test programs' own code (tests/, tests/support/) is compiled at -O0 in
# sanitizer builds, still instrumented: the library they drive keeps -O1 and
# its run time, while their GoogleTest and Eigen templates compile 2.5 times
# faster (a unity batch of the offline tests: 108 s at -O1, 43 s at -O0; the
# test programs of the ASan build 842 CPU-s, then 344; docs/sanitizers.md).
# A test whose own loops are its time writes them in plain scalars, as
# ContactGeometry's brute force does: Eigen's expressions unoptimized cost
# tens of calls an operation. (Compiling such a file alone at -O1 does not
# help: the linker keeps one copy of each inline Eigen function, often an
# -O0 one.) Call it in the directory whose targets it is for.
macro(palpate_sanitizer_test_code)
  if(PALPATE_SANITIZE)
    add_compile_options(-O0)
  endif()
endmacro()
