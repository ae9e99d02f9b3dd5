#!/bin/bash
# Run a command that must fail on bad input, the way squeal reports errors:
#   expect_error.sh <regex> -- <command...>
# Passes only if ALL of these hold:
#   - the exit code is not 0 (and the process was not killed by a signal: code < 128);
#   - stderr has exactly one line starting with "squeal: error:";
#   - that line matches <regex> (extended regex, case-insensitive);
#   - stderr has no PETSc error traceback ("PETSC ERROR").
# stdout and stderr of the command are echoed for ctest --output-on-failure.
set -u
if [ $# -lt 3 ] || [ "$2" != "--" ]; then
  echo "usage: $0 <regex> -- <command...>" >&2
  exit 2
fi
regex=$1
shift 2

tmp=$(mktemp -d "${TMPDIR:-/tmp}/expect_error.XXXXXX") || exit 2
trap 'rm -rf "$tmp"' EXIT

echo "+ $*"
"$@" >"$tmp/out" 2>"$tmp/err" </dev/null
rc=$?
echo "--- exit code: $rc"
echo "--- stdout:"; cat "$tmp/out"
echo "--- stderr:"; cat "$tmp/err"
echo "---"

fail=0
if [ "$rc" -eq 0 ]; then
  echo "FAIL: exit code 0 on bad input (expected non-zero)"
  fail=1
elif [ "$rc" -ge 128 ]; then
  echo "FAIL: exit code $rc: killed by a signal / crashed (expected a clean non-zero exit)"
  fail=1
fi

nerr=$(grep -c '^squeal: error:' "$tmp/err")
if [ "$nerr" -ne 1 ]; then
  echo "FAIL: stderr has $nerr line(s) starting with 'squeal: error:' (expected exactly 1)"
  fail=1
fi
if [ "$nerr" -ge 1 ]; then
  line=$(grep '^squeal: error:' "$tmp/err" | head -n 1)
  if ! printf '%s\n' "$line" | grep -Eqi -- "$regex"; then
    echo "FAIL: error line does not match /$regex/: $line"
    fail=1
  fi
fi
if grep -q 'PETSC ERROR' "$tmp/err"; then
  echo "FAIL: stderr has a PETSc error traceback (expected one squeal: error: line)"
  fail=1
fi

if [ "$fail" -eq 0 ]; then
  echo "PASS: exit code $rc, error line matches /$regex/"
fi
exit "$fail"
