#!/usr/bin/env bash
# clang-format (Debian 12's, version 14, with the .clang-format at the root)
# over every C and C++ file the repository tracks.
#   scripts/format.sh           rewrites the files in place
#   scripts/format.sh --check   changes nothing; lists the files that differ
#                               and exits 1 if any does (scripts/test.sh runs it)
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' '*.c' ':!fuzz/corpus' ':!fuzz/reproducers')
if [ "${1:-}" = --check ]; then
  differ=()
  for f in "${files[@]}"; do
    clang-format --dry-run --Werror "$f" >/dev/null 2>&1 || differ+=("$f")
  done
  if [ ${#differ[@]} -gt 0 ]; then
    echo "format: ${#differ[@]} file(s) differ from clang-format (run scripts/format.sh):" >&2
    printf '  %s\n' "${differ[@]}" >&2
    exit 1
  fi
  echo "format: ${#files[@]} files as clang-format writes them"
else
  clang-format -i "${files[@]}"
fi
