#!/bin/bash
# The results package's command line (scripts/squeal_cli.py) on a fresh results file:
#   check_python_package.sh SQUEAL SCENE OUT_PREFIX
# squeal writes OUT_PREFIX.h5 (stability only); `info` names its status, model and the stability
# verdict; `compare` of the file with itself exits 0; a copy with one eigenvalue changed by 1e-6
# (relative) exits 1 naming /stability/eigenvalues, and 0 again with --rtol 1e-3; `plot stability`
# writes its PNG.
set -u
squeal=$1 scene=$2 out=$3
here=$(cd "$(dirname "$0")" && pwd)
py=/usr/bin/python3
cli="$py $here/../../scripts/squeal_cli.py"
fails=0
check() { # check <description> <command...>: ok/FAIL line, counts failures
  local what=$1; shift
  if "$@"; then echo "ok:   $what"; else echo "FAIL: $what"; fails=$((fails + 1)); fi
}
rm -f "$out.h5" "$out.mod.h5" "$out.png"
"$squeal" -scene "$scene" -analyses stability -output "$out.h5" >/dev/null || { echo "FAIL: squeal exited with $?"; exit 1; }

info=$($cli info "$out.h5"); rc=$?
echo "$info"
check "info exits 0" test $rc -eq 0
check "info: status complete" grep -q "^status: complete$" <<<"$info"
check "info: the model" grep -q "^model: three_dof, 3 DOFs, 1 contact point(s)" <<<"$info"
check "info: the stability verdict" grep -Eq "^  stability +UNSTABLE: 1 unstable mode\(s\); most unstable 91\.7 Hz" <<<"$info"

$cli compare "$out.h5" "$out.h5"; check "compare with itself exits 0" test $? -eq 0
cp "$out.h5" "$out.mod.h5"
$py -c "import h5py, sys
with h5py.File(sys.argv[1], 'a') as f:
    f['stability/eigenvalues'][0, 1] *= 1 + 1e-6" "$out.mod.h5"
diff=$($cli compare "$out.h5" "$out.mod.h5"); rc=$?
echo "$diff"
check "compare with a changed copy exits 1" test $rc -eq 1
check "compare names the changed dataset" grep -q "^/stability/eigenvalues: 1 of 4 value(s) differ" <<<"$diff"
$cli compare --rtol 1e-3 "$out.h5" "$out.mod.h5" >/dev/null; check "compare --rtol 1e-3 exits 0" test $? -eq 0
$cli plot stability "$out.h5" -o "$out.png" >/dev/null; check "plot stability writes $out.png" test -s "$out.png"
[ $fails -eq 0 ] && echo PASS || echo "FAILED: $fails check(s)"
exit $((fails > 0))
