#!/bin/sh
# The load test (issue 6; BENCHMARKS.md "Load: 8 tools and 4 viewers for 10
# minutes"): palpated serving 4 simulator stations, each with its own organ
# and two tools at 1 kHz (config/load-test.toml, config/gestures/demo.toml in
# a loop), 4 viewers reading every surface stream and the heartbeat, and 100
# reliable constraint requests per second; first, in the same run, station 1
# alone (the baseline of the ratios). palpate_load_generator
# (bench/load/load_generator.cpp) starts palpated and every client as
# separate processes, samples palpated's VmRSS, VmHWM and CPU time every
# second, and prints the round trips over the whole run, per tool and per
# minute, the requests, the viewers, palpated's memory and CPU, and its checks
# (no crash, no lost reply, every tool answered, every viewer fed, RSS flat).
#
# Usage: bench/load_test.sh [SECONDS] [BUILD_DIR] [MODEL.h5]   (as root)
#   SECONDS    the load phase, default 600; the baseline and the RSS warm-up
#              are 30 s each (a quarter of SECONDS when that is shorter)
#   BUILD_DIR  default build (palpated, and palpate_load_generator: built with
#              the tests or the benchmarks, in bench/load/)
#   MODEL.h5   default out/sample-organ.h5 (scripts/demo.sh writes it)
# PALPATE_LOAD_FLAGS adds flags to palpate_load_generator, e.g.
# --shared-organ (every station's tools on one model: 8 tools per solve).
# Output: the table on stdout; summary.json, table.txt, palpated.log and the
# raw per-tick data in $PALPATE_LOAD_OUT (default BUILD_DIR/load-test).
#
# Everything runs inside ONE private network namespace whose only interface
# is loopback (unshare --net; see bench/roundtrip_common.sh), and every DDS
# process uses palpate's loopback-only configuration: no DDS packet can reach
# a real network. Exit status: the generator's (0 every check passed, 1 a
# check failed, 3 palpated or a client did not come up).
set -eu

here=$(dirname "$(realpath "$0")")
. "$here/roundtrip_common.sh"
if [ "${PALPATE_BENCH_NETNS:-}" != 1 ]; then
  seconds=${1:-600}
  build=${2:-$here/../build}
  model=${3:-$here/../out/sample-organ.h5}
  [ -f "$model" ] || {
    echo "load_test: no compliance file $model (scripts/demo.sh writes out/sample-organ.h5)" >&2
    exit 1
  }
  enter_private_netns "$0" "$build" "$model" "$seconds"
fi
build=$1 model=$2 seconds=$3
require_loopback_only load_test

generator=""
for candidate in "$build/bench/load/palpate_load_generator"; do
  [ -x "$candidate" ] && generator=$candidate && break
done
[ -n "$generator" ] || { echo "load_test: palpate_load_generator is missing in $build (ninja -C $build palpate_load_generator)" >&2; exit 1; }
[ -x "$build/server/palpated" ] || { echo "load_test: $build/server/palpated is missing (build it)" >&2; exit 1; }

quarter=$(/usr/bin/python3 -c 'import sys; print(min(30.0, float(sys.argv[1]) / 4))' "$seconds")
out=${PALPATE_LOAD_OUT:-$build/load-test}
rm -rf "$out/work"
mkdir -p "$out"
echo "load_test: $(uptime)"
status=0
"$generator" --palpated "$build/server/palpated" --config "$here/../config/load-test.toml" \
  --model-file "$model" --gesture "$here/../config/gestures/demo.toml" \
  --stations 4 --viewers 4 --request-hz 100 --seconds "$seconds" --baseline "$quarter" \
  --warmup "$quarter" --rss-tolerance-mb 8 --work "$out/work" --json "$out/summary.json" \
  ${PALPATE_LOAD_FLAGS:-} >"$out/table.txt" || status=$?
cat "$out/table.txt"
cp "$out/work/palpated.log" "$out/palpated.log"
echo "load_test: $(uptime)"
echo "load_test: summary in $out/summary.json"
exit $status
