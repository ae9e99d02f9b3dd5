#!/bin/bash
# The whole nonlinear pipeline on the 2625-DOF pad (issue 8, item 5 and the 2-minute target):
# Craig-Bampton reduction to 542 DOFs, stability, energy estimate, shooting (pre-periods from the
# estimate, Newton on GMRES with exact tangent products) and Floquet multipliers, as the scene
# examples/pad/pad_cycle.yaml runs them. Prints the wall time and peak memory of the run, the
# PETSc stage and event times of each part, the Newton iterations and tangent integrations, the
# cycle's period and the multipliers' verdict, with the load average before and after (on a
# shared machine compare only runs taken under the same load; the user CPU time is printed too).
#   bash benchmarks/pad_cycle.sh [BUILD_DIR (build)] [extra squeal options...]
#   SCENE=pad_large_cycle.yaml bash benchmarks/pad_cycle.sh   (the 31119-DOF pad: ~3-4 min, 2.1 GB)
#   RANKS=2 bash benchmarks/pad_cycle.sh   (under mpiexec: the reduction and shooting's blocks of tangent
#   columns and preconditioner products shared; times are rank 0's, CPU time that of all ranks)
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$here/build}
[ $# -gt 0 ] && shift
squeal=$build/squeal
[ -x "$squeal" ] || { echo "no squeal binary at $squeal: build first or give the build directory" >&2; exit 2; }
scene=${SCENE:-pad_cycle.yaml}
tmp=$(mktemp -d /tmp/pad_cycle.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

ranks=${RANKS:-1}
launch=()
[ "$ranks" -gt 1 ] && launch=(mpiexec -n "$ranks" --mca mpi_yield_when_idle 1)
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
/usr/bin/time -f "%e %U %M" -o "$tmp/time" "${launch[@]}" "$squeal" -scene "$here/examples/pad/$scene" -output "$tmp/out.h5" \
  -log_view ":$tmp/log" "$@" > "$tmp/out" 2>&1 || { echo "FAILED:" >&2; tail -5 "$tmp/out" >&2; exit 1; }
read -r wall user rss < "$tmp/time"
echo "$scene, reduction + stability + energy + shooting + Floquet, $ranks rank(s): wall $wall s (user CPU $user s), peak RSS $((rss / 1024)) MB"
grep -A1 "Craig-Bampton reduction" "$tmp/out" | sed 's/^/  /'
sed -n '/Summary of Stages/,/^---/p' "$tmp/log" |
  sed -n 's/^ *[0-9]*: *\(.*\): \([0-9.e+-]*\) .*/\1 \2/p' |
  awk '{t = $NF; $NF = ""; if (t > 0.005) printf "  stage %-18s %9.2f s\n", $0, t}'
# Events inside the Shooting stage: pre-periods, Newton (SNESSolve), Floquet, the integrations, and
# the linear preconditioner (its monodromy and factor).
awk '/^(ShootPrePeriods|SNESSolve|ShootFloquet|ShootTangentFlow|ShootFlow|ShootLinearPC) +[0-9]/ {printf "  event %-18s %9.2f s  (%d calls)\n", $1, $4, $2}' "$tmp/log"
grep -E "^shooting: (start|converged)|limit cycle period|Floquet multipliers|power balance" "$tmp/out" | sed 's/^/  /'
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
