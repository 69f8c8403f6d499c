#!/bin/sh
# The first ticks of a recorded session, two builds alternating: palpated
# --record serving the sample organ, palpate-pliers playing
# config/gestures/press.toml with --csv; per run, the largest round trip of
# the first 20 ticks and how many of them were late or missing, then the
# whole run's p99 and max. Runs itself in a private network namespace.
# Usage: bench/recording_first_ticks.sh BEFORE_BUILD AFTER_BUILD [RUNS] [OUT_DIR]
set -eu
if [ "${PALPATE_BENCH_NETNS:-}" != 1 ]; then
  exec unshare --net -- env PALPATE_BENCH_NETNS=1 sh -c 'ip link set lo up && exec "$0" "$@"' \
    "$(realpath "$0")" "$(realpath "$1")" "$(realpath "$2")" "${3:-6}" "$(realpath -m "${4:-out/bench/recording-first-ticks}")"
fi
before=$1 after=$2 runs=${3:-6} out=$4
source_dir=$(dirname "$(realpath "$0")")/..
rm -rf "$out"
mkdir -p "$out"
"$after/precompute/palpate-precompute" -q make-sample -o "$out/organ.msh"
"$after/precompute/palpate-precompute" -q -j "$source_dir/config/sample-organ.toml" \
  --mesh "$out/organ.msh" --no-xdmf -o "$out/organ.h5"
r=1
while [ "$r" -le "$runs" ]; do
  for v in before after; do
    b=$([ "$v" = before ] && echo "$before" || echo "$after")
    mkdir -p "$out/rec-$v-$r"
    "$b/server/palpated" --model "sample-organ=$out/organ.h5" --record "$out/rec-$v-$r" \
      --log-level warn 2>"$out/palpated-$v-$r.log" &
    daemon=$!
    "$b/clients/palpate-pliers" "$source_dir/config/gestures/press.toml" --model sample-organ -q \
      --csv "$out/ticks-$v-$r.csv" >"$out/pliers-$v-$r.txt" 2>&1 || true
    kill "$daemon"
    wait "$daemon" || true
  done
  r=$((r + 1))
done
exec /usr/bin/python3 - "$out" "$runs" <<'PY'
import csv, sys
out, runs = sys.argv[1], int(sys.argv[2])
for v in ("before", "after"):
    rows = []
    for r in range(1, runs + 1):
        ticks = list(csv.DictReader(open(f"{out}/ticks-{v}-{r}.csv")))
        first = [t for t in ticks if int(t["tick"]) < 20]
        worst = max(float(t["rtt_us"]) if t["rtt_us"] else float("inf") for t in first)
        late = sum(t["outcome"] != "in_time" for t in first)
        rtt = sorted(float(t["rtt_us"]) for t in ticks if t["rtt_us"])
        rows.append((worst, late, rtt[int(0.99 * (len(rtt) - 1))], rtt[-1]))
    print(f"{v}: first 20 ticks, largest round trip µs {[round(x[0]) for x in rows]}, "
          f"late or missing {[x[1] for x in rows]}; whole run p99 µs {[round(x[2]) for x in rows]}, "
          f"max µs {[round(x[3]) for x in rows]}")
PY
