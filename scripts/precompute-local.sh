#!/bin/bash
# Batch precomputation on one machine: N shards of palpate-precompute as
# parallel processes, then merge (docs/precompute.md, "Batch precomputation").
#
#   scripts/precompute-local.sh N OUTPUT.h5 [palpate-precompute options…]
#
# e.g. scripts/precompute-local.sh 2 out/liver.h5 -j config/liver.toml
#
# Each shard computes whole blocks of G's columns into OUTPUT-stem.part-A-B.h5
# with a checkpoint beside it: run the same command again after a failure or
# a kill and every shard resumes where it stopped. The merged file equals a
# single run's bit for bit. Each shard uses the cores it is given (OpenBLAS
# and palpate's solve threads follow the CPU affinity): with N ≥ cores, pin
# them with PALPATE_LOCAL_PIN=1 (one core each, round robin).
#
# Environment: PALPATE_PRECOMPUTE (the program; default: on PATH, then the
# build directory), PALPATE_LOCAL_PIN=1.
set -euo pipefail

usage() {
  echo "usage: $0 N OUTPUT.h5 [palpate-precompute options: -j JOB, --mesh …, --precision …]" >&2
  exit 2
}
[ $# -ge 2 ] || usage
count=$1
output=$2
shift 2
[[ "$count" =~ ^[1-9][0-9]*$ ]] || { echo "$0: N must be a positive integer, not '$count'" >&2; exit 2; }

here=$(cd "$(dirname "$0")/.." && pwd)
precompute=${PALPATE_PRECOMPUTE:-$(command -v palpate-precompute || echo "$here/build/precompute/palpate-precompute")}
[ -x "$precompute" ] || { echo "$0: palpate-precompute not found (set PALPATE_PRECOMPUTE)" >&2; exit 2; }

dir=$(dirname "$output")
name=$(basename "$output")
stem=${name%.*}
ext=${name#"$stem"}
cores=$(nproc)

pids=()
for ((k = 0; k < count; k++)); do
  pin=()
  if [ "${PALPATE_LOCAL_PIN:-0}" = 1 ]; then pin=(taskset -c $((k % cores))); fi
  # Each shard's lines are prefixed with its number, for one readable log.
  ( "${pin[@]}" "$precompute" "$@" --shard "$k/$count" -o "$output" 2>&1 | sed -u "s|^|[shard $k/$count] |" ) &
  pids+=($!)
done
failed=0
for pid in "${pids[@]}"; do wait "$pid" || failed=1; done
# The pipeline's status is sed's: look for the shards' files instead.
shopt -s nullglob
parts=("$dir/$stem".part-*-*"$ext")
if [ "$failed" != 0 ] || [ "${#parts[@]}" -ne "$count" ]; then
  echo "$0: expected $count shard files $dir/$stem.part-*$ext, found ${#parts[@]}: a shard failed (see its" \
       "lines above; run again to resume it), or files of another split are there (remove them)" >&2
  exit 1
fi
merge_args=()  # the options merge shares with the shards
while [ $# -gt 0 ]; do
  case "$1" in
    --no-xdmf | -q | --quiet | --json | --memory-limit-gb=*) merge_args+=("$1") ;;
    --memory-limit-gb) merge_args+=("$1" "${2:-}"); shift ;;
  esac
  shift
done
"$precompute" merge -o "$output" "${merge_args[@]}" "${parts[@]}"
rm -f -- "${parts[@]}"
