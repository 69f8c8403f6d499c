#!/bin/sh
# palpated serving a large compliance file (docs/precompute.md, "Serving a
# large model"): start-up time, resident memory and the request → reply round
# trip at 1 kHz, for LARGE.h5 against BASELINE.h5 measured in the same run.
#
# Usage: bench/large_model_serving.sh BUILD_DIR LARGE.h5 BASELINE.h5 [SECONDS]   (as root)
#
# Like the other round-trip benchmarks, everything runs in one private network
# namespace whose only interface is loopback, and every DDS process gets
# palpate's loopback configuration. For each file in turn: palpated serves it
# alone as "liver" (log level info); start-up is the time from launching
# palpated to its event=model_loaded line (the child-process probe of the file
# included); memory is palpated's VmRSS then and its VmHWM at the end;
# palpate_rtt_bench measures k = 1 and k = 20 constrained vertices (force
# requests, waitset client), 2 s warm-up then SECONDS (default 10).
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
enter_private_netns "$0" "$@"

BUILD=$1
LOOPBACK_URI=$(loopback_uri "$BUILD")
LARGE=$2
BASELINE=$(realpath "${3:?usage: $0 BUILD_DIR LARGE.h5 BASELINE.h5 [SECONDS]}")
SECONDS_MEASURED=${4:-10}

require_loopback_only large_model_serving
for program in "$BUILD/server/palpated" "$BUILD/bench/palpate_rtt_bench"; do
  [ -x "$program" ] || { echo "large_model_serving: $program is missing (build it)" >&2; exit 1; }
done

work=$(mktemp -d)
daemon=""
trap '[ -n "$daemon" ] && kill -TERM "$daemon" 2>/dev/null; rm -rf "$work"' EXIT

status_mb() { # PID KEY: /proc/PID/status KEY in MB (10^6 bytes)
  awk -v k="$2:" '$1 == k {printf "%.0f", $2 * 1024 / 1e6}' "/proc/$1/status"
}

echo "machine: $(hostname), $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GB", $2 / 1e6}' /proc/meminfo); load average $(cut -d' ' -f1-3 /proc/loadavg); $(date -u +%FT%TZ)"
echo
echo "| model | file | G | palpated's log | start-up s | RSS after load | peak RSS | k = 1 p50 / p99 µs | k = 20 p50 / p99 µs | daemon solve k = 20 p50 µs |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for which in baseline large; do
  if [ "$which" = large ]; then model=$LARGE; else model=$BASELINE; fi
  log=$work/palpated-$which.log
  start=$(date +%s.%N)
  CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/server/palpated" --model "liver=$model" --log-level info 2>"$log" &
  daemon=$!
  while ! grep -q "event=model_loaded" "$log"; do
    kill -0 "$daemon" 2>/dev/null || { echo "large_model_serving: palpated exited:" >&2; cat "$log" >&2; exit 1; }
    sleep 0.05
  done
  loaded=$(date +%s.%N)
  rss_loaded=$(status_mb "$daemon" VmRSS)
  for k in 1 20; do
    CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/bench/palpate_rtt_bench" --model-id liver -k "$k" --rate-hz 1000 \
      --seconds "$SECONDS_MEASURED" --warmup-seconds 2 --json >"$work/rtt-$which-$k.json" ||
      { echo "large_model_serving: palpate_rtt_bench -k $k failed; palpated said:" >&2; cat "$log" >&2; exit 1; }
  done
  peak=$(status_mb "$daemon" VmHWM)
  kill -TERM "$daemon"
  wait "$daemon" || { echo "large_model_serving: palpated exited with status $?" >&2; cat "$log" >&2; exit 1; }
  daemon=""
  /usr/bin/python3 - "$work" "$which" "$model" "$log" "$start" "$loaded" "$rss_loaded" "$peak" <<'EOF'
import json, os, re, sys
work, which, model, log, start, loaded, rss, peak = sys.argv[1:]
line = next(l for l in open(log) if "event=model_loaded" in l)
fields = dict(re.findall(r"(\w+)=(\S+)", line))
r = {k: json.load(open(f"{work}/rtt-{which}-{k}.json")) for k in (1, 20)}
rt = lambda k: f"{r[k]['round_trip']['p50_us']:.0f} / {r[k]['round_trip']['p99_us']:.0f}"
print(f"| {which}: {fields['compliance_vertices']} surface vertices | {os.path.basename(model)}, "
      f"{os.path.getsize(model) / 1e9:.2f} GB | {float(fields['G_MB']) / 1e3:.2f} GB {fields['G_precision']} | "
      f"model_loaded … G_MB={fields['G_MB']} G_precision={fields['G_precision']} seconds={fields['seconds']} | "
      f"{float(loaded) - float(start):.1f} | {rss} MB | {peak} MB | {rt(1)} | {rt(20)} | "
      f"{r[20]['daemon_solve']['p50_us']:.1f} |")
EOF
done
