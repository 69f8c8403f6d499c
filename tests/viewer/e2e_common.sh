# Sourced by the viewer's end-to-end scripts (viewer_e2e.sh, region_e2e.sh)
# after `set -euo pipefail`, with $name set to the script's name: refuses to
# start DDS outside a private network namespace, checks node, Chromium and
# the viewer's node modules, and gives a work folder and a list of pids
# that are stopped, and the folder removed, on exit.
interfaces=$(ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
if [ "$interfaces" != "lo " ]; then
  echo "$name: refusing to start DDS outside a private network namespace (interfaces: $interfaces)" >&2
  exit 1
fi
for tool in node /usr/bin/chromium; do
  command -v "$tool" >/dev/null || { echo "$name: $tool not found; run scripts/install-deps.sh" >&2; exit 1; }
done
[ -d "$source_dir/viewer/node_modules/playwright-core" ] ||
  { echo "$name: viewer/node_modules is missing; run scripts/install-deps.sh (npm ci in viewer/)" >&2; exit 1; }

mkdir -p "$out"
work=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
