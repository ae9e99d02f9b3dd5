#!/bin/bash
# `squeal ... | head` (issue 20, hidden .part files left behind): the reader of standard output
# goes away, squeal gets SIGPIPE; it must stop like SIGTERM, with its results file under its name
# (status "interrupted (SIGPIPE) ..."), exit 1, no PETSc traceback and no temporary left.
#   check_broken_pipe.sh OUT.h5 -- squeal args... (args must print many lines)
set -u
out=$1; shift 2
dir=$(dirname "$out"); base=$(basename "$out")
rm -f "$out" "$dir/.$base.part-"*
tmp=$(mktemp) || exit 2
trap 'rm -f "$tmp"' EXIT
echo "+ $* | head -3"
"$@" 2>"$tmp" | head -3
rc=${PIPESTATUS[0]}
echo "--- exit code: $rc"; echo "--- stderr:"; cat "$tmp"; echo "---"
bad=0
check() { if eval "$1"; then echo "ok:   $2"; else echo "FAIL: $2"; bad=1; fi; }
check '[ "$rc" = 1 ]' "exit code 1"
check '! grep -q "PETSC ERROR" "$tmp"' "no PETSc traceback"
check 'grep -q "^squeal: error: interrupted by SIGPIPE" "$tmp"' "stderr says 'interrupted by SIGPIPE'"
check '! ls "$dir/.$base.part-"* >/dev/null 2>&1' "no temporary .$base.part-* left"
check '/usr/bin/python3 -c "import h5py,sys; s=h5py.File(sys.argv[1],\"r\").attrs[\"status\"]; s=s.decode() if isinstance(s,bytes) else s; print(s); sys.exit(not s.startswith(\"interrupted (SIGPIPE)\"))" "$out"' \
  "$base readable, status 'interrupted (SIGPIPE) ...'"
[ $bad = 0 ] && echo PASS || echo FAILED
exit $bad
