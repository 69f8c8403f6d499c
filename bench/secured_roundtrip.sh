#!/bin/sh
# What DDS Security costs the round trips (docs/security.md): the tool loop
# (pose → feedback, palpate-pliers on config/gestures/steady-press.toml, one
# tool, 1 kHz) and the request loop (palpate-client demo: 3,001 requests at
# 1 kHz), with palpate's plain loopback configuration (the baseline) and
# with the configurations of scripts/dds-security.sh, data signed and data
# encrypted. Variants alternate, ROUNDS times (default 2), so that a drift
# of the machine's speed falls on all of them; palpated is restarted for each.
#
# Usage: bench/secured_roundtrip.sh BUILD_DIR MODEL.h5 [SECONDS] [ROUNDS]   (as root)
#
# Everything runs inside ONE private network namespace whose only interface
# is loopback (unshare --net); the secured configurations are loopback only
# too, like palpate's built-in one.
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
enter_private_netns "$0" "$@"

BUILD=$1
MODEL=$2
SECONDS_MEASURED=${3:-10}
ROUNDS=${4:-2}
here=$(dirname "$(realpath "$0")")
GESTURE=$here/../config/gestures/steady-press.toml
REPEAT=$(/usr/bin/python3 -c 'import math, sys; print(max(1, math.ceil(float(sys.argv[1]) / 10.6)))' "$SECONDS_MEASURED")

require_loopback_only secured_roundtrip
for program in "$BUILD/server/palpated" "$BUILD/clients/palpate-pliers" "$BUILD/clients/palpate-client"; do
  [ -x "$program" ] || { echo "secured_roundtrip: $program is missing (build it)" >&2; exit 1; }
done
[ -f "$MODEL" ] || { echo "secured_roundtrip: no compliance file $MODEL" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$here/../scripts/dds-security.sh" "$work/encrypt" --protection encrypt >"$work/certs.log"
"$here/../scripts/dds-security.sh" "$work/sign" --protection sign >>"$work/certs.log"

# config VARIANT PARTICIPANT: the --dds-config argument ("" for the built-in loopback one).
config() { [ "$1" = plain ] && echo "" || echo "$work/$1/$2/cyclonedds.xml"; }

round=1
while [ "$round" -le "$ROUNDS" ]; do
  for variant in plain sign encrypt; do
    tag=$variant-$round
    "$BUILD/server/palpated" --model "organ=$MODEL" --log-level warn --dds-config "$(config $variant palpated)" \
      2>"$work/palpated-$tag.log" &
    daemon=$!
    if ! "$BUILD/clients/palpate-pliers" "$GESTURE" --model organ --tool left --repeat "$REPEAT" --warmup 1 \
        --timeout 30 --quiet --dds-config "$(config $variant pliers)" --json "$work/pliers-$tag.json" \
        >"$work/pliers-$tag.txt" 2>&1 ||
      ! "$BUILD/clients/palpate-client" --dds-config "$(config $variant client)" demo --model organ \
        >"$work/client-$tag.txt" 2>&1; then
      echo "secured_roundtrip: $variant round $round failed:" >&2
      cat "$work/pliers-$tag.txt" "$work/client-$tag.txt" "$work/palpated-$tag.log" >&2 2>/dev/null || true
      kill -TERM "$daemon"
      exit 1
    fi
    kill -TERM "$daemon"
    wait "$daemon" || { echo "secured_roundtrip: palpated exited with status $?" >&2; exit 1; }
  done
  round=$((round + 1))
done

/usr/bin/python3 - "$work" "$ROUNDS" <<'EOF'
import json, re, statistics, sys

work, rounds = sys.argv[1], int(sys.argv[2])
variants = ("plain", "sign", "encrypt")
rows = {}
for v in variants:
    tool, client = [], []
    for r in range(1, rounds + 1):
        t = json.load(open(f"{work}/pliers-{v}-{r}.json"))["tools"][0]
        tool.append(t)
        text = open(f"{work}/client-{v}-{r}.txt").read()
        m = re.search(r"round trip seen by this client p50 (\d+) µs, p99 (\d+) µs, max (\d+) µs", text)
        if not m:
            sys.exit(f"secured_roundtrip: no round trip line in client-{v}-{r}.txt:\n{text}")
        client.append(tuple(float(x) for x in m.groups()))
    med = lambda xs: statistics.median(xs)
    rows[v] = {
        "tool_p50": med([t["round_trip"]["p50_us"] for t in tool]),
        "tool_p99": med([t["round_trip"]["p99_us"] for t in tool]),
        "tool_p999": med([t["round_trip"]["p999_us"] for t in tool]),
        "tool_within": med([100 * t["within_budget_share"] for t in tool]),
        "compute_p50": med([t["compute"]["p50_us"] for t in tool]),
        "req_p50": med([c[0] for c in client]),
        "req_p99": med([c[1] for c in client]),
        "runs": [{"tool": t["round_trip"], "within": t["within_budget_share"], "request": c} for t, c in zip(tool, client)],
    }
base = rows["plain"]
print(f"Round trips with and without DDS Security, loopback only, 1 kHz, µs (median over {rounds} alternating rounds)")
print(f"{'variant':>8} | {'tool p50':>8} {'p99':>6} {'p99.9':>6} {'≤1 ms':>7} {'÷ p50':>6} {'÷ p99':>6} | "
      f"{'request p50':>11} {'p99':>6} {'÷ p50':>6} {'÷ p99':>6} | compute p50")
for v in variants:
    r = rows[v]
    print(f"{v:>8} | {r['tool_p50']:>8.0f} {r['tool_p99']:>6.0f} {r['tool_p999']:>6.0f} {r['tool_within']:>6.2f}% "
          f"{r['tool_p50'] / base['tool_p50']:>6.2f} {r['tool_p99'] / base['tool_p99']:>6.2f} | "
          f"{r['req_p50']:>11.0f} {r['req_p99']:>6.0f} {r['req_p50'] / base['req_p50']:>6.2f} "
          f"{r['req_p99'] / base['req_p99']:>6.2f} | {r['compute_p50']:.1f}")
print("JSON " + json.dumps(rows))
EOF
