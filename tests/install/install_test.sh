#!/bin/sh
# cmake --install into a fresh prefix, then two out-of-tree consumers of it:
# a CMake project (find_package(palpate) + palpate::palpate, every public
# header compiled alone, a ToolClient on palpate::transport, and a C99
# program on the C API, palpate::device) and pkg-config builds (the C++
# library, and the C API from C with palpate-device.pc). Their programs
# run: the library and its dependencies are found at run time. CTest runs
# it in a private network namespace (the ToolClient and the C program join
# DDS on loopback).
# Usage: install_test.sh BUILD_DIR SOURCE_DIR WORK_DIR
set -eu
build=$1 source=$2 work=$3
interfaces=$(ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
if [ "$interfaces" != "lo " ]; then
  echo "install_test: refusing to start DDS outside a private network namespace (interfaces: $interfaces)" >&2
  exit 1
fi
rm -rf "$work"
mkdir -p "$work"
prefix=$work/prefix

cmake --install "$build" --prefix "$prefix" >"$work/install.log"
for f in bin/palpated bin/palpate-precompute bin/palpate-client bin/palpate-pliers \
         include/palpate/core/error.hpp include/palpate/idl/palpate.h include/palpate/device.h \
         lib/libpalpate_device.so lib/cmake/palpate/palpateConfig.cmake lib/pkgconfig/palpate.pc \
         lib/pkgconfig/palpate-device.pc; do
  [ -e "$prefix/$f" ] || { echo "install_test: $f was not installed" >&2; exit 1; }
done
if find "$prefix/include" -path '*/detail/*' | grep -q .; then
  echo "install_test: internal headers were installed:" >&2
  find "$prefix/include" -path '*/detail/*' >&2
  exit 1
fi
"$prefix/bin/palpated" --version

# The CMake consumer, every public header in a unit of its own.
cp -r "$source/tests/install/consumer" "$work/consumer"
# README's first client, exactly as README has it (the block after
# <!-- first-client -->), built below with the consumer at CMake's defaults.
awk '/^<!-- first-client -->$/ { take = 1; next }
     take && /^```cpp$/ { inside = 1; next }
     inside && /^```$/ { exit }
     inside { print }' "$source/README.md" >"$work/consumer/first_client.cpp"
[ -s "$work/consumer/first_client.cpp" ] || {
  echo "install_test: README has no <!-- first-client --> block" >&2
  exit 1
}
mkdir -p "$work/consumer-build/headers"
i=0
for h in $(cd "$prefix/include" && find palpate -name '*.hpp' | sort); do
  i=$((i + 1))
  printf '#include "%s"\n' "$h" >"$work/consumer-build/headers/header_$i.cpp"
done
echo "install_test: $i public headers"
cmake -S "$work/consumer" -B "$work/consumer-build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$prefix" >"$work/consumer-configure.log"
cmake --build "$work/consumer-build" -j2 >"$work/consumer-build.log" 2>&1 || {
  cat "$work/consumer-build.log" >&2
  exit 1
}
"$work/consumer-build/consumer"
"$work/consumer-build/device_client"
"$work/consumer-build/device_c"

# The first client against a real palpated started just before it, twenty
# times in a row, each a new process: its first request is not lost to
# discovery (issue 35), and it prints what README says.
"$prefix/bin/palpate-precompute" -q make-sample -o "$work/organ.msh"
"$prefix/bin/palpate-precompute" -q -j "$source/config/sample-organ.toml" --mesh "$work/organ.msh" \
  --no-xdmf -o "$work/organ.h5"
"$prefix/bin/palpated" --model organ="$work/organ.h5" >"$work/palpated.log" 2>&1 &
palpated_pid=$!
trap 'kill "$palpated_pid" 2>/dev/null || true' EXIT
for run in $(seq 20); do
  out=$("$work/consumer-build/first_client") || {
    echo "install_test: README's first client failed on run $run: $out" >&2
    cat "$work/palpated.log" >&2
    exit 1
  }
  case $out in
    "ok: vertex "*" moved ("*") m") ;;
    *) echo "install_test: README's first client printed '$out' on run $run" >&2; exit 1 ;;
  esac
done
echo "install_test: README's first client, 20 runs: $out"
kill "$palpated_pid"
wait "$palpated_pid" 2>/dev/null || true
trap - EXIT

# pkg-config, for builds without CMake.
PKG_CONFIG_PATH=$prefix/lib/pkgconfig
export PKG_CONFIG_PATH
# shellcheck disable=SC2046
c++ -std=c++20 -o "$work/consumer-pkgconfig" "$work/consumer/main.cpp" $(pkg-config --cflags --libs palpate)
LD_LIBRARY_PATH=$prefix/lib "$work/consumer-pkgconfig"
# The C API from plain C: its header alone, strict C99, then a program.
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Wpedantic -Werror -o "$work/device-c-pkgconfig" \
  "$work/consumer/device_c.c" $(pkg-config --cflags --libs palpate-device)
LD_LIBRARY_PATH=$prefix/lib "$work/device-c-pkgconfig"
echo "install_test: installed, found by CMake and pkg-config, programs run"
