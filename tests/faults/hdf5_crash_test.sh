#!/bin/sh
# A compliance file that crashes Debian's libhdf5 (fuzz/reproducers/libhdf5,
# docs/fuzzing.md) is refused by palpated with one message and exit 2, not a
# segmentation fault: the file is read first in a child process.
# Usage: hdf5_crash_test.sh PALPATED REPRODUCER.h5   (no DDS: --check-config)
set -u
# Under the ASan build (scripts/sanitize.sh), let the child die by the signal
# as a Release build does, instead of ASan's SEGV report and exit 1.
out=$(ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}handle_segv=0" "$1" --check-config -m crash="$2" 2>&1)
rc=$?
echo "$out"
[ "$rc" -eq 2 ] || { echo "FAIL: exit $rc, expected 2"; exit 1; }
[ "$(printf '%s\n' "$out" | wc -l)" -eq 1 ] || { echo "FAIL: expected one line"; exit 1; }
case "$out" in
  *"the HDF5 library crashed reading it (signal 11)"*"precompute it again"*) echo PASS ;;
  *) echo "FAIL: message does not say the file crashed the reader"; exit 1 ;;
esac
