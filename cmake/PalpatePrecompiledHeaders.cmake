# Precompiled headers (README, "How long the suite takes"): the standard,
# Eigen and fmt headers nearly every unit includes are parsed once per
# target instead of once per file (Eigen/Dense alone takes a compiler ~5 s).
#
#   palpate_precompile_library(<target>)       a library layer: its own PCH
#   palpate_precompile_test_support(<target>)  the tests' PCH, on palpate_test_support
#   palpate_precompile_test(<target>)          a test or benchmark program: that PCH, reused
#
# PALPATE_PRECOMPILE_HEADERS=OFF builds without them: each file includes what
# it names, as it must anyway (a PCH is never a substitute for an include).
option(PALPATE_PRECOMPILE_HEADERS "Precompile the common headers of each target" ON)

set(palpate_pch_common
  <algorithm> <array> <chrono> <cmath> <cstdint> <cstring> <filesystem> <functional> <limits>
  <memory> <optional> <span> <string> <string_view> <utility> <vector>
  <Eigen/Dense> <Eigen/Geometry>)

# fmt's headers depend on FMT_SHARED, which fmt::fmt's users get: fmt is
# precompiled only for a layer that links it.
# Call it after the target's target_link_libraries.
function(palpate_precompile_library target)
  if(PALPATE_PRECOMPILE_HEADERS)
    set(headers ${palpate_pch_common})
    get_target_property(links ${target} LINK_LIBRARIES)
    if("fmt::fmt" IN_LIST links)
      list(APPEND headers <fmt/format.h>)
    endif()
    target_precompile_headers(${target} PRIVATE ${headers})
  endif()
endfunction()

# One PCH for every test program: GoogleTest and the headers the tests use
# most, no fmt (the programs differ in FMT_SHARED; nothing else in it
# depends on a definition they differ in).
function(palpate_precompile_test_support target)
  if(PALPATE_PRECOMPILE_HEADERS)
    target_precompile_headers(${target} PRIVATE ${palpate_pch_common}
      <fstream> <random> <thread> <gtest/gtest.h>)
  endif()
endfunction()

function(palpate_precompile_test target)
  if(PALPATE_PRECOMPILE_HEADERS AND TARGET palpate_test_support)
    target_precompile_headers(${target} REUSE_FROM palpate_test_support)
  endif()
endfunction()
