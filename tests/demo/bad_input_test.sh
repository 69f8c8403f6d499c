#!/bin/sh
# scripts/demo.sh with a mesh that does not exist says so at once, before it
# installs or builds anything (issue 35: it installed and built first).
#   bad_input_test.sh SOURCE_DIR
set -u
interfaces=$(ip -o link show | awk -F': ' '{print $2}' | tr '\n' ' ')
if [ "$interfaces" != "lo " ]; then
  echo "bad_input_test: refusing to run the demo outside a private network namespace (interfaces: $interfaces)" >&2
  exit 1
fi
out=$(cd "$1" && scripts/demo.sh /nonexistent/liver.msh 2>&1)
code=$?
fail() { echo "bad_input_test: $1"; echo "--- demo.sh said:"; echo "$out"; exit 1; }
[ "$code" -eq 2 ] || fail "exit code $code, expected 2"
echo "$out" | grep -q "demo: /nonexistent/liver.msh: no such file" || fail "no 'no such file' line"
echo "$out" | grep -q "install-deps" && fail "it ran the install first"
[ "$(echo "$out" | wc -l)" -eq 1 ] || fail "more than the one line"
echo "bad_input_test: one line, exit 2, nothing installed or built"
