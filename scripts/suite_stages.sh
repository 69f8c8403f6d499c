# Sourced by scripts/test.sh and scripts/sanitize.sh: `stage NAME CMD...`
# runs CMD, prints "suite: NAME <seconds> s" when it ends (and fails as CMD
# fails), and notes it in one file the two scripts share
# (PALPATE_SUITE_STAGES_FILE), so that `stages_summary` prints every stage
# of the run with the total at the end.
stages_file=${PALPATE_SUITE_STAGES_FILE:-$(mktemp /tmp/palpate-suite-stages.XXXXXX)}
export PALPATE_SUITE_STAGES_FILE=$stages_file
# The suite links with lld where it is installed (scripts/install-deps.sh
# installs it; README, "How long the suite takes").
PALPATE_LINK_FLAGS=""
if command -v ld.lld >/dev/null 2>&1; then
  PALPATE_LINK_FLAGS="-DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld -DCMAKE_SHARED_LINKER_FLAGS=-fuse-ld=lld -DCMAKE_MODULE_LINKER_FLAGS=-fuse-ld=lld"
fi
stage() { # NAME CMD...
  local name=$1 start end status=0
  shift
  start=$(date +%s)
  "$@" || status=$?
  end=$(date +%s)
  echo "suite: $name $((end - start)) s"
  printf '%s\t%s\t%s\n' "$name" "$((end - start))" "$status" >>"$stages_file"
  return $status
}
stages_summary() {
  echo "suite: stages (wall time, s):"
  awk -F'\t' '{ printf "  %-28s %6d%s\n", $1, $2, ($3 == 0 ? "" : "  (failed)"); total += $2 }
              END { printf "  %-28s %6d\n", "total", total }' "$stages_file"
  rm -f "$stages_file"
}
