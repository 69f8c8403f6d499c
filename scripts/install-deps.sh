#!/usr/bin/env bash
# Install palpate's build and run dependencies from Debian 12 packages.
#
# Idempotent: when every package is already installed it changes nothing and
# touches no network. Needs root (or sudo) only when something is missing.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config git
  # numerics: Eigen, CHOLMOD (SuiteSparse) on the optimized OpenBLAS
  libeigen3-dev libsuitesparse-dev libopenblas-dev libopenblas0-pthread
  # files and meshes
  libhdf5-dev libgmsh-dev
  # command line, configuration, logging, JSON
  libssl-dev libcli11-dev libtomlplusplus-dev libspdlog-dev libfmt-dev nlohmann-json3-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # independent reader used by the tests (Debian's python3, not a venv)
  python3 python3-h5py python3-numpy
  # DDS middleware and its tools (ddsperf), network namespaces
  cyclonedds-dev cyclonedds-tools iproute2 util-linux
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q '^install ok installed$'; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages already installed"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
