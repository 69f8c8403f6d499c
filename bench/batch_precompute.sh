#!/bin/bash
# Batch precomputation benchmark (docs/precompute.md, "Batch precomputation"):
# wall time of 1, 2 and 4 local shards (+ merge) against the single streaming
# run of the same job, measured in the same invocation; peak RSS of every
# process; columns per second; and a check that every merged file equals the
# single run's (content_sha256). For N > 1 it also runs the N shards one after
# another, each alone: the slowest plus the merge is what N machines like this
# one would take (a cluster), measured rather than extrapolated.
#
#   bench/batch_precompute.sh BUILD_DIR OUT_DIR [SHARD_COUNTS] [palpate-precompute job options…]
#
# SHARD_COUNTS defaults to "1 2 4"; the job defaults to the h8 OpenHELP liver
# (../shared/data/liver, docs/data.md; posterior-superior box attachment,
# E = 85 kPa, ν = 0.45). Examples:
#   bench/batch_precompute.sh build out/bench/batch                       # h8 liver
#   bench/batch_precompute.sh build out/bench/batch "1 2 4" --mesh ../shared/data/liver/openhelp-liver.stl \
#       --mesh-unit mm --fill-size 6.8 -E 85e3 --nu 0.45 --fix-box -200 100 190 100 250 250   # ~100k tets
# Add --precision float32 and/or --memory-limit-gb G to measure those. Prints
# a Markdown table; the machine's other load is printed too (no baseline is
# meaningful on a loaded machine).
set -euo pipefail

[ $# -ge 2 ] || { echo "usage: $0 BUILD_DIR OUT_DIR [SHARD_COUNTS] [job options…]" >&2; exit 2; }
build=$1
out=$2
shift 2
counts="1 2 4"
if [ $# -gt 0 ] && [[ "$1" =~ ^[0-9\ ]+$ ]]; then counts=$1; shift; fi
here=$(cd "$(dirname "$0")/.." && pwd)
precompute=$build/precompute/palpate-precompute
[ -x "$precompute" ] || { echo "$0: $precompute not built" >&2; exit 2; }
if [ $# -eq 0 ]; then
  data=$here/../shared/data/liver
  [ -f "$data/openhelp-liver-h8.msh" ] || { echo "$0: $data/openhelp-liver-h8.msh is absent (see docs/data.md); give a job" >&2; exit 2; }
  set -- --mesh "$data/openhelp-liver-h8.msh" --mesh-unit mm -E 85e3 --nu 0.45 --fix-box -200 100 190 100 250 250
fi
mkdir -p "$out"
job=("$@" --no-xdmf --json -q)

# Runs CMD under /usr/bin/time -v; prints "wall_s peak_rss_MB". The peak is
# the report's peak_rss_bytes (the largest VmHWM of its phases): /usr/bin/time's
# maximum RSS only covers the last phase, because palpate-precompute resets
# the high-water mark at each phase to measure it.
timed() {
  local log=$1
  shift
  /usr/bin/time -v -o "$log.time" "$@" > "$log.json"
  local rss
  rss=$(/usr/bin/python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["peak_rss_bytes"] / 2**20)' "$log.json")
  awk -F': ' -v r="$rss" '/Elapsed \(wall clock\)/ {n = split($2, t, ":"); s = 0; for (i = 1; i <= n; i++) s = s * 60 + t[i]; w = s}
              END {printf "%.2f %.0f\n", w, r}' "$log.time"
}
json_value() {  # json_value FILE KEY: the first number after "KEY":
  grep -o "\"$2\": *[0-9.e+-]*" "$1" | head -1 | sed 's/.*: *//'
}
digest() {
  /usr/bin/python3 -c 'import h5py, sys; print(h5py.File(sys.argv[1])["/"].attrs["content_sha256"])' "$1"
}

echo "machine: $(hostname), $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GB", $2 / 1e6}' /proc/meminfo); load average $(cut -d' ' -f1-3 /proc/loadavg); $(date -u +%FT%TZ)"
echo "job: ${*}"

rm -f "$out"/single.h5 "$out"/.single.h5.checkpoint
read -r single_wall single_rss < <(timed "$out/single" "$precompute" "${job[@]}" --method solves -o "$out/single.h5")
single_digest=$(digest "$out/single.h5")
m=$(json_value "$out/single.json" surface)
rate=$(json_value "$out/single.json" columns_per_second)
echo
echo "| run | processes | wall s | vs single | merge s | peak RSS per process (MiB) | columns/s per process | file = single |"
echo "|---|---|---|---|---|---|---|---|"
printf "| single (solves, streamed) | 1 | %s | 1.00 | – | %s | %.0f | – |\n" "$single_wall" "$single_rss" "$rate"
# row LABEL TAG N WALL MERGE_WALL MERGE_RSS: the table row of the N shard runs
# whose reports are $out/TAG-N-k.json, merged into $out/sharded.h5.
row() {
  local label=$1 tag=$2 n=$3 wall=$4 merge_wall=$5 merge_rss=$6 rss rates same
  rss=$(cat "$out"/"$tag"-"$n"-*.measure | awk '{printf "%s%s", sep, $2; sep = " / "}')
  rates=$(for ((k = 0; k < n; k++)); do json_value "$out/$tag-$n-$k.json" columns_per_second; done |
          awk '{printf "%s%.0f", sep, $1; sep = " / "}')
  same=$([ "$(digest "$out/sharded.h5")" = "$single_digest" ] && echo yes || echo NO)
  printf "| %s | %d | %.2f | %.2f | %s | %s (merge %s) | %s | %s |\n" \
    "$label" "$n" "$wall" "$(awk -v a="$wall" -v b="$single_wall" 'BEGIN {print a / b}')" "$merge_wall" \
    "$rss" "$merge_rss" "$rates" "$same"
  rm -f "$out"/sharded.h5 "$out"/sharded.part-*
}
merge() { # TAG: merges $out/sharded.part-* into $out/sharded.h5; prints "wall_s peak_rss"
  timed "$out/$1" "$precompute" merge -o "$out/sharded.h5" --no-xdmf --json -q "$out"/sharded.part-*
}

for n in $counts; do
  rm -f "$out"/sharded.h5 "$out"/sharded.part-* "$out"/.sharded.part-*
  start=$(date +%s.%N)
  pids=()
  for ((k = 0; k < n; k++)); do
    timed "$out/shard-$n-$k" "$precompute" "${job[@]}" --shard "$k/$n" -o "$out/sharded.h5" > "$out/shard-$n-$k.measure" &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid"; done
  read -r merge_wall merge_rss < <(merge "merge-$n")
  end=$(date +%s.%N)
  row "$n local shard$([ "$n" -gt 1 ] && echo s) + merge" shard "$n" \
    "$(awk -v a="$start" -v b="$end" 'BEGIN {print b - a}')" "$merge_wall" "$merge_rss"

  # The same shards one after another, each alone on the machine: what N
  # machines like this one would take (the slowest shard, then the merge).
  [ "$n" -gt 1 ] || continue
  slowest=0
  for ((k = 0; k < n; k++)); do
    timed "$out/alone-$n-$k" "$precompute" "${job[@]}" --shard "$k/$n" -o "$out/sharded.h5" > "$out/alone-$n-$k.measure"
    slowest=$(awk -v a="$slowest" -v b="$(cut -d' ' -f1 "$out/alone-$n-$k.measure")" 'BEGIN {print (b > a ? b : a)}')
  done
  read -r merge_wall merge_rss < <(merge "merge-alone-$n")
  row "$n shards, one machine each (run alone one after another; slowest + merge)" alone "$n" \
    "$(awk -v a="$slowest" -v b="$merge_wall" 'BEGIN {print a + b}')" "$merge_wall" "$merge_rss"
done
echo
echo "G: $m columns; single run's report: $out/single.json"
rm -f "$out/single.h5"
