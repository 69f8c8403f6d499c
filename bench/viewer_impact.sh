#!/bin/sh
# Does watching cost the haptics? The tool loop's round trip (palpate-pliers,
# both tools on steady-press.toml, 1 kHz) with nobody watching, with
# palpate-viewer bridging the topics to no page, and with a page open in
# headless Chromium (software WebGL, niced, 30 frames/s at most), same
# daemon, same run. The first configuration is the baseline of the ratios.
#
# Usage: bench/viewer_impact.sh BUILD_DIR MODEL.h5 [SECONDS]   (as root)
#
# Everything runs inside one private network namespace whose only interface
# is loopback, with palpate's loopback Cyclone configuration (CYCLONEDDS_URI).
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
enter_private_netns "$0" "$@"

BUILD=$1
LOOPBACK_URI=$(loopback_uri "$BUILD")
MODEL=$2
SECONDS_MEASURED=${3:-10}
SOURCE=$(dirname "$(realpath "$0")")/..
GESTURE=$SOURCE/config/gestures/steady-press.toml
REPEAT=$(/usr/bin/python3 -c 'import math, sys; print(max(1, math.ceil(float(sys.argv[1]) / 10.6)))' "$SECONDS_MEASURED")
require_loopback_only viewer_impact

work=$(mktemp -d)
printf '#!/bin/sh\nexec nice -n 10 /usr/bin/chromium "$@"\n' > "$work/chromium"
chmod +x "$work/chromium"
pids=""
cleanup() { for p in $pids; do kill -TERM "$p" 2>/dev/null || true; done; wait; rm -rf "$work"; }
trap cleanup EXIT

CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/server/palpated" --model "organ=$MODEL" --log-level warn 2>"$work/palpated.log" &
pids="$!"

play() {  # play NAME: the gesture, both tools, summary in $work/NAME.json
  CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/clients/palpate-pliers" "$GESTURE" --model organ --repeat "$REPEAT" \
    --warmup 1 --timeout 30 --quiet --json "$work/$1.json" >"$work/$1.txt" ||
    { echo "viewer_impact: palpate-pliers failed ($1):" >&2; cat "$work/$1.txt" >&2; exit 1; }
}

play nobody
CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/viewer/palpate-viewer" --listen 127.0.0.1:0 >"$work/viewer.log" 2>&1 &
viewer=$!
pids="$pids $viewer"
sleep 1
url=$(grep -o 'http://127.0.0.1:[0-9]*/' "$work/viewer.log")
play bridge
PALPATE_CHROMIUM="$work/chromium" node "$SOURCE/viewer/test/capture.mjs" --url "$url" --model organ \
  --out "$work" --interval 0 --seconds "$((11 * REPEAT))" >"$work/watch.txt" 2>&1 &
page=$!
pids="$pids $page"
for _ in $(seq 300); do grep -q 'capture: ready' "$work/watch.txt" && break; sleep 0.1; done
play page
wait "$page" || true

/usr/bin/python3 - "$work" <<'PY'
import json, sys
work = sys.argv[1]
page_text = open(f"{work}/watch.txt").read()
try:
    page = json.loads(page_text.strip().splitlines()[-1])
except (ValueError, IndexError):
    sys.exit(f"viewer_impact: the page did not report its rates; it said:\n{page_text}")
print("Tool loop round trip (pose → feedback), two tools, 1 kHz, µs; palpate-pliers on steady-press.toml")
print(f"{'watching':>8} {'tool':>5} | {'p50':>6} {'p99':>6} {'p99.9':>7} {'max':>7} {'≤1 ms':>8} {'late':>5} {'miss':>5} | {'p50 ÷ nobody':>12} {'p99 ÷ nobody':>12}")
base = {t["id"]: t["round_trip"] for t in json.load(open(f"{work}/nobody.json"))["tools"]}
for name in ("nobody", "bridge", "page"):
    for t in json.load(open(f"{work}/{name}.json"))["tools"]:
        rt, b = t["round_trip"], base[t["id"]]
        print(f"{name:>8} {t['id']:>5} | {rt['p50_us']:>6.0f} {rt['p99_us']:>6.0f} {rt['p999_us']:>7.0f} {rt['max_us']:>7.0f} "
              f"{100 * t['within_budget_share']:>7.2f}% {t['late']:>5} {t['missing']:>5} | {rt['p50_us'] / b['p50_us']:>12.2f} {rt['p99_us'] / b['p99_us']:>12.2f}")
print(f"page: {page['frames_per_s']:.1f} frames/s drawn, {page['surfaces_per_s']:.1f} surface frames/s received over {page['seconds']:.1f} s")
PY
