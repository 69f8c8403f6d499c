#!/bin/sh
# The load test's short version (CTest load_short; the long one is
# bench/load_test.sh, BENCHMARKS.md "Load"): palpated with 8 tools at 1 kHz
# (4 stations × 2), 4 viewers and 100 requests/s for 20 s after 3 s of one
# station alone, on a small sample organ precomputed here. palpate_load_generator
# checks: palpated alive and exiting 0, every child exiting 0, no lost and no
# error reply, every tool answered and touching, every viewer receiving each
# model's surface and the heartbeat, no pose refused, palpated's RSS growth
# after a 5 s warm-up within 8 MB. No timing assertion: the round trips are
# printed, not checked.
#
# Usage: load_short_test.sh PRECOMPUTE PALPATED GENERATOR SOURCE_DIR OUT_DIR
# CTest starts it inside a private network namespace (unshare --net, lo up);
# it refuses to start DDS anywhere else.
set -eu
precompute=$1 palpated=$2 generator=$3 source_dir=$4 out=$5

interfaces=$(ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
if [ "$interfaces" != "lo " ]; then
  echo "load_short: refusing to start DDS outside a private network namespace (interfaces: $interfaces)" >&2
  exit 1
fi

rm -rf "$out"
mkdir -p "$out"
# A small organ (327 compliance vertices, 12 mm edges): about 3 s to precompute.
"$precompute" -q make-sample -o "$out/organ.msh" --size 0.012
"$precompute" -q -j "$source_dir/config/sample-organ.toml" --mesh "$out/organ.msh" \
  --method condensation --no-xdmf -o "$out/organ.h5"

# Under the sanitizers (scripts/sanitize.sh sets PALPATE_TEST_TIME_SCALE),
# ASan's quarantine of freed memory (256 MB) and its shadow grow palpated's
# RSS by design: the tolerance widens to 512 MB there, and LeakSanitizer
# checks for leaks instead.
# A reply's wait (2 s) stretches by the same factor: every client is
# instrumented too, and 8 tools at 1 kHz under ASan fill both cores.
rss_tolerance_mb=8
case "${PALPATE_TEST_TIME_SCALE:-1}" in 1 | 1.0) ;; *) rss_tolerance_mb=512 ;; esac
request_timeout_s=$(awk -v scale="${PALPATE_TEST_TIME_SCALE:-1}" 'BEGIN { print 2 * scale }')

exec "$generator" --palpated "$palpated" --config "$source_dir/config/load-test.toml" \
  --model-file "$out/organ.h5" --gesture "$source_dir/config/gestures/demo.toml" \
  --stations 4 --viewers 4 --request-hz 100 --seconds 20 --baseline 3 --warmup 5 \
  --rss-tolerance-mb "$rss_tolerance_mb" --request-timeout "$request_timeout_s" --work "$out/work" --json "$out/summary.json"
