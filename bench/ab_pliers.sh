#!/bin/sh
# Two builds of palpate, same run, alternating: palpated and palpate-pliers
# of each build play config/gestures/steady-press.toml (the left tool in
# contact, 10 s, the first second left out) ROUNDS times; then the medians
# over the rounds of each run's round-trip p50, p99 and p99.9, palpated's
# compute p50, and their ratio. For a change to the tool loop's path that
# should not move its speed (BENCHMARKS.md, "The first hour").
#
# Usage: bench/ab_pliers.sh BEFORE_BUILD AFTER_BUILD MODEL.h5 [ROUNDS] [OUT_DIR]   (as root)
#
# Everything runs in ONE private network namespace whose only interface is
# loopback, and each palpated uses its built-in loopback configuration.
set -eu
. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
if [ "${PALPATE_BENCH_NETNS:-}" != 1 ]; then
  [ $# -ge 3 ] || { echo "usage: $0 BEFORE_BUILD AFTER_BUILD MODEL.h5 [ROUNDS] [OUT_DIR]" >&2; exit 2; }
  before=$(realpath "$1") after=$(realpath "$2") model=$(realpath "$3")
  shift 3
  exec unshare --net -- env PALPATE_BENCH_NETNS=1 sh "$(realpath "$0")" "$before" "$after" "$model" "$@"
fi
before=$1 after=$2 model=$3 rounds=${4:-3} out=${5:-out/bench/ab-pliers}
require_loopback_only ab_pliers
gesture=$(dirname "$(realpath "$0")")/../config/gestures/steady-press.toml
mkdir -p "$out"
rm -f "$out"/*.json
uptime >"$out/load-before.txt"
r=1
while [ "$r" -le "$rounds" ]; do
  for v in before after; do
    b=$([ "$v" = before ] && echo "$before" || echo "$after")
    "$b/server/palpated" --model "organ=$model" --log-level warn 2>"$out/palpated-$v-$r.log" &
    daemon=$!
    "$b/clients/palpate-pliers" "$gesture" --model organ --tool left --warmup 1 -q \
      --json "$out/pliers-$v-$r.json" >/dev/null
    kill -TERM "$daemon"
    wait "$daemon"
  done
  r=$((r + 1))
done
uptime >"$out/load-after.txt"
exec /usr/bin/python3 - "$out" "$rounds" <<'EOF'
import json, statistics, sys
out, rounds = sys.argv[1], int(sys.argv[2])
def figures(v):
    rows = []
    for r in range(1, rounds + 1):
        with open(f"{out}/pliers-{v}-{r}.json") as f:
            t = json.load(f)["tools"][0]
        rows.append((t["round_trip"]["p50_us"], t["round_trip"]["p99_us"],
                     t["round_trip"]["p999_us"], t["compute"]["p50_us"], t["within_budget_share"]))
    return [statistics.median(c) for c in zip(*rows)]
b, a = figures("before"), figures("after")
names = ["round trip p50 µs", "round trip p99 µs", "round trip p99.9 µs",
         "palpated's compute p50 µs", "within 1 ms"]
print(f"{'':28} {'before':>9} {'after':>9} {'after/before':>13}   (medians of {rounds} rounds)")
for n, x, y in zip(names, b, a):
    print(f"{n:28} {x:9.3g} {y:9.3g} {y / x if x else float('nan'):13.2f}")
EOF
