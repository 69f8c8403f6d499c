# palpate::warnings: the warning set every palpate target links privately.
add_library(palpate_warnings INTERFACE)
add_library(palpate::warnings ALIAS palpate_warnings)
target_compile_options(palpate_warnings INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
    -Wold-style-cast -Wcast-align -Woverloaded-virtual>)
