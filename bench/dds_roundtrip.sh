#!/bin/sh
# DDS round trip of palpated against Cyclone DDS's own ping-pong, same machine,
# same rate, comparable payload, same loopback configuration.
#
# Usage: bench/dds_roundtrip.sh BUILD_DIR MODEL.h5 [SECONDS]   (as root)
#
# Everything runs inside ONE private network namespace whose only interface
# is loopback (unshare --net), and every DDS process gets palpate's loopback
# Cyclone configuration through CYCLONEDDS_URI (the XML of
# palpate::dds::loopback_config() in lib/src/dds.cpp): no DDS packet can reach
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
#    prints min/50%/90%/99%/max once per second; the first 2 s are dropped,
#    and the table gives the median over the seconds of its 50% and 99%
#    figures and the largest max (it prints no 99.9%).
#
# Caveat: ddsperf's round trip is ping→pong→ping between two listeners with
# nothing in between; ours is request→(validate, solve, reply)→reply through
# palpate's client (waitset, sample copy). The ratio is the overhead palpated
# adds over the transport's own floor, solve included.
set -eu

if [ $# -lt 2 ]; then
  echo "usage: $0 BUILD_DIR MODEL.h5 [SECONDS]" >&2
  exit 2
fi

# palpate::dds::loopback_config(), verbatim.
LOOPBACK_URI='<General><Interfaces><NetworkInterface name="lo" multicast="false"/></Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>100</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery>'

if [ "${PALPATE_ROUNDTRIP_NETNS:-}" != 1 ]; then
  build=$(realpath "$1")
  model=$(realpath "$2")
  shift 2
  exec unshare --net -- env PALPATE_ROUNDTRIP_NETNS=1 sh "$(realpath "$0")" "$build" "$model" "$@"
fi

BUILD=$1
MODEL=$2
SECONDS_MEASURED=${3:-10}
WARMUP=2
RATE=1000

# Inside the namespace: bring loopback up and refuse to go on if anything
# else is there (/sys/class/net would show the host's devices, ip does not).
ip link set lo up
interfaces=$(ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
if [ "$interfaces" != "lo " ]; then
  echo "dds_roundtrip: refusing to run: network namespace has interfaces '$interfaces', want only lo" >&2
  exit 1
fi

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
    CYCLONEDDS_URI="$LOOPBACK_URI" ddsperf -D $((duration + 3)) pong "$mode" >"$work/pong-$k-$mode.txt" 2>&1 &
    pong=$!
    echo "ddsperf -D $duration ping ${RATE}Hz size $size $mode  (with: ddsperf -D $((duration + 3)) pong $mode)" \
      >"$work/ddsperf-$k-$mode.cmd"
    CYCLONEDDS_URI="$LOOPBACK_URI" ddsperf -D "$duration" ping "${RATE}Hz" size "$size" "$mode" \
      >"$work/ping-$k-$mode.txt" 2>&1
    wait "$pong" || true
  done
done

/usr/bin/python3 - "$work" "$WARMUP" <<'EOF'
import json, re, statistics, sys

work, warmup = sys.argv[1], float(sys.argv[2])
# "[pid] 3.000  host:pid size 1200 mean 24.5us min 8.4us 50% 25.1us 90% 36.1us 99% 43.8us max 517.5us cnt 908"
LINE = re.compile(r"\]\s+([\d.]+)\s+\S+ size (\d+) mean ([\d.]+)us min ([\d.]+)us 50% ([\d.]+)us "
                  r"90% ([\d.]+)us 99% ([\d.]+)us max ([\d.]+)us cnt (\d+)")

def ddsperf(k, mode):
    path = f"{work}/ping-{k}-{mode}.txt"
    rows = [m.groups() for m in map(LINE.search, open(path)) if m]
    rows = [r for r in rows if float(r[0]) > warmup]
    if not rows:
        raise SystemExit(f"dds_roundtrip: no latency lines from ddsperf ping (k={k}, {mode}); its output:\n"
                         + open(path).read())
    return {"mode": mode, "size": int(rows[0][1]), "seconds": len(rows), "samples": sum(int(r[8]) for r in rows),
            "p50_us": statistics.median(float(r[4]) for r in rows),
            "p99_us": statistics.median(float(r[6]) for r in rows),
            "worst_second_p99_us": max(float(r[6]) for r in rows),
            "max_us": max(float(r[7]) for r in rows),
            "command": open(f"{work}/ddsperf-{k}-{mode}.cmd").read().strip()}

results = []
print("DDS round trip, loopback only, 1 kHz (µs); ddsperf: median over 1-s intervals of its 50% / 99%")
print("palpated's client waits for the reply on a waitset (as ddsperf's waitset mode) or polls (busy)")
print(f"{'k':>3} {'bytes':>6} {'client':>8} | {'palpated p50':>12} {'p99':>7} {'p99.9':>7} {'max':>7} | "
      f"{'ddsperf':>8} {'p50':>6} {'p99':>6} {'max':>7} | {'ratio p50':>9} {'p99':>5}")
for k in (1, 20):
    theirs = {mode: ddsperf(k, mode) for mode in ("listener", "waitset")}
    for wait in ("waitset", "busy"):
        ours = json.load(open(f"{work}/rtt-{k}-{wait}.json"))
        rt = ours["round_trip"]
        for mode in ("listener", "waitset"):
            t = theirs[mode]
            r50, r99 = rt["p50_us"] / t["p50_us"], rt["p99_us"] / t["p99_us"]
            print(f"{k:>3} {t['size']:>6} {wait:>8} | {rt['p50_us']:>12.1f} {rt['p99_us']:>7.1f} {rt['p999_us']:>7.1f} "
                  f"{rt['max_us']:>7.1f} | {mode:>8} {t['p50_us']:>6.1f} {t['p99_us']:>6.1f} {t['max_us']:>7.1f} | "
                  f"{r50:>9.2f} {r99:>5.2f}")
            results.append({"k": k, "client_wait": wait, "palpated": ours, "ddsperf": t, "ratio_p50": r50,
                            "ratio_p99": r99})
for k in (1, 20):
    r = next(x for x in results if x["k"] == k)
    print(f"k={k}: daemon solve p50 {r['palpated']['daemon_solve']['p50_us']:.1f} µs; ddsperf commands: "
          + "; ".join(x["ddsperf"]["command"] for x in results if x["k"] == k and x["client_wait"] == "waitset"))
print("target: palpated ≤ 1.5 × ddsperf at p50 and p99")
print("JSON " + json.dumps(results))
EOF
