#!/bin/sh
# The surface stream while the region is cut (issue 20: "the stream at
# 60 Hz with the changing topology"): serves the cut demo's organ (the
# sample organ with config/sample-organ-cut.toml's region) with
# config/palpated-cut.toml's pliers and hook, reads its surface stream as a
# viewer does (build/bench/palpate_region_stream_bench) while
# palpate-pliers plays config/gestures/cut.toml, and prints the stream's
# rate, gaps and timing around each new topology version, and palpated's
# cuts (BENCHMARKS.md, "The stream while the region is cut").
#
# Usage: bench/region_stream.sh BUILD_DIR [MESH_SIZE_M]   (as root; default 0.008, the demo's)
#
# Everything runs inside one private network namespace whose only interface
# is loopback, with palpate's loopback Cyclone configuration (CYCLONEDDS_URI).
set -eu

. "$(dirname "$(realpath "$0")")/roundtrip_common.sh"
if [ $# -lt 1 ]; then
  echo "usage: $0 BUILD_DIR [MESH_SIZE_M]" >&2
  exit 2
fi
if [ "${PALPATE_BENCH_NETNS:-}" != 1 ]; then
  exec unshare --net -- env PALPATE_BENCH_NETNS=1 sh "$(realpath "$0")" "$(realpath "$1")" "${2:-0.008}"
fi
BUILD=$1
SIZE=${2:-0.008}
SOURCE=$(dirname "$(realpath "$0")")/..
require_loopback_only region_stream
LOOPBACK_URI=$(loopback_uri "$BUILD")

work=$(mktemp -d)
pids=""
cleanup() { for p in $pids; do kill -TERM "$p" 2>/dev/null || true; done; wait; rm -rf "$work"; }
trap cleanup EXIT

"$BUILD/bin/palpate-precompute" make-sample -o "$work/sample-organ.msh" --size "$SIZE" >/dev/null
sed -e "s|\"../out/sample-organ.msh\"|\"$work/sample-organ.msh\"|" \
    -e "s|\"../out/sample-organ-cut.h5\"|\"$work/sample-organ-cut.h5\"|" \
    -e 's|^method = .*$|method = "condensation"|' "$SOURCE/config/sample-organ-cut.toml" >"$work/cut.toml"
"$BUILD/bin/palpate-precompute" --job "$work/cut.toml" >"$work/precompute.txt"
sed -e "s|\"../out/sample-organ-cut.h5\"|\"$work/sample-organ-cut.h5\"|" \
    "$SOURCE/config/palpated-cut.toml" >"$work/palpated.toml"

CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/bin/palpated" --config "$work/palpated.toml" 2>"$work/palpated.log" &
pids="$!"
tries=0
until grep -q "event=serving" "$work/palpated.log" 2>/dev/null; do
  tries=$((tries + 1))
  [ $tries -lt 600 ] || { echo "region_stream: palpated did not start:" >&2; cat "$work/palpated.log" >&2; exit 1; }
  sleep 0.1
done

# The gesture lasts 7.2 s (the hook cuts from 2.7 to 4.8 s); the stream is
# read for 6 s from 0.5 s into it, while the tools move the organ (at rest
# palpated publishes nothing new).
CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/bin/palpate-pliers" "$SOURCE/config/gestures/cut.toml" \
  --model sample-organ-cut -q >"$work/pliers.txt" 2>&1 &
pliers=$!
sleep 0.5
CYCLONEDDS_URI="$LOOPBACK_URI" "$BUILD/bench/palpate_region_stream_bench" sample-organ-cut 6 >"$work/stream.txt"
wait "$pliers" || { echo "region_stream: palpate-pliers failed:" >&2; cat "$work/pliers.txt" >&2; exit 1; }

echo "region_stream: the sample organ at $SIZE m, $(grep -o 'tetrahedra=[0-9]*' "$work/palpated.log" | head -1) in the region; $(date -u +%Y-%m-%dT%H:%M:%SZ), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
cat "$work/stream.txt"
grep 'event=cut ' "$work/palpated.log" | awk '{ for (i = 1; i <= NF; ++i) if ($i ~ /^tetrahedra=/) { split($i, kv, "="); n += kv[2] } }
  END { printf "  palpated: %d cuts removing %d tetrahedra\n", NR, n }'
