#!/usr/bin/env bash
# Runs palpate's whole test suite from a clean checkout: installs the Debian
# packages it needs (scripts/install-deps.sh), checks that the C++ is as
# clang-format writes it (scripts/format.sh --check), configures, builds,
# and runs CTest; then the same suite under the sanitizers
# (scripts/sanitize.sh: ASan+UBSan on the whole suite, TSan on the
# concurrent tests; docs/sanitizers.md). PALPATE_SANITIZERS=0 skips them.
# Usage: scripts/test.sh [extra ctest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/format.sh --check
build=${PALPATE_BUILD_DIR:-build}
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release
cmake --build "$build" -j2
# Tests that start DDS participants (later issues) run inside a private
# network namespace whose only interface is loopback, so no DDS traffic can
# reach a real network: `unshare --net` then `ip link set lo up`.
unshare --net -- sh -c 'ip link set lo up && exec ctest --test-dir "$0" --output-on-failure -j2 "$@"' "$build" "$@"
if [ "${PALPATE_SANITIZERS:-1}" != 0 ]; then
  exec scripts/sanitize.sh all "$@"
fi
