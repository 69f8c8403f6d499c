# Unity builds (README, "How long the suite takes"): a target's sources
# compiled a batch at a time, each batch one translation unit that includes
# its files one after the other. What a file costs the compiler is mostly
# the templates it instantiates (Eigen's expressions and decompositions,
# GoogleTest's assertions), and files of one target instantiate the same
# ones: compiled together they are instantiated once a batch, not once a
# file (six contact test files: 55 s one by one, 30 s as one unit).
#
#   palpate_unity_build(<target> [BATCH <n>])   n files a unit (default 8)
#
# Files of a batch share one scope, so a helper's name in an unnamed
# namespace must be unique within its target (the compiler says so when it
# is not). PALPATE_UNITY_BUILD=OFF compiles each file alone, as an editing
# build wants (a change recompiles one file, not its batch).
option(PALPATE_UNITY_BUILD "Compile each library and test program in batches of files" ON)

function(palpate_unity_build target)
  cmake_parse_arguments(ARG "" "BATCH" "" ${ARGN})
  if(NOT ARG_BATCH)
    set(ARG_BATCH 8)
  endif()
  if(PALPATE_UNITY_BUILD)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_MODE BATCH
                                               UNITY_BUILD_BATCH_SIZE ${ARG_BATCH})
  endif()
endfunction()
