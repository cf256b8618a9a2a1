#!/usr/bin/env bash
# Every C and C++ file of the tree (what git tracks, and new files it does
# not ignore, so a file is checked before its first commit) is as
# clang-format (14, Debian 12's) and .clang-format write it. Prints each file
# that is not, with the first lines that differ, and exits 1; `scripts/check-format.sh --fix` rewrites them.
# Outside CI, a machine without clang-format skips with a message; under
# CI=true its absence is a failure.
set -euo pipefail
cd "$(dirname "$0")/.."
format=""
for candidate in clang-format-14 clang-format; do
  command -v "$candidate" >/dev/null && { format=$candidate; break; }
done
if [ -z "$format" ]; then
  if [ "${CI:-}" = true ]; then
    echo "check-format: clang-format is not installed (scripts/install-deps.sh installs it)" >&2
    exit 1
  fi
  echo "check-format: SKIPPED: no clang-format on this machine (scripts/install-deps.sh installs it)"
  exit 0
fi
mapfile -t files < <(git ls-files --cached --others --exclude-standard '*.c' '*.cc' '*.cpp' '*.h' |
  grep -v '/node_modules/')
if [ "${1:-}" = --fix ]; then
  "$format" -i "${files[@]}"
  echo "check-format: formatted ${#files[@]} files"
  exit 0
fi
bad=0
for f in "${files[@]}"; do
  if ! out=$("$format" "$f" | diff -u "$f" - 2>&1); then
    bad=$((bad + 1))
    echo "check-format: $f is not formatted (scripts/check-format.sh --fix):"
    echo "$out" | sed -n '3,12p'
  fi
done
echo "check-format: ${#files[@]} files checked with $("$format" --version | sed 's/.*version \([0-9.]*\).*/\1/'), $bad not formatted"
[ "$bad" -eq 0 ]
