# The installed CMake package and pkg-config file (docs/architecture.md,
# "Using palpate from another build"):
#
#   find_package(palpate CONFIG REQUIRED)
#   target_link_libraries(app PRIVATE palpate::palpate)   # or palpate::transport, ...
#
#   pkg-config --cflags --libs palpate
#   pkg-config --cflags --libs palpate-device   # the C API alone (palpate/device.h)
include(CMakePackageConfigHelpers)
set(palpate_cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/palpate)
install(EXPORT palpateTargets NAMESPACE palpate:: DESTINATION ${palpate_cmake_dir})
configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/palpateConfig.cmake.in
  ${CMAKE_CURRENT_BINARY_DIR}/palpateConfig.cmake INSTALL_DESTINATION ${palpate_cmake_dir})
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/palpateConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/palpateConfig.cmake
              ${CMAKE_CURRENT_BINARY_DIR}/palpateConfigVersion.cmake
        DESTINATION ${palpate_cmake_dir})

# pkg-config: every layer, for builds without CMake.
# Relocatable: the prefix is found from where the file is installed.
file(RELATIVE_PATH palpate_pc_to_prefix ${CMAKE_INSTALL_FULL_LIBDIR}/pkgconfig ${CMAKE_INSTALL_PREFIX})
string(REGEX REPLACE "/$" "" palpate_pc_to_prefix "${palpate_pc_to_prefix}")
configure_file(${CMAKE_CURRENT_LIST_DIR}/palpate.pc.in ${CMAKE_CURRENT_BINARY_DIR}/palpate.pc @ONLY)
# The C API alone: a C program needs its header and library only.
configure_file(${CMAKE_CURRENT_LIST_DIR}/palpate-device.pc.in
               ${CMAKE_CURRENT_BINARY_DIR}/palpate-device.pc @ONLY)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/palpate.pc ${CMAKE_CURRENT_BINARY_DIR}/palpate-device.pc
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
