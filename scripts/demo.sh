#!/usr/bin/env bash
# palpate's demo on a fresh Debian 12 machine, as root: installs what is
# missing, builds, precomputes an organ, serves it with palpated, opens the
# live viewer, and plays a two-handed gesture with palpate-pliers through the
# C API for devices, the local model rendered at 4 kHz (right hand presses
# and glides, left hand grasps, pulls and releases), then prints the latency
# and force summary, the recorded session's report and plots.
#
# Usage: scripts/demo.sh              the sample organ (config/sample-organ.toml)
#        scripts/demo.sh config/sample-organ-cut.toml
#                                     the cut demo: the sample organ with its cuttable
#                                     region, served with config/palpated-cut.toml (pliers
#                                     and a cutting hook), playing config/gestures/cut.toml
#        scripts/demo.sh JOB.toml     a precompute job, e.g. config/openhelp-liver-h8.toml
#        scripts/demo.sh MESH         a mesh (.msh .mesh .vtk .stl): the job in config/ that
#                                     names it, else a default job (docs/viewer.md, "The demo")
# Environment: PALPATE_DEMO_PORT     the viewer's port on 127.0.0.1 (default 8080)
#              PALPATE_DEMO_REPEAT   times the gesture is played (default 2; the cut demo 1)
#              PALPATE_DEMO_GESTURE  the gesture file (default config/gestures/demo.toml;
#                                    config/gestures/lift.toml grasps and lifts;
#                                    config/gestures/cut.toml, with no job given, runs
#                                    the cut demo)
#              PALPATE_DEMO_WARPING  "linear" (default) or "warped": the model's
#                                    mechanics (palpated --warp, docs/model/warped.md,
#                                    "Large rotations: warped compliance")
#              PALPATE_DEMO_NETNS    "private" (default) or "host" (below)
#              PALPATE_BUILD_DIR     the build directory (default build)
#              PALPATE_DEMO_OUT      the folder of its outputs (default out/demo; the
#                                    sample organ stays in out/, where its job writes it)
# Outputs: out/demo/ (the script lists them at the end). A second run reuses
# the compliance file when its input hash shows the same problem
# (palpate-precompute --reuse) and keeps the earlier sessions' recordings
# and plots (each session's files are named by its start time).
#
# Network: palpated, the pliers and the viewer's DDS side run in a private
# network namespace whose only interface is loopback (unshare --net, then
# ip link set lo up); the viewer opens its HTTP port on the machine's
# 127.0.0.1 before joining that namespace, so a browser here can reach it.
# PALPATE_DEMO_NETNS=host runs them in the machine's namespace instead, still
# with palpate's loopback-only DDS configuration.
set -euo pipefail
cd "$(dirname "$0")/.."
script_start_ns=$(date +%s%N)
port=${PALPATE_DEMO_PORT:-8080}
# The cut demo: its job, its palpated configuration (the tools: pliers and
# a cutting hook) and its gesture, chosen together by the job or the gesture.
cut_job=config/sample-organ-cut.toml
cut_config=config/palpated-cut.toml
cut_gesture=config/gestures/cut.toml
input=${1:-}
if [ -z "$input" ] && [ -n "${PALPATE_DEMO_GESTURE:-}" ] &&
   [ "$(realpath -m "$PALPATE_DEMO_GESTURE")" = "$(realpath -m "$cut_gesture")" ]; then
  input=$cut_job
fi
cut_demo=0
[ -n "$input" ] && [ "$(realpath -m "$input")" = "$(realpath -m "$cut_job")" ] && cut_demo=1
if [ "$cut_demo" = 1 ]; then
  repeat=${PALPATE_DEMO_REPEAT:-1}
  gesture=${PALPATE_DEMO_GESTURE:-$cut_gesture}
else
  repeat=${PALPATE_DEMO_REPEAT:-2}
  gesture=${PALPATE_DEMO_GESTURE:-config/gestures/demo.toml}
fi
warping=${PALPATE_DEMO_WARPING:-linear}
case $warping in linear | warped) ;; *)
  echo "demo: PALPATE_DEMO_WARPING=$warping: expected linear or warped" >&2; exit 2 ;;
esac
if [ ! -f "$gesture" ]; then
  echo "demo: PALPATE_DEMO_GESTURE=$gesture: no such file (the gestures are in config/gestures/)" >&2
  exit 2
fi
# A mistyped input is said before minutes of install and build, not after.
# (The sample organ's mesh is made below, so its job needs no file yet.)
if [ -n "$input" ] && [ "$cut_demo" = 0 ] && [ ! -f "$input" ]; then
  echo "demo: $input: no such file (expected a job .toml or a mesh .msh/.mesh/.vtk/.stl)" >&2
  exit 2
fi
warp_flags=()
netns_mode=${PALPATE_DEMO_NETNS:-private}
build=${PALPATE_BUILD_DIR:-build}
case $netns_mode in private | host) ;; *)
  echo "demo: PALPATE_DEMO_NETNS=$netns_mode: expected private or host" >&2; exit 2 ;;
esac
if [ "$netns_mode" = private ] && [ "$(id -u)" -ne 0 ]; then
  echo "demo: run as root (a private network namespace needs it), or set PALPATE_DEMO_NETNS=host" >&2
  exit 2
fi

say() { printf '\ndemo: %s\n' "$*"; }
now_ms() { echo $(($(date +%s%N) / 1000000)); }
# wait_for FILE PATTERN PID SECONDS: until FILE has a line matching PATTERN
# (true), PID exits or SECONDS pass (false).
wait_for() {
  local deadline=$(($(now_ms) + 1000 * $4))
  until grep -q "$2" "$1" 2>/dev/null; do
    kill -0 "$3" 2>/dev/null && [ "$(now_ms)" -lt "$deadline" ] || return 1
    sleep 0.1
  done
}

scripts/install-deps.sh
install_ms=$(($(now_ms) - script_start_ns / 1000000))
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j2 --target palpate_bin
build_ms=$(($(now_ms) - script_start_ns / 1000000 - install_ms))
out=${PALPATE_DEMO_OUT:-out/demo}
# The screenshots are this run's; the recordings and their plots are kept.
rm -f "$out"/viewer*.png
mkdir -p "$out/recordings"
precompute=$build/bin/palpate-precompute

# ------------------------------------------------------------- the organ
job_output() {  # the compliance file a job writes, resolved against the job's folder
  /usr/bin/python3 -c '
import os, sys, tomllib
job = sys.argv[1]
with open(job, "rb") as f:
    out = tomllib.load(f)["output"]["file"]
print(os.path.normpath(os.path.join(os.path.dirname(job), out)))' "$1"
}
job_for_mesh() {  # the job under config/ whose mesh is this file, if any
  /usr/bin/python3 -c '
import glob, os, sys, tomllib
mesh = os.path.realpath(sys.argv[1])
for job in sorted(glob.glob("config/**/*.toml", recursive=True)):
    try:
        with open(job, "rb") as f:
            m = tomllib.load(f).get("mesh", {}).get("file")
    except (OSError, tomllib.TOMLDecodeError):
        continue
    if m and os.path.realpath(os.path.join(os.path.dirname(job), m)) == mesh:
        print(job)
        break' "$1"
}

if [ -z "$input" ] || [ "$cut_demo" = 1 ]; then
  say "the sample organ (about 1,900 vertices, the scale of the 1999 INRIA liver)"
  "$precompute" make-sample -o out/sample-organ.msh --size 0.008
  [ -n "$input" ] || input=config/sample-organ.toml
fi
case $input in
  *.toml) job=$input ;;
  *) job=$(job_for_mesh "$input") ;;
esac
start=$(now_ms)
if [ -n "$job" ]; then
  say "precomputing $job (both methods, cross-checked; kept if the file there holds this problem)"
  "$precompute" --job "$job" --reuse
  compliance=$(job_output "$job")
else
  # A mesh no job names: guess its unit from its size (the one that makes
  # it about 20 cm across), hold the top 15 % of
  # it (a hanging organ) and use the sample's material. Say so.
  read -r unit half_space < <(/usr/bin/python3 -c '
import contextlib, sys, meshio, numpy as np
with contextlib.redirect_stdout(sys.stderr):  # meshio talks on stdout
    p = meshio.read(sys.argv[1]).points
lo, hi = p.min(axis=0), p.max(axis=0)
# The unit that makes it organ-sized: its diagonal nearest 0.2 m (log scale).
diagonal = np.linalg.norm(hi - lo)
unit = min(("m", 1.0), ("cm", 0.01), ("mm", 0.001), key=lambda u: abs(np.log(diagonal * u[1] / 0.2)))[0]
z = hi[2] - 0.15 * (hi[2] - lo[2])
print(unit, 0, 0, f"{z:.6g}", 0, 0, 1)' "$input")
  compliance=$out/$(basename "${input%.*}").h5
  say "no job in config/ names $input: unit $unit (from its size), fixed: the top 15 % (z ≥ $(echo "$half_space" | cut -d' ' -f3)), E = 85 kPa, ν = 0.45"
  # shellcheck disable=SC2086
  "$precompute" --mesh "$input" --mesh-unit "$unit" --fix-half-space $half_space \
    -E 85e3 --nu 0.45 --method condensation -o "$compliance" --reuse
fi
model=$(basename "$compliance" .h5)
precompute_ms=$(($(now_ms) - start))

# ------------------------------------------------- processes and cleanup
pids=()     # running: stopped by cleanup
started=()  # every process this script started, checked at the end
cleanup() {
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT
trap 'exit 130' INT TERM

if [ "$netns_mode" = private ]; then
  unshare --net -- sleep infinity &
  holder=$!
  pids+=("$holder")
  started+=("$holder")
  netns=/proc/$holder/ns/net
  for _ in $(seq 50); do [ "$(readlink "$netns")" != "$(readlink /proc/self/ns/net)" ] && break; sleep 0.02; done
  # nsenter joins the namespace and execs the program: $! is the program.
  in_netns=(nsenter --net="$netns" --)
  "${in_netns[@]}" ip link set lo up
  interfaces=$("${in_netns[@]}" ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
  [ "$interfaces" = "lo " ] || { echo "demo: the private namespace has '$interfaces', want only lo" >&2; exit 5; }
  viewer_netns=(--dds-netns "$netns")
else
  in_netns=()
  viewer_netns=()
fi

say "palpated serves $compliance as model '$model' (DDS: loopback only, network namespace: $netns_mode)"
[ "$warping" = warped ] && warp_flags=(--warp "$model")
if [ "$cut_demo" = 1 ]; then
  # Its configuration serves the job's file as this model, with the tools.
  served=(--config "$cut_config")
  viewer_tools=(-c "$cut_config")
else
  served=(--model "$model=$compliance")
  viewer_tools=()
fi
"${in_netns[@]}" "$build/bin/palpated" "${served[@]}" "${warp_flags[@]}" --record "$out/recordings" 2>"$out/palpated.log" &
daemon=$!
pids+=("$daemon")
started+=("$daemon")
if ! wait_for "$out/palpated.log" 'event=serving' "$daemon" 60; then
  echo "demo: palpated did not start serving; its log ($out/palpated.log) ends with:" >&2
  tail -3 "$out/palpated.log" >&2
  exit 5
fi
"$build/bin/palpate-viewer" --listen "127.0.0.1:$port" "${viewer_netns[@]}" "${viewer_tools[@]}" >"$out/viewer.log" 2>&1 &
pids+=($!)
started+=($!)
wait_for "$out/viewer.log" 'http://[0-9.]*:[0-9]*/' "$!" 10 || true
url=$(grep -o 'http://[0-9.]*:[0-9]*/' "$out/viewer.log" || true)
if [ -z "$url" ]; then
  echo "demo: the viewer did not start: $(cat "$out/viewer.log") (another port: PALPATE_DEMO_PORT=8081)" >&2
  exit 5
fi
say "the live viewer: $url?model=$model (open it in a browser on this machine, or ssh -L $port:127.0.0.1:$port)"
if [ -n "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ] && command -v xdg-open >/dev/null; then
  xdg-open "$url?model=$model" >/dev/null 2>&1 || true
fi

say "palpate-client: requests and replies at 1 kHz (docs/dds.md)"
"${in_netns[@]}" "$build/bin/palpate-client" demo --model "$model"

# Headless Chromium takes screenshots while the gesture plays; it renders
# in software, so it runs niced to leave the cores to palpated's 1 kHz loop.
gesture_s=$(/usr/bin/python3 -c '
import math, sys, tomllib
with open(sys.argv[1], "rb") as f:
    g = tomllib.load(f)
end = max(k["t"] for t in g["tool"] for k in t["keyframe"])
print(math.ceil(end * int(sys.argv[2])) + 1)' "$gesture" "$repeat")
printf '#!/bin/sh\nexec nice -n 10 /usr/bin/chromium "$@"\n' > "$out/.chromium"
chmod +x "$out/.chromium"
PALPATE_CHROMIUM=$out/.chromium node viewer/test/capture.mjs --url "$url" --model "$model" \
  --out "$out" --seconds "$gesture_s" --interval 1 >"$out/capture.log" 2>&1 &
capture=$!
pids+=("$capture")
started+=("$capture")
wait_for "$out/capture.log" 'capture: ready' "$capture" 30 ||
  echo "demo: no screenshots: $(tail -1 "$out/capture.log")" >&2

say "palpate-pliers plays $gesture $repeat time(s) on the $warping model: poses at 1 kHz, the local model rendered at 4 kHz through the C API (docs/pliers.md, docs/devices.md)"
status=0
"${in_netns[@]}" "$build/bin/palpate-pliers" "$gesture" --model "$model" --repeat "$repeat" \
  --json "$out/pliers.json" || status=$?
wait "$capture" 2>/dev/null || true
kill -TERM "$daemon"
wait "$daemon" || status=$?
cleanup
pids=()

recording=$(ls -t "$out"/recordings/*.h5 2>/dev/null | head -1 || true)
recordings=$(ls "$out"/recordings/*.h5 2>/dev/null | wc -l)
if [ -n "$recording" ]; then
  say "the recorded session ($recording)"
  /usr/bin/python3 scripts/session_report.py "$recording" || status=$?
  /usr/bin/python3 scripts/session_plots.py "$recording" --out "$out" || status=$?
fi

left=0
for pid in "${started[@]}"; do kill -0 "$pid" 2>/dev/null && left=$((left + 1)); done
seconds() { echo "$(($1 / 1000)).$(($1 % 1000 / 100)) s"; }
total_ms=$(($(now_ms) - script_start_ns / 1000000))
say "done in $(seconds "$total_ms"): install $(seconds "$install_ms"), build $(seconds "$build_ms"), precompute $(seconds "$precompute_ms"), the rest $(seconds $((total_ms - install_ms - build_ms - precompute_ms))); processes left running: $left of ${#started[@]} started"
xdmf=${compliance%.h5}.xdmf
[ -f "$xdmf" ] && xdmf=", $xdmf for ParaView" || xdmf=""
echo "  compliance file  $compliance$xdmf (docs/compliance-file.md)"
echo "  viewer           $out/viewer.png (the liveliest of $out/viewer-NN.png); log $out/viewer.log"
echo "  gesture summary  $out/pliers.json"
echo "  session          ${recording:-none} and its plots $out/<session>-force.png, -latency.png, -contacts.png"
echo "                   ($recordings recorded session(s) in $out/recordings, earlier runs' kept)"
echo "  daemon log       $out/palpated.log"
exit $status
