#!/usr/bin/env bash
# Install palpate's build and run dependencies from Debian 12 packages, and
# the viewer's two JavaScript packages from the npm registry (npm ci, pinned
# by viewer/package-lock.json).
#
# Idempotent: when everything is already there it changes nothing and
# touches no network. Needs root (or sudo) only when a package is missing.
set -euo pipefail

packages=(
  # toolchain; clang-format 14 checks the code's layout (scripts/format.sh)
  build-essential cmake ninja-build pkg-config git clang-format
  # clang 14 and its run-time libraries: the sanitizer builds and libFuzzer
  # (scripts/sanitize.sh, docs/sanitizers.md, docs/fuzzing.md)
  clang libclang-rt-14-dev
  # the suite's linker (scripts/suite_stages.sh)
  lld
  # numerics: Eigen, CHOLMOD (SuiteSparse) on the optimized OpenBLAS, and
  # LAPACKE, the C interface to LAPACK (OpenBLAS's cblas.h is BLAS's)
  libeigen3-dev libsuitesparse-dev libopenblas-dev libopenblas0-pthread liblapacke-dev
  # files and meshes
  libhdf5-dev libgmsh-dev
  # command line, configuration, logging, JSON
  libssl-dev libcli11-dev libtomlplusplus-dev libspdlog-dev libfmt-dev nlohmann-json3-dev
  # tests and benchmarks; stress-ng loads the cores for the real-time
  # round trips (bench/realtime_roundtrip.sh, docs/realtime.md)
  libgtest-dev libgmock-dev libbenchmark-dev stress-ng
  # independent reader used by the tests (Debian's python3, not a venv)
  python3 python3-h5py python3-numpy
  # the independent contact check (tests/runtime/contact_reference): sparse LU, NNLS
  python3-scipy
  # DDS middleware and its tools (ddsperf), network namespaces
  cyclonedds-dev cyclonedds-tools iproute2 util-linux
  # DDS Security: Cyclone's plugins (libddsc0debian, with cyclonedds-dev) and
  # the openssl program scripts/dds-security.sh makes certificates with
  libddsc0debian openssl
  # the browser viewer: Boost.Beast (HTTP/WebSocket bridge), Node.js and npm
  # for three.js, Chromium for its end-to-end test and the demo's screenshots
  libboost-dev nodejs chromium
  # session plots (matplotlib), the XDMF sidecar's independent reader
  # (meshio), the gmsh program (the STL tutorial and its test)
  python3-matplotlib python3-meshio gmsh
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q '^install ok installed$'; then
    missing+=("$p")
  fi
done

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages already installed"
else
  echo "install-deps: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
# Debian's nodejs comes without npm (a package of its own); some builds of
# nodejs include it.
if ! command -v npm >/dev/null; then
  echo "install-deps: installing npm"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends npm
fi

# The viewer's JavaScript packages (three.js; playwright-core for its test),
# at the versions of viewer/package-lock.json, from the npm registry. Skipped
# when node_modules already matches the lock file.
viewer=$(cd "$(dirname "$0")/../viewer" && pwd)
stamp="$viewer/node_modules/.palpate-package-lock.json"
if ! cmp -s "$viewer/package-lock.json" "$stamp"; then
  echo "install-deps: npm ci in $viewer"
  (cd "$viewer" && npm ci --no-audit --no-fund --loglevel=error)
  cp "$viewer/package-lock.json" "$stamp"
else
  echo "install-deps: viewer/node_modules matches package-lock.json"
fi
