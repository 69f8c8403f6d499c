#!/usr/bin/env bash
# Runs palpate's libFuzzer targets for longer than the test suite does
# (docs/fuzzing.md). Usage:
#   scripts/fuzz.sh [TARGET|all] [SECONDS]      default: all, 600 s each
# Environment:
#   PALPATE_FUZZ_BUILD_DIR  build directory (default build-fuzz; configured and
#                           built here with clang, ASan+UBSan and -DPALPATE_FUZZ=ON)
#   PALPATE_FUZZ_WORK       working corpora, logs and crash inputs, outside the
#                           repository (default /tmp/palpate-fuzz)
#   PALPATE_FUZZ_PARALLEL   targets run at once (default 2)
#   PALPATE_FUZZ_KEEP_GOING 1: libFuzzer's fork mode, which records a crash and
#                           goes on (-fork=1 -ignore_crashes=1 ...)
# The seed corpus fuzz/corpus/<target>/ is read, never written. A crash's
# input lands in $PALPATE_FUZZ_WORK/<target>/artifacts/; reproduce it with
#   <build>/fuzz/<target> <that file>
set -euo pipefail
cd "$(dirname "$0")/.."
targets_all=(fuzz_request fuzz_pose fuzz_compliance_file fuzz_compliance_struct fuzz_mesh_file
             fuzz_tet_mesh fuzz_daemon_config fuzz_job fuzz_gesture)
target=${1:-all}
seconds=${2:-600}
build=${PALPATE_FUZZ_BUILD_DIR:-build-fuzz}
work=${PALPATE_FUZZ_WORK:-/tmp/palpate-fuzz}
parallel=${PALPATE_FUZZ_PARALLEL:-2}
if [[ $target == all ]]; then
  targets=("${targets_all[@]}")
elif [[ " ${targets_all[*]} " == *" $target "* ]]; then
  targets=("$target")
else
  echo "fuzz.sh: unknown target '$target'; expected all or one of: ${targets_all[*]}" >&2
  exit 2
fi
if ! [[ $seconds =~ ^[1-9][0-9]*$ ]]; then
  echo "fuzz.sh: SECONDS '$seconds' is not a positive whole number" >&2
  exit 2
fi

if [[ ! -f $build/build.ninja ]]; then
  launcher=()
  command -v ccache > /dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  CC=clang CXX=clang++ cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DPALPATE_SANITIZE=address,undefined -DPALPATE_FUZZ=ON -DPALPATE_BUILD_BENCHMARKS=OFF "${launcher[@]}"
fi
ninja -C "$build" -j2 "${targets[@]}"

# Debian's Gmsh leaks on the malformed meshes it refuses (fuzz/lsan.supp).
export LSAN_OPTIONS=suppressions=$PWD/fuzz/lsan.supp

run() {
  local t=$1 dir=$work/$1
  mkdir -p "$dir/corpus" "$dir/artifacts"
  local options=(-max_total_time="$seconds" -timeout=30 -rss_limit_mb=3072 -print_final_stats=1
                 -artifact_prefix="$dir/artifacts/")
  case $t in
    fuzz_daemon_config | fuzz_job | fuzz_gesture) options+=(-dict=fuzz/toml.dict) ;;
    fuzz_mesh_file) options+=(-detect_leaks=0) ;;  # Gmsh leaks on every refused file
  esac
  [[ ${PALPATE_FUZZ_KEEP_GOING:-0} == 1 ]] &&
    options+=(-fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1)
  local status=0
  "$build/fuzz/$t" "${options[@]}" "$dir/corpus" "fuzz/corpus/$t" > "$dir/log.txt" 2>&1 || status=$?
  echo "$status" > "$dir/status"
}

running=0
for t in "${targets[@]}"; do
  echo "fuzz.sh: $t for $seconds s (log: $work/$t/log.txt)"
  run "$t" &
  if ((++running >= parallel)); then
    wait -n || true
    ((running--))
  fi
done
wait

# One line per target: libFuzzer's own final figures.
printf '%-24s %6s %12s %9s %7s %7s %7s %9s\n' target exit executions exec/s cov ft corpus artifacts
for t in "${targets[@]}"; do
  dir=$work/$t
  log=$dir/log.txt
  execs=$(grep -oE 'stat::number_of_executed_units: +[0-9]+' "$log" | tail -1 | awk '{print $2}')
  rate=$(grep -oE 'stat::average_exec_per_sec: +[0-9]+' "$log" | tail -1 | awk '{print $2}')
  last=$(grep -E '^#[0-9]+.*cov: ' "$log" | tail -1)
  # In fork mode the executions are the last status line's count.
  [[ -z $execs ]] && execs=$(sed -E 's/^#([0-9]+).*/\1/' <<< "$last")
  cov=$(grep -o 'cov: [0-9]*' <<< "$last" | awk '{print $2}')
  ft=$(grep -o 'ft: [0-9]*' <<< "$last" | awk '{print $2}')
  corpus=$(find "$dir/corpus" -type f | wc -l)
  artifacts=$(find "$dir/artifacts" -type f | wc -l)
  printf '%-24s %6s %12s %9s %7s %7s %7s %9s\n' "$t" "$(cat "$dir/status")" "${execs:-?}" \
    "${rate:-?}" "${cov:-?}" "${ft:-?}" "$corpus" "$artifacts"
done
