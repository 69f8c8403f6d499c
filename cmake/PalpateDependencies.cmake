# Every dependency comes from a Debian 12 package (scripts/install-deps.sh).
# Nothing is downloaded at configure time.
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(BLAS REQUIRED)
find_package(LAPACK REQUIRED)
find_package(HDF5 REQUIRED COMPONENTS C)
find_package(OpenSSL REQUIRED COMPONENTS Crypto)
find_package(tomlplusplus REQUIRED)
find_package(spdlog REQUIRED)
find_package(fmt REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(CLI11 CONFIG QUIET)
find_package(Threads REQUIRED)
find_package(CycloneDDS 0.10 REQUIRED)

# CHOLMOD (SuiteSparse 5.x ships no CMake package): an imported target.
find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse REQUIRED)
find_library(CHOLMOD_LIBRARY cholmod REQUIRED)
find_library(SUITESPARSECONFIG_LIBRARY suitesparseconfig REQUIRED)
add_library(palpate_cholmod INTERFACE IMPORTED)
target_include_directories(palpate_cholmod SYSTEM INTERFACE ${CHOLMOD_INCLUDE_DIR})
target_link_libraries(palpate_cholmod INTERFACE ${CHOLMOD_LIBRARY} ${SUITESPARSECONFIG_LIBRARY}
  LAPACK::LAPACK BLAS::BLAS)
add_library(SuiteSparse::CHOLMOD ALIAS palpate_cholmod)

# LAPACKE and CBLAS, the C interfaces to LAPACK and BLAS (liblapacke-dev;
# cblas.h from libopenblas-dev, /usr/include/<arch>/cblas.h, a Debian
# alternative): their prototypes pass the hidden string lengths a
# gfortran-built LAPACK takes, which prototypes declared by hand would omit.
# The BLAS and LAPACK beneath stay BLAS::BLAS and LAPACK::LAPACK (OpenBLAS).
find_path(LAPACKE_INCLUDE_DIR lapacke.h REQUIRED)
find_library(LAPACKE_LIBRARY lapacke REQUIRED)
find_path(CBLAS_INCLUDE_DIR cblas.h REQUIRED)
add_library(palpate_lapacke INTERFACE IMPORTED)
target_include_directories(palpate_lapacke SYSTEM INTERFACE ${LAPACKE_INCLUDE_DIR}
  ${CBLAS_INCLUDE_DIR})
target_link_libraries(palpate_lapacke INTERFACE ${LAPACKE_LIBRARY} LAPACK::LAPACK BLAS::BLAS)
add_library(palpate::lapacke ALIAS palpate_lapacke)

# Gmsh SDK (libgmsh-dev ships no CMake package).
find_path(GMSH_INCLUDE_DIR gmsh.h REQUIRED)
find_library(GMSH_LIBRARY gmsh REQUIRED)
add_library(palpate_gmsh INTERFACE IMPORTED)
target_include_directories(palpate_gmsh SYSTEM INTERFACE ${GMSH_INCLUDE_DIR})
target_link_libraries(palpate_gmsh INTERFACE ${GMSH_LIBRARY})
add_library(Gmsh::Gmsh ALIAS palpate_gmsh)

# CLI11 2.1 in Debian is header-only and may lack a CMake config.
if(NOT TARGET CLI11::CLI11)
  find_path(CLI11_INCLUDE_DIR CLI/CLI.hpp REQUIRED)
  add_library(palpate_cli11 INTERFACE IMPORTED)
  target_include_directories(palpate_cli11 SYSTEM INTERFACE ${CLI11_INCLUDE_DIR})
  add_library(CLI11::CLI11 ALIAS palpate_cli11)
endif()
