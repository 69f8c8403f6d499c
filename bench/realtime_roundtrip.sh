#!/bin/sh
# Real-time operation under a competing CPU load (docs/realtime.md): the
# request and tool-pose round trips, quiet and loaded, each without and with
# the real-time options, next to Cyclone DDS's own ping-pong (ddsperf) in
# the same configuration and wake-up mode, all in one run.
#
# Usage: bench/realtime_roundtrip.sh BUILD_DIR MODEL.h5 [SECONDS]   (as root)
#
# Everything runs inside ONE private network namespace whose only interface
# is loopback (unshare --net), every DDS process with palpate's loopback
# Cyclone configuration (plus, with the options, the fragment that makes
# Cyclone's receive thread SCHED_FIFO: palpated --print-dds-config
# --rt-priority P; no interface or multicast setting in it).
#
# Four phases, in this order: quiet without the options, quiet with them,
# loaded without, loaded with. "Loaded": stress-ng --cpu N (default: one
# hog per CPU, N = nproc) at normal priority during the whole phase. In each
# phase:
#   1. palpated serves MODEL.h5 ("organ", default tools);
#      palpate_rtt_bench: k = 1 requests at 1 kHz, SECONDS measured after a
#      2 s warm-up; palpate-pliers: steady-press.toml with the left tool at
#      1 kHz, ceil(SECONDS / 10.6) plays, the first second left out.
#   2. ddsperf ping-pong at 1 kHz, SECONDS + 2 s (the first 2 s dropped):
#      reliable with the request/reply payload, best effort (-u) with the
#      mean of the pose's and the ToolResponse's sizes (334 bytes); pong in palpated's wake-up mode (listener:
#      the reply written on Cyclone's receive thread; waitset: a thread
#      woken), ping in the client's (waitset). It prints HALF its round trip
#      (bench/ddsperf_log.py doubles it): both sides of every ratio are full
#      round trips.
# Without the options every process has the normal scheduling. With them
# (RT_PRIORITY, default 50; RT_CPUS, default: all): palpated --rt-priority
# --cpus --lock-memory, the clients --rt-priority --cpus --lock-memory, and
# ddsperf under chrt -f RT_PRIORITY and taskset -c RT_CPUS with the same
# Cyclone fragment. SERVE (default listener) is palpated's --serve in both;
# CLIENT_WAIT=busy (default waitset) makes both clients poll (ddsperf has
# no polling mode: its ping then still waits on a waitset).
#
# It prints, per phase and kind, p50 / p99 / p99.9 / max / share within
# 1 ms, ddsperf's round trip p50 / p99 and the ratios, then the loaded
# figures over the quiet ones, and the 1-minute load average sampled every
# 5 s. Take measurements for the record on an otherwise quiet machine
# (uptime, top): the quiet phases are only quiet then.
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
enter_private_netns "$0" "$@"

BUILD=$1
MODEL=$2
SECONDS_MEASURED=${3:-10}
WARMUP=2
RATE=1000
RT_PRIORITY=${RT_PRIORITY:-50}
RT_CPUS=${RT_CPUS:-}
SERVE=${SERVE:-listener}
CLIENT_WAIT=${CLIENT_WAIT:-waitset}
LOAD_CPUS=${LOAD_CPUS:-$(nproc)}
GESTURE=$(dirname "$(realpath "$0")")/../config/gestures/steady-press.toml
REPEAT=$(/usr/bin/python3 -c 'import math, sys; print(max(1, math.ceil(float(sys.argv[1]) / 10.6)))' "$SECONDS_MEASURED")

require_loopback_only realtime_roundtrip

for program in "$BUILD/server/palpated" "$BUILD/clients/palpate-pliers" "$BUILD/bench/palpate_rtt_bench" \
    /usr/bin/ddsperf /usr/bin/stress-ng /usr/bin/chrt /usr/bin/taskset; do
  [ -x "$program" ] || { echo "realtime_roundtrip: $program is missing (build it, or scripts/install-deps.sh)" >&2; exit 1; }
done
[ -f "$MODEL" ] || { echo "realtime_roundtrip: no compliance file $MODEL" >&2; exit 1; }
case "$SERVE" in listener|waitset|busy) ;; *) echo "realtime_roundtrip: SERVE=$SERVE: expected listener, waitset or busy" >&2; exit 2 ;; esac
case "$CLIENT_WAIT" in waitset|busy) ;; *) echo "realtime_roundtrip: CLIENT_WAIT=$CLIENT_WAIT: expected waitset or busy" >&2; exit 2 ;; esac

work=$(mktemp -d)
load_pid=""
sampler=""
cleanup() {
  [ -n "$load_pid" ] && kill "$load_pid" 2>/dev/null && wait "$load_pid" 2>/dev/null
  [ -n "$sampler" ] && kill "$sampler" 2>/dev/null
  rm -rf "$work"
}
trap cleanup EXIT

# The 1-minute load average every 5 s, for the record.
( while :; do echo "$(date -u +%H:%M:%S) $(cut -d' ' -f1 /proc/loadavg)"; sleep 5; done ) >"$work/loadavg.txt" &
sampler=$!

PLAIN_URI=$(loopback_uri "$BUILD")
RT_URI=$(env -u CYCLONEDDS_URI "$BUILD/server/palpated" --print-dds-config --rt-priority "$RT_PRIORITY")
case "$RT_URI" in *"<AllowMulticast>false</AllowMulticast>"*) ;; *) echo "realtime_roundtrip: the real-time configuration lost loopback-only: $RT_URI" >&2; exit 1 ;; esac

rt_flags() {  # the real-time flags of palpate's programs
  echo "--rt-priority $RT_PRIORITY${RT_CPUS:+ --cpus $RT_CPUS} --lock-memory"
}
rt_prefix() {  # ddsperf with the same scheduling
  echo "chrt -f $RT_PRIORITY${RT_CPUS:+ taskset -c $RT_CPUS}"
}

# ddsperf_phase WORK TAG SECONDS SIZE PONG_MODE URI PREFIX [FLAGS]
ddsperf_phase() {
  _work=$1 _tag=$2 _seconds=$3 _size=$4 _pong=$5 _uri=$6 _prefix=$7 _flags=${8:-}
  CYCLONEDDS_URI="$_uri" $_prefix ddsperf $_flags -D $((_seconds + 3)) pong "$_pong" >"$_work/pong-$_tag.txt" 2>&1 &
  _pid=$!
  echo "${_prefix:+$_prefix }ddsperf ${_flags:+$_flags }-D $_seconds ping ${RATE}Hz size $_size waitset  (with: ${_prefix:+$_prefix }ddsperf ${_flags:+$_flags }-D $((_seconds + 3)) pong $_pong)" \
    >"$_work/ddsperf-$_tag.cmd"
  CYCLONEDDS_URI="$_uri" $_prefix ddsperf $_flags -D "$_seconds" ping "${RATE}Hz" size "$_size" waitset \
    >"$_work/ping-$_tag.txt" 2>&1
  wait "$_pid" || true
}

# phase NAME OPTIONS(off|on)
phase() {
  _name=$1 _options=$2
  if [ "$_options" = on ]; then
    _flags=$(rt_flags) _uri=$RT_URI _prefix=$(rt_prefix)
  else
    _flags="" _uri=$PLAIN_URI _prefix=""
  fi
  _busy=""
  [ "$CLIENT_WAIT" = busy ] && _busy="--busy-wait"
  echo "$(date -u +%H:%M:%S) phase $_name: palpated --serve $SERVE $_flags; clients $CLIENT_WAIT $_flags" >&2
  "$BUILD/server/palpated" --model "organ=$MODEL" --log-level info --serve "$SERVE" $_flags \
    2>"$work/palpated-$_name.log" &
  _daemon=$!
  if ! "$BUILD/bench/palpate_rtt_bench" --model-id organ -k 1 --rate-hz "$RATE" --seconds "$SECONDS_MEASURED" \
      --warmup-seconds "$WARMUP" $_busy $_flags --json >"$work/requests-$_name.json" 2>"$work/requests-$_name.err"; then
    echo "realtime_roundtrip: palpate_rtt_bench failed ($_name):" >&2
    cat "$work/requests-$_name.err" "$work/palpated-$_name.log" >&2
    kill -TERM "$_daemon"
    exit 1
  fi
  if ! "$BUILD/clients/palpate-pliers" "$GESTURE" --model organ --tool left --rate "$RATE" --repeat "$REPEAT" \
      --warmup 1 --timeout 30 --quiet $_busy $_flags --json "$work/poses-$_name.json" >"$work/poses-$_name.txt" 2>&1; then
    echo "realtime_roundtrip: palpate-pliers failed ($_name):" >&2
    cat "$work/poses-$_name.txt" "$work/palpated-$_name.log" >&2
    kill -TERM "$_daemon"
    exit 1
  fi
  kill -TERM "$_daemon"
  wait "$_daemon" || { echo "realtime_roundtrip: palpated exited with status $? ($_name)" >&2; cat "$work/palpated-$_name.log" >&2; exit 1; }
  grep -o 'event=realtime.*' "$work/palpated-$_name.log" >"$work/realtime-$_name.txt" || true
  _pong=listener
  [ "$SERVE" != listener ] && _pong=waitset
  _size=$(/usr/bin/python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print((r["request_bytes"]+r["reply_bytes"])//2)' "$work/requests-$_name.json")
  ddsperf_phase "$work" "requests-$_name" $((SECONDS_MEASURED + WARMUP)) "$_size" "$_pong" "$_uri" "$_prefix"
  # The mean size of a pose and of the answer the client reads (XCDR2,
  # approximate): the pose as in bench/pliers_roundtrip.sh, 4 + 16 + 16 + 80;
  # the ToolResponse (appendable: a 4-byte header more) 4 + 4 + 16 + 16 +
  # 16 (sequence, send time) + 56 (pose) + 56 (force, torque, grip) + 8
  # (contacts, state) + 8 (two flags, padded) + 8 (compute) + 8 (two flags,
  # padded) + 48 (contact wrench) + 288 (6 x 6 stiffness) + 16 (limits).
  ddsperf_phase "$work" "poses-$_name" $((SECONDS_MEASURED + WARMUP)) \
    $(( (4 + 16 + 16 + 80 + 4 + 4 + 16 + 16 + 16 + 56 + 56 + 8 + 8 + 8 + 8 + 48 + 288 + 16) / 2 )) \
    "$_pong" "$_uri" "$_prefix" -u
}

{ echo "before: $(uptime)"; top -bn1 | head -n 15; } >"$work/machine.txt"
phase quiet-off off
phase quiet-on on
stress-ng --cpu "$LOAD_CPUS" --timeout 3600 --quiet &
load_pid=$!
sleep 2
phase loaded-off off
phase loaded-on on
kill "$load_pid"
wait "$load_pid" 2>/dev/null || true
load_pid=""
echo "after: $(uptime)" >>"$work/machine.txt"

/usr/bin/python3 - "$work" "$WARMUP" "$(dirname "$(realpath "$0")")" "$SERVE" "$CLIENT_WAIT" "$LOAD_CPUS" <<'EOF'
import json, sys

sys.path.insert(0, sys.argv[3])
import ddsperf_log

work, warmup, serve, client_wait, load_cpus = sys.argv[1], float(sys.argv[2]), sys.argv[4], sys.argv[5], sys.argv[6]
phases = ["quiet-off", "quiet-on", "loaded-off", "loaded-on"]
print(open(f"{work}/machine.txt").read().rstrip())
print(f"palpated --serve {serve}; clients wait: {client_wait}; load: stress-ng --cpu {load_cpus} in the loaded phases")
for p in phases:
    print(f"  {p}: " + open(f"{work}/realtime-{p}.txt").read().strip())
rows = []
for p in phases:
    for kind in ("requests", "poses"):
        t = ddsperf_log.summary(work, f"{kind}-{p}", "", warmup, "realtime_roundtrip")
        ours = json.load(open(f"{work}/{kind}-{p}.json"))
        if kind == "requests":
            rt, within = ours["round_trip"], ours["within_1ms_share"]
            extra = f"daemon solve p50 {ours['daemon_solve']['p50_us']:.1f} µs, timeouts {ours['timeouts']}"
        else:
            tool = ours["tools"][0]
            rt, within = tool["round_trip"], tool["within_budget_share"]
            extra = (f"late {tool['late']}, missing {tool['missing']}, compute p50 {tool['compute']['p50_us']:.1f} µs "
                     f"p99 {tool['compute']['p99_us']:.1f} µs, tick lag p99 {tool['schedule_lag']['p99_us']:.0f} µs")
        rows.append({"phase": p, "kind": kind, "p50": rt["p50_us"], "p99": rt["p99_us"], "p999": rt["p999_us"],
                     "max": rt["max_us"], "within_1ms": within, "ddsperf": t,
                     "ratio_p50": rt["p50_us"] / t["ddsperf_rtt_p50_us"],
                     "ratio_p99": rt["p99_us"] / t["ddsperf_rtt_p99_us"], "extra": extra})
print("Round trips, µs; ddsperf RTT = 2 × what it prints, median over 1-s intervals of its 50% / 99%, same")
print("configuration, scheduling and wake-up mode (pong as palpated, ping on a waitset)")
print(f"{'phase':>10} {'kind':>8} | {'p50':>7} {'p99':>7} {'p99.9':>7} {'max':>7} {'≤1 ms':>8} | "
      f"{'ddsperf p50':>11} {'p99':>7} {'max':>7} | {'÷ p50':>6} {'÷ p99':>6}")
for r in rows:
    t = r["ddsperf"]
    print(f"{r['phase']:>10} {r['kind']:>8} | {r['p50']:>7.1f} {r['p99']:>7.1f} {r['p999']:>7.1f} {r['max']:>7.0f} "
          f"{100 * r['within_1ms']:>7.2f}% | {t['ddsperf_rtt_p50_us']:>11.1f} {t['ddsperf_rtt_p99_us']:>7.1f} "
          f"{t['ddsperf_rtt_max_us']:>7.0f} | {r['ratio_p50']:>6.2f} {r['ratio_p99']:>6.2f}")
for r in rows:
    print(f"{r['phase']} {r['kind']}: {r['extra']}; ddsperf: {r['ddsperf']['command']}")
by = {(r["phase"], r["kind"]): r for r in rows}
print("Loaded over quiet (target, issue 19: with the options within 2 ×):")
for kind in ("requests", "poses"):
    for opt in ("off", "on"):
        l, q = by[(f"loaded-{opt}", kind)], by[(f"quiet-{opt}", kind)]
        print(f"  {kind:>8}, options {opt:>3}: p50 {l['p50'] / q['p50']:.2f} ×, p99 {l['p99'] / q['p99']:.2f} ×"
              f"  (loaded-{opt} over quiet-{opt})")
    l, q = by[("loaded-on", kind)], by[("quiet-off", kind)]
    print(f"  {kind:>8}, loaded with options over quiet without: p50 {l['p50'] / q['p50']:.2f} ×, p99 {l['p99'] / q['p99']:.2f} ×")
print("target (issue 19): ≤ 1.2 × ddsperf's round trip at p50 and p99, same configuration and wake-up mode")
print("load average (1 min) every 5 s: " + " ".join(l.split()[1] for l in open(f"{work}/loadavg.txt")))
print("JSON " + json.dumps(rows))
EOF
