#!/usr/bin/env bash
# palpate's demo on a fresh Debian 12 machine: installs what is missing,
# builds, generates the sample organ (or takes the mesh given), precomputes
# its surface compliance by both methods, and prints the report.
#
# Usage: scripts/demo.sh                 the sample organ (config/sample-organ.toml)
#        scripts/demo.sh JOB.toml        any job file, e.g. config/openhelp-liver-h12.toml
# Outputs go to out/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j2 --target palpate-precompute
mkdir -p out
precompute=build/precompute/palpate-precompute
if [ $# -eq 0 ]; then
  # About 1,900 vertices: the scale of the 1999 INRIA liver (1,969).
  "$precompute" make-sample -o out/sample-organ.msh --size 0.008
  job=config/sample-organ.toml
else
  job=$1
fi
"$precompute" --job "$job"
echo
echo "demo: compliance file and report are in out/ (HDF5: docs/compliance-file.md)"
