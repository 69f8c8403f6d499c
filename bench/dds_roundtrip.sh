#!/bin/sh
# DDS round trip of palpated against Cyclone DDS's own ping-pong, same machine,
# same rate, comparable payload, same loopback configuration.
#
# Usage: bench/dds_roundtrip.sh BUILD_DIR MODEL.h5 [SECONDS]   (as root)
#
# Everything runs inside ONE private network namespace whose only interface
# is loopback (unshare --net), and every DDS process gets palpate's loopback
# Cyclone configuration through CYCLONEDDS_URI (the XML of
# palpate::dds::loopback_config() in lib/transport/src/dds.cpp): no DDS packet can reach
# a real network.
#
# 1. palpated serves MODEL.h5 as "liver"; palpate_rtt_bench measures the
#    request→reply round trip at 1 kHz for k = 1 and k = 20 (force only,
#    reused constraint set), its client waiting on a waitset and polling
#    (--busy-wait), 2 s warm-up then SECONDS (default 10) measured;
#    palpated is stopped with SIGTERM.
# 2. ddsperf ping-pong (two processes, like client and daemon) at 1000 Hz with
#    the mean of our request and reply sizes as payload, for each k, in its
#    listener and waitset modes; ddsperf
#    prints min/50%/90%/99%/max once per second, each HALF its round trip
#    (bench/ddsperf_log.py doubles them: the table compares full round trips);
#    the first 2 s are dropped, and the table gives the median over the
#    seconds of its 50% and 99% figures and the largest max (it prints no
#    99.9%).
#
# Caveat: ddsperf's round trip is ping→pong→ping between two listeners with
# nothing in between; ours is request→(validate, solve, reply)→reply through
# palpate's client (waitset, sample copy). The ratio is the overhead palpated
# adds over the transport's own floor, solve included.
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
enter_private_netns "$0" "$@"

BUILD=$1
LOOPBACK_URI=$(loopback_uri "$BUILD")
MODEL=$2
SECONDS_MEASURED=${3:-10}
WARMUP=2
RATE=1000

require_loopback_only dds_roundtrip

for program in "$BUILD/server/palpated" "$BUILD/bench/palpate_rtt_bench" /usr/bin/ddsperf; do
  [ -x "$program" ] || { echo "dds_roundtrip: $program is missing (build it, or apt-get install cyclonedds-tools)" >&2; exit 1; }
done
[ -f "$MODEL" ] || { echo "dds_roundtrip: no compliance file $MODEL" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# 1. palpated and palpate_rtt_bench.
CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/server/palpated" --model "liver=$MODEL" --log-level warn 2>"$work/palpated.log" &
daemon=$!
for k in 1 20; do
  for wait in waitset busy; do
    flag=""
    [ "$wait" = busy ] && flag="--busy-wait"
    if ! CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/bench/palpate_rtt_bench" --model-id liver -k "$k" --rate-hz "$RATE" \
        --seconds "$SECONDS_MEASURED" --warmup-seconds "$WARMUP" $flag --json >"$work/rtt-$k-$wait.json"; then
      echo "dds_roundtrip: palpate_rtt_bench -k $k $flag failed; palpated said:" >&2
      cat "$work/palpated.log" >&2
      kill -TERM "$daemon"
      exit 1
    fi
  done
done
kill -TERM "$daemon"
wait "$daemon" || { echo "dds_roundtrip: palpated exited with status $?" >&2; cat "$work/palpated.log" >&2; exit 1; }

# 2. ddsperf ping-pong, payload = mean of our request and reply sizes, in
#    both of its triggering modes: listener (its default: the reply is written
#    from Cyclone's receive thread) and waitset (an application thread wakes
#    up, as in palpated and palpate's client).
for k in 1 20; do
  size=$(/usr/bin/python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print((r["request_bytes"]+r["reply_bytes"])//2)' "$work/rtt-$k-waitset.json")
  duration=$((SECONDS_MEASURED + WARMUP))
  for mode in listener waitset; do
    ddsperf_pair "$work" "$k-$mode" "$duration" "$RATE" "$size" "$mode"
  done
done

/usr/bin/python3 - "$work" "$WARMUP" "$(dirname "$(realpath "$0")")" <<'EOF'
import json, sys

sys.path.insert(0, sys.argv[3])
import ddsperf_log

work, warmup = sys.argv[1], float(sys.argv[2])
def ddsperf(k, mode):
    return ddsperf_log.summary(work, f"{k}-{mode}", mode, warmup, "dds_roundtrip")

results = []
print("DDS round trip, loopback only, 1 kHz (µs); ddsperf RTT: its ping → pong → ping round trip (2 × the latency it"
      " prints), median over 1-s intervals of its 50% / 99%")
print("palpated's client waits for the reply on a waitset (as ddsperf's waitset mode) or polls (busy)")
print(f"{'k':>3} {'bytes':>6} {'client':>8} | {'palpated p50':>12} {'p99':>7} {'p99.9':>7} {'max':>7} | "
      f"{'ddsperf':>8} {'RTT p50':>7} {'p99':>6} {'max':>7} | {'ratio p50':>9} {'p99':>5}")
for k in (1, 20):
    theirs = {mode: ddsperf(k, mode) for mode in ("listener", "waitset")}
    for wait in ("waitset", "busy"):
        ours = json.load(open(f"{work}/rtt-{k}-{wait}.json"))
        rt = ours["round_trip"]
        for mode in ("listener", "waitset"):
            t = theirs[mode]
            # Full round trip over full round trip (ddsperf_log doubles what ddsperf prints).
            r50 = rt["p50_us"] / t["ddsperf_rtt_p50_us"]
            r99 = rt["p99_us"] / t["ddsperf_rtt_p99_us"]
            print(f"{k:>3} {t['size']:>6} {wait:>8} | {rt['p50_us']:>12.1f} {rt['p99_us']:>7.1f} {rt['p999_us']:>7.1f} "
                  f"{rt['max_us']:>7.1f} | {mode:>8} {t['ddsperf_rtt_p50_us']:>7.1f} {t['ddsperf_rtt_p99_us']:>6.1f} "
                  f"{t['ddsperf_rtt_max_us']:>7.1f} | {r50:>9.2f} {r99:>5.2f}")
            results.append({"k": k, "client_wait": wait, "palpated": ours, "ddsperf": t, "ratio_p50": r50,
                            "ratio_p99": r99})
for k in (1, 20):
    r = next(x for x in results if x["k"] == k)
    print(f"k={k}: daemon solve p50 {r['palpated']['daemon_solve']['p50_us']:.1f} µs; ddsperf commands: "
          + "; ".join(x["ddsperf"]["command"] for x in results if x["k"] == k and x["client_wait"] == "waitset"))
print("target (issue 19): palpated ≤ 1.2 × ddsperf's round trip at p50 and at p99")
print("JSON " + json.dumps(results))
EOF
