#!/bin/bash
# Run a command that must succeed and check its combined stdout+stderr:
#   run_check.sh [--forbid REGEX]... [--require REGEX]... -- <command...>
# Passes only if the exit code is 0, no line of the output matches any --forbid regex and
# every --require regex matches some line (extended regexes, case-insensitive).
set -u
forbid=()
require=()
while [ $# -gt 0 ]; do
  case "$1" in
    --forbid) forbid+=("$2"); shift 2 ;;
    --require) require+=("$2"); shift 2 ;;
    --) shift; break ;;
    *) echo "usage: $0 [--forbid REGEX]... [--require REGEX]... -- <command...>" >&2; exit 2 ;;
  esac
done
if [ $# -eq 0 ]; then
  echo "usage: $0 [--forbid REGEX]... [--require REGEX]... -- <command...>" >&2
  exit 2
fi

tmp=$(mktemp -d "${TMPDIR:-/tmp}/run_check.XXXXXX") || exit 2
trap 'rm -rf "$tmp"' EXIT

echo "+ $*"
"$@" >"$tmp/out" 2>&1 </dev/null
rc=$?
echo "--- exit code: $rc"
echo "--- stdout+stderr:"; cat "$tmp/out"
echo "---"

fail=0
if [ "$rc" -ne 0 ]; then
  echo "FAIL: exit code $rc (expected 0)"
  fail=1
fi
for re in "${forbid[@]+"${forbid[@]}"}"; do
  if grep -Eqi -- "$re" "$tmp/out"; then
    echo "FAIL: output matches forbidden /$re/:"
    grep -Ei -- "$re" "$tmp/out" | head -n 20
    fail=1
  fi
done
for re in "${require[@]+"${require[@]}"}"; do
  if ! grep -Eqi -- "$re" "$tmp/out"; then
    echo "FAIL: output does not match required /$re/"
    fail=1
  fi
done
[ "$fail" -eq 0 ] && echo "PASS"
exit "$fail"
