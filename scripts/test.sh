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
# Each stage's wall time, printed as it ends ("suite: <stage> <s> s") and
# again at the end: where the suite's time goes (README, "How long the suite
# takes").
. scripts/suite_stages.sh
stage "install" scripts/install-deps.sh
stage "format check" scripts/format.sh --check
build=${PALPATE_BUILD_DIR:-build}
stage "release configure" cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release $PALPATE_LINK_FLAGS
stage "release build" cmake --build "$build" -j2
# Tests that start DDS participants (later issues) run inside a private
# network namespace whose only interface is loopback, so no DDS traffic can
# reach a real network: `unshare --net` then `ip link set lo up`.
stage "release tests" unshare --net -- sh -c 'ip link set lo up && exec ctest --test-dir "$0" --output-on-failure -j2 "$@"' "$build" "$@"
if [ "${PALPATE_SANITIZERS:-1}" != 0 ]; then
  PALPATE_SUITE_STAGES_PARENT=1 scripts/sanitize.sh all "$@"
fi
stages_summary
