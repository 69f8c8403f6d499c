# PALPATE_SANITIZE (e.g. address,undefined or thread): compile and link every
# target with those sanitizers. PALPATE_FUZZ: instrument every target for
# libFuzzer's coverage (clang only); the fuzz targets themselves link
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
  add_compile_options(-fsanitize=fuzzer-no-link)
endif()
