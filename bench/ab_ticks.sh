#!/bin/sh
# Two builds of palpate, same run, alternating: the in-process request
# solves (palpate_solve_bench) and the tool ticks (palpate_contact_bench) on
# one compliance file, ROUNDS times each, then the medians and their ratio
# (bench/ab_summary.py). For a change that should not move the speed, such
# as a restructuring (BENCHMARKS.md, "The layers").
# Usage: bench/ab_ticks.sh BEFORE_BUILD AFTER_BUILD MODEL.h5 [ROUNDS] [OUT_DIR]
set -eu
before=$1 after=$2 model=$3 rounds=${4:-5} out=${5:-out/bench/ab-ticks}
mkdir -p "$out"
rm -f "$out"/*.json
uptime >"$out/load-before.txt"
r=1
while [ "$r" -le "$rounds" ]; do
  for v in before after; do
    b=$([ "$v" = before ] && echo "$before" || echo "$after")
    "$b/bench/palpate_solve_bench" "$model" --benchmark_min_time=0.5s --benchmark_format=json \
      >"$out/solve-$v-$r.json" 2>/dev/null
    "$b/bench/palpate_contact_bench" "$model" --benchmark_format=json >"$out/contact-$v-$r.json" 2>/dev/null
  done
  r=$((r + 1))
done
uptime >"$out/load-after.txt"
exec /usr/bin/python3 "$(dirname "$0")/ab_summary.py" "$out"
