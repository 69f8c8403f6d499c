#!/usr/bin/env bash
# palpate's demo on a fresh Debian 12 machine: installs what is missing,
# builds, generates the sample organ (or takes the job given), precomputes its
# surface compliance by both methods, then serves it with palpated while
# palpate-client presses, pinches and slides on it at 1 kHz, then
# palpate-pliers plays a press and a grasp with the tool topics.
#
# Usage: scripts/demo.sh                 the sample organ (config/sample-organ.toml)
#        scripts/demo.sh JOB.toml        any job file, e.g. config/openhelp-liver-h12.toml
# Outputs go to out/ (the daemon's log: out/palpated.log).
#
# DDS runs in a private network namespace whose only interface is loopback
# (unshare --net), and palpated's default configuration is loopback-only too.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j2 --target palpate-precompute palpated palpate-client palpate-pliers
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
compliance=$(/usr/bin/python3 -c '
import os, sys, tomllib
job = sys.argv[1]
with open(job, "rb") as f:
    out = tomllib.load(f)["output"]["file"]
print(os.path.normpath(os.path.join(os.path.dirname(job), out)))' "$job")
model=$(basename "$compliance" .h5)

echo
echo "demo: palpated serves $compliance as model '$model'; palpate-client palpates it (loopback only)"
unshare --net -- sh -c '
  ip link set lo up || exit 1
  build/server/palpated --model "$1=$2" 2>out/palpated.log &
  daemon=$!
  build/clients/palpate-client demo --model "$1"
  status=$?
  if [ $status -eq 0 ]; then
    echo
    echo "demo: palpate-pliers plays two gestures on the tool topics at 1 kHz (docs/pliers.md)"
    for gesture in press grasp-pull-release; do
      build/clients/palpate-pliers "config/gestures/$gesture.toml" --model "$1" || status=$?
    done
  fi
  kill -TERM $daemon
  wait $daemon || status=$?
  exit $status' demo "$model" "$compliance"
echo
echo "demo: compliance file and report in out/ (HDF5: docs/compliance-file.md); daemon log out/palpated.log"
