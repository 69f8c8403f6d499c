#!/usr/bin/env bash
# Regenerates the feel's reference traces deliberately (docs/tools.md, "The
# feel under regression tests"): builds palpate-precompute and
# palpate_play_gesture if needed, makes the sample organ the test uses
# (tests/feel/make_organ.sh), plays every gesture of config/gestures/ into
# tests/feel/reference/<gesture>.csv, and plots old against new into a PNG
# per gesture in the folder it prints, with a line per gesture (max |ΔF|).
# Then review the plots and commit the traces with the change that made them.
#
#   scripts/regenerate-feel-traces.sh [BUILD_DIR]     (default: build)
#
# No DDS, no network; about 15 s after a build (a first build: minutes).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}

if [ ! -f "$build/CMakeCache.txt" ]; then
  echo "regenerate-feel-traces: configuring $build (Release)"
  cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
echo "regenerate-feel-traces: building palpate-precompute and palpate_play_gesture in $build"
if ! cmake --build "$build" -j2 --target palpate-precompute palpate_play_gesture \
  >"$build/regenerate-feel-traces-build.log" 2>&1; then
  tail -n 30 "$build/regenerate-feel-traces-build.log" >&2
  echo "regenerate-feel-traces: the build failed (log: $build/regenerate-feel-traces-build.log)" >&2
  exit 1
fi
player=$build/tests/feel/palpate_play_gesture
precompute=$build/precompute/palpate-precompute

organ_dir=$build/tests/feel/organ
tests/feel/make_organ.sh "$precompute" "$PWD" "$organ_dir"

out=out/feel-traces/$(date -u +%Y%m%dT%H%M%SZ)
mkdir -p "$out/old" "$out/new"
cp tests/feel/reference/*.csv "$out/old/" 2>/dev/null || true

for gesture in config/gestures/*.toml; do
  name=$(basename "$gesture" .toml)
  # Only the gestures for palpated's default tools (left, right): cut.toml's
  # cutting hook needs its served cut region (tests/daemon/cut_gesture_dds_test.cpp).
  if grep -E '^id = ' "$gesture" | grep -qvE '^id = "(left|right)"'; then
    echo "  $name: not for palpated's default tools; skipped"
    continue
  fi
  "$player" "$organ_dir/organ.h5" "$gesture" -o "$out/new/$name.csv" |
    sed 's/^/  /'
done
cp "$out"/new/*.csv tests/feel/reference/

echo "regenerate-feel-traces: old (tests/feel/reference/ before) against new, max |ΔF| per gesture:"
/usr/bin/python3 scripts/feel_trace_plots.py "$out/old" "$out/new" "$out"
echo "regenerate-feel-traces: plots in $out/ (<gesture>.png); traces written to tests/feel/reference/"
git status --short tests/feel/reference/ | sed 's/^/  /'
