#!/bin/sh
# The tool loop's round trip (pose → palpated's contact solve → feedback), as
# palpate-pliers measures it at 1 kHz, next to Cyclone DDS's own best-effort
# ping-pong at the same rate and a comparable payload, same machine, same
# loopback configuration, same run.
#
# Usage: bench/pliers_roundtrip.sh BUILD_DIR MODEL.h5 [SECONDS]   (as root)
#
# Everything runs inside ONE private network namespace whose only interface
# is loopback (unshare --net), and every DDS process gets palpate's loopback
# Cyclone configuration through CYCLONEDDS_URI (the XML of
# palpate::dds::loopback_config() in lib/transport/src/dds.cpp): no DDS packet can reach
# a real network.
#
# 1. palpated serves MODEL.h5 as "organ" with its default tools (left,
#    right); palpate-pliers plays config/gestures/steady-press.toml (each tool
#    in contact, depth 3-5 mm, 10 s per play, played ceil(SECONDS / 10.6)
#    times, the first second left out) for the left tool alone, then for
#    both tools, its loop waiting for feedback on a waitset and polling
#    (--busy-wait); palpated is stopped with SIGTERM.
# 2. ddsperf -u (best effort, as the tool topics) ping-pong at 1000 Hz with
#    the mean of the pose and feedback sizes as payload, in its listener and
#    waitset modes, SECONDS + 2 s; ddsperf prints min/50%/90%/99%/max once per
#    second, each HALF its round trip (bench/ddsperf_log.py doubles them: the
#    ratios compare full round trips); the first 2 s are dropped, and the
#    table gives the median over the seconds of its 50% and 99% figures and
#    the largest max (it prints no 99.9%, and no share under 1 ms).
#
# Caveat: ddsperf's round trip is ping→pong→ping between two processes with
# nothing in between; ours is pose→(contacts, solve of every tool, feedback)
# →feedback through palpate's ToolClient. The ratio is what palpated's tool
# loop adds over the transport's own floor, the contact solve included.
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
enter_private_netns "$0" "$@"

BUILD=$1
LOOPBACK_URI=$(loopback_uri "$BUILD")
MODEL=$2
SECONDS_MEASURED=${3:-10}
WARMUP=2
RATE=1000
GESTURE=$(dirname "$(realpath "$0")")/../config/gestures/steady-press.toml
REPEAT=$(/usr/bin/python3 -c 'import math, sys; print(max(1, math.ceil(float(sys.argv[1]) / 10.6)))' "$SECONDS_MEASURED")

require_loopback_only pliers_roundtrip

for program in "$BUILD/server/palpated" "$BUILD/clients/palpate-pliers" /usr/bin/ddsperf; do
  [ -x "$program" ] || { echo "pliers_roundtrip: $program is missing (build it, or apt-get install cyclonedds-tools)" >&2; exit 1; }
done
[ -f "$MODEL" ] || { echo "pliers_roundtrip: no compliance file $MODEL" >&2; exit 1; }
[ -f "$GESTURE" ] || { echo "pliers_roundtrip: no gesture file $GESTURE" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# 1. palpated and palpate-pliers.
CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/server/palpated" --model "organ=$MODEL" --log-level warn 2>"$work/palpated.log" &
daemon=$!
for tools in one two; do
  for wait in waitset busy; do
    flags=""
    [ "$tools" = one ] && flags="--tool left"
    [ "$wait" = busy ] && flags="$flags --busy-wait"
    if ! CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/clients/palpate-pliers" "$GESTURE" --model organ --rate "$RATE" \
        --repeat "$REPEAT" --warmup 1 --timeout 30 --quiet $flags --json "$work/pliers-$tools-$wait.json" \
        >"$work/pliers-$tools-$wait.txt"; then
      echo "pliers_roundtrip: palpate-pliers $flags failed; it said:" >&2
      cat "$work/pliers-$tools-$wait.txt" >&2
      echo "palpated said:" >&2
      cat "$work/palpated.log" >&2
      kill -TERM "$daemon"
      exit 1
    fi
  done
done
kill -TERM "$daemon"
wait "$daemon" || { echo "pliers_roundtrip: palpated exited with status $?" >&2; cat "$work/palpated.log" >&2; exit 1; }

# 2. ddsperf ping-pong, best effort, payload = mean of the pose and feedback
#    sizes (XCDR2, approximate: encapsulation 4, two bounded strings of ids
#    "left"/"organ" at 4 + length + 1 padded to 8, then the fixed fields:
#    pose 2 × 8 + 8 × 8 = 80; feedback 8 + 8 + 6 × 8 + 8 + 4 + 4 + 2 padded
#    to 8 + 8 = 96).
size=$(( (4 + 16 + 16 + 80 + 4 + 16 + 16 + 96) / 2 ))
duration=$((SECONDS_MEASURED + WARMUP))
for mode in listener waitset; do
  ddsperf_pair "$work" "$mode" "$duration" "$RATE" "$size" "$mode" -u
done

/usr/bin/python3 - "$work" "$WARMUP" "$(dirname "$(realpath "$0")")" <<'EOF'
import json, sys

sys.path.insert(0, sys.argv[3])
import ddsperf_log

work, warmup = sys.argv[1], float(sys.argv[2])
def ddsperf(mode):
    return ddsperf_log.summary(work, mode, mode, warmup, "pliers_roundtrip")

theirs = {mode: ddsperf(mode) for mode in ("listener", "waitset")}
print("Tool loop round trip (pose → feedback), loopback only, 1 kHz, µs; palpate-pliers on steady-press.toml")
print("ddsperf -u (best effort) ping-pong, its round trip (RTT: 2 × the latency it prints), median over 1-s intervals")
print("of its 50% / 99% (it gives no p99.9, no share ≤ 1 ms):")
for t in theirs.values():
    print(f"  {t['mode']:>8}: RTT p50 {t['ddsperf_rtt_p50_us']:.1f}  p99 {t['ddsperf_rtt_p99_us']:.1f}  "
          f"max {t['ddsperf_rtt_max_us']:.1f}  ({t['samples']} round trips; printed p50 {t['printed_half_p50_us']:.1f}, "
          f"p99 {t['printed_half_p99_us']:.1f})")
print(f"{'tools':>5} {'tool':>5} {'wait':>7} | {'p50':>6} {'p99':>6} {'p99.9':>7} {'max':>7} {'≤1 ms':>8} "
      f"{'late':>5} {'miss':>5} | {'÷ listener RTT p50':>18} {'p99':>5} | {'÷ waitset RTT p50':>17} {'p99':>5}")
runs = []
for tools in ("one", "two"):
    for wait in ("waitset", "busy"):
        ours = json.load(open(f"{work}/pliers-{tools}-{wait}.json"))
        runs.append({"tools": tools, "client_wait": wait, "pliers": ours})
        for tool in ours["tools"]:
            rt = tool["round_trip"]
            # Full round trip over full round trip (ddsperf_log doubles what ddsperf prints).
            ratios = {m: (rt["p50_us"] / t["ddsperf_rtt_p50_us"], rt["p99_us"] / t["ddsperf_rtt_p99_us"])
                      for m, t in theirs.items()}
            print(f"{tools:>5} {tool['id']:>5} {wait:>7} | {rt['p50_us']:>6.0f} {rt['p99_us']:>6.0f} "
                  f"{rt['p999_us']:>7.0f} {rt['max_us']:>7.0f} {100 * tool['within_budget_share']:>7.2f}% "
                  f"{tool['late']:>5} {tool['missing']:>5} | {ratios['listener'][0]:>18.2f} {ratios['listener'][1]:>5.2f} | "
                  f"{ratios['waitset'][0]:>17.2f} {ratios['waitset'][1]:>5.2f}")
for run in runs:
    for tool in run["pliers"]["tools"]:
        c, lag = tool["compute"], tool["schedule_lag"]
        print(f"{run['tools']} tool(s), {run['client_wait']}, {tool['id']}: {tool['ticks']} poses counted; palpated's compute "
              f"p50 {c['p50_us']:.1f} µs p99 {c['p99_us']:.1f} µs; tick start lag p99 {lag['p99_us']:.0f} µs; "
              f"max |force| {tool['max_force_n']:.2f} N, max contacts {tool['max_contacts']}")
print("ddsperf commands: " + "; ".join(t["command"] for t in theirs.values()))
print("target (issue 19): pose → feedback ≤ 1.2 × ddsperf's round trip at p50 and at p99")
print("JSON " + json.dumps({"pliers": runs, "ddsperf": theirs}))
EOF
