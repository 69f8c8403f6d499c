# Sourced by bench/dds_roundtrip.sh and bench/pliers_roundtrip.sh: what both
# round-trip benchmarks need to run DDS safely and to measure Cyclone's own
# ping-pong in the same run. POSIX sh.

# loopback_uri BUILD_DIR: palpate's built-in loopback configuration
# (config/dds-loopback.xml, as palpated prints it), for CYCLONEDDS_URI: ddsperf
# and every other process of a benchmark get it.
loopback_uri() {
  [ -x "$1/server/palpated" ] || { echo "$1/server/palpated is missing: build it first" >&2; exit 1; }
  env -u CYCLONEDDS_URI "$1/server/palpated" --print-dds-config
}

# enter_private_netns SCRIPT BUILD_DIR MODEL [ARGS...]: unless already
# inside, re-executes SCRIPT in a new network namespace (paths made absolute).
# Without BUILD_DIR and MODEL it prints the benchmarks' usage and exits 2.
enter_private_netns() {
  if [ $# -lt 3 ]; then
    echo "usage: $1 BUILD_DIR MODEL.h5 [SECONDS]" >&2
    exit 2
  fi
  if [ "${PALPATE_BENCH_NETNS:-}" != 1 ]; then
    _script=$(realpath "$1")
    _build=$(realpath "$2")
    _model=$(realpath "$3")
    shift 3
    exec unshare --net -- env PALPATE_BENCH_NETNS=1 sh "$_script" "$_build" "$_model" "$@"
  fi
}

# require_loopback_only NAME: inside the namespace, brings loopback up and
# refuses to go on if anything else is there (/sys/class/net would show the
# host's devices, ip does not).
require_loopback_only() {
  ip link set lo up
  _interfaces=$(ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
  if [ "$_interfaces" != "lo " ]; then
    echo "$1: refusing to run: network namespace has interfaces '$_interfaces', want only lo" >&2
    exit 1
  fi
}

# ddsperf_pair WORK TAG SECONDS RATE_HZ SIZE MODE [FLAGS]: one ddsperf
# ping-pong (pong in the background, a little longer than the ping), the
# ping's output in WORK/ping-TAG.txt and its command line in
# WORK/ddsperf-TAG.cmd (read by bench/ddsperf_log.py).
ddsperf_pair() {
  _work=$1 _tag=$2 _seconds=$3 _rate=$4 _size=$5 _mode=$6 _flags=${7:-}
  CYCLONEDDS_URI="$LOOPBACK_URI" ddsperf $_flags -D $((_seconds + 3)) pong "$_mode" >"$_work/pong-$_tag.txt" 2>&1 &
  _pong=$!
  echo "ddsperf ${_flags:+$_flags }-D $_seconds ping ${_rate}Hz size $_size $_mode  (with: ddsperf ${_flags:+$_flags }-D $((_seconds + 3)) pong $_mode)" \
    >"$_work/ddsperf-$_tag.cmd"
  CYCLONEDDS_URI="$LOOPBACK_URI" ddsperf $_flags -D "$_seconds" ping "${_rate}Hz" size "$_size" "$_mode" \
    >"$_work/ping-$_tag.txt" 2>&1
  wait "$_pong" || true
}
