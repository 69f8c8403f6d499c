#!/usr/bin/env bash
# End-to-end test of the browser viewer (docs/viewer.md): palpated serves a
# small sample organ, palpate-viewer bridges it to the page, headless
# Chromium shows it, palpate-client and palpate-pliers press it, and the
# test stops palpated at the end (viewer/test/viewer_e2e.mjs has the
# checks). Screenshots and logs go to OUT_DIR.
#
# Usage: tests/viewer/viewer_e2e.sh BUILD_DIR OUT_DIR
# CTest starts it inside a private network namespace (unshare --net, lo up);
# it refuses to start DDS anywhere else.
set -euo pipefail
build=$(realpath "$1")
out=$(realpath -m "$2")
source_dir=$(realpath "$(dirname "$0")/../..")

name=viewer_e2e
# shellcheck source=tests/viewer/e2e_common.sh
source "$source_dir/tests/viewer/e2e_common.sh"

# A small organ (958 vertices): precomputed in well under a second.
"$build/precompute/palpate-precompute" make-sample -o "$work/organ.msh" --size 0.012 >/dev/null
sed -e "s|../out/sample-organ.msh|organ.msh|" -e "s|../out/sample-organ.h5|organ.h5|" \
    -e 's|^method = .*|method = "condensation"|' "$source_dir/config/sample-organ.toml" > "$work/job.toml"
"$build/precompute/palpate-precompute" --job "$work/job.toml" > "$out/precompute.txt" 2>&1
# A free surface vertex for palpate-client's requests: the first compliance vertex.
vertex=$(/usr/bin/python3 -c 'import sys, h5py; print(int(h5py.File(sys.argv[1], "r")["compliance/vertex_ids"][0]))' \
  "$work/organ.h5")

"$build/server/palpated" --model organ="$work/organ.h5" 2>"$out/palpated.log" &
palpated_pid=$!
pids+=($palpated_pid)
"$build/viewer/palpate-viewer" --listen 127.0.0.1:0 >"$out/viewer.log" 2>&1 &
pids+=($!)
url=""
for _ in $(seq 100); do
  url=$(grep -o 'http://127.0.0.1:[0-9]*/' "$out/viewer.log" || true)
  [ -n "$url" ] && break
  sleep 0.1
done
[ -n "$url" ] || { echo "viewer_e2e: palpate-viewer did not start:" >&2; cat "$out/viewer.log" >&2; exit 1; }

# Chromium renders WebGL in software (SwiftShader) and would take both cores
# from palpated's 1 kHz loop: it runs niced.
printf '#!/bin/sh\nexec nice -n 10 /usr/bin/chromium "$@"\n' > "$work/chromium"
chmod +x "$work/chromium"
PALPATE_CHROMIUM="$work/chromium" node "$source_dir/viewer/test/viewer_e2e.mjs" --url "$url" \
  --pliers "$build/clients/palpate-pliers" --client "$build/clients/palpate-client" \
  --gesture "$source_dir/config/gestures/steady-press.toml" --model organ --vertex "$vertex" \
  --palpated-pid "$palpated_pid" --out "$out"
