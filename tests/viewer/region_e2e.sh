#!/usr/bin/env bash
# End-to-end test of the viewer drawing a served cut region (docs/viewer.md,
# "The cut region"): palpated serves the small sample organ twice, with its
# cuttable region (config/sample-organ-cut.toml) and without, palpate-viewer
# bridges both, headless Chromium shows each (viewer/test/region_e2e.mjs has
# the checks). Screenshots and logs go to OUT_DIR.
#
# Usage: tests/viewer/region_e2e.sh BUILD_DIR OUT_DIR
# CTest starts it inside a private network namespace (unshare --net, lo up);
# it refuses to start DDS anywhere else.
set -euo pipefail
build=$(realpath "$1")
out=$(realpath -m "$2")
source_dir=$(realpath "$(dirname "$0")/../..")

name=region_e2e
# shellcheck source=tests/viewer/e2e_common.sh
source "$source_dir/tests/viewer/e2e_common.sh"

# The small sample organ (958 vertices), with and without its region: each
# precomputed in well under a second.
"$build/precompute/palpate-precompute" make-sample -o "$work/organ.msh" --size 0.012 >/dev/null
for job in sample-organ sample-organ-cut; do
  sed -e "s|../out/sample-organ.msh|organ.msh|" -e "s|../out/$job.h5|$job.h5|" \
      -e 's|^method = .*|method = "condensation"|' "$source_dir/config/$job.toml" > "$work/$job.toml"
  "$build/precompute/palpate-precompute" --job "$work/$job.toml" > "$out/precompute-$job.txt" 2>&1
done

"$build/server/palpated" --model cut="$work/sample-organ-cut.h5" --model organ="$work/sample-organ.h5" \
  2>"$out/palpated.log" &
pids+=($!)
"$build/viewer/palpate-viewer" --listen 127.0.0.1:0 >"$out/viewer.log" 2>&1 &
pids+=($!)
url=""
for _ in $(seq 100); do
  url=$(grep -o 'http://127.0.0.1:[0-9]*/' "$out/viewer.log" || true)
  [ -n "$url" ] && break
  sleep 0.1
done
[ -n "$url" ] || { echo "region_e2e: palpate-viewer did not start:" >&2; cat "$out/viewer.log" >&2; exit 1; }

printf '#!/bin/sh\nexec nice -n 10 /usr/bin/chromium "$@"\n' > "$work/chromium"
chmod +x "$work/chromium"
PALPATE_CHROMIUM="$work/chromium" node "$source_dir/viewer/test/region_e2e.mjs" --url "$url" \
  --model cut --plain organ --out "$out"
