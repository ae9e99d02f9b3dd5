#!/bin/bash
# Instructions per step of a whole 3-DOF transient run (`squeal -analyses transient`, records,
# energy bookkeeping, cycle summary and results file included) against the hand-written loop of
# bench_step.cpp over the same steps, counted by callgrind: the run of P2 periods minus the run
# of P1 periods, over the (P2 - P1) x 1000 steps between them (set-up, eigenanalysis and file
# creation cancel); the hand loop warmed up over P1 x 1000 uncounted steps from the same start.
# Usage: benchmarks/transient_instructions.sh [build dir, default build] [case 1|2, default 1]
#        [P1, default 10] [P2, default 20] [extra squeal options, e.g. -transient_keep_every 10]
# Needs valgrind (a measuring tool, not a project dependency).
set -euo pipefail
build=$(cd "${1:-build}" && pwd)
c=${2:-1}
p1=${3:-10}
p2=${4:-20}
shift $(($# < 4 ? $# : 4))
root=$(cd "$(dirname "$0")/.." && pwd)
scene=$root/examples/three_dof/$([ "$c" = 2 ] && echo case2_stick_slip.yaml || echo case1_separation_slip.yaml)
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
total() { awk '/^(summary|totals):/ { s = $2 } END { printf "%.0f", s }' "$1"; }
run() { # periods [options] -> total instructions of the whole run
  local p=$1
  shift
  (cd "$out" && valgrind --tool=callgrind --callgrind-out-file="$out/cg$p" "$build/squeal" -scene "$scene" -analyses transient \
    -transient_periods "$p" -output "$out/t$p.h5" "$@" > "$out/log$p" 2>&1)
  total "$out/cg$p"
}
steps=$(((p2 - p1) * 1000))
a=$(run "$p1" "$@")
b=$(run "$p2" "$@")
valgrind --tool=callgrind --toggle-collect='*CountedSteps*' --callgrind-out-file="$out/cgm" "$build/squeal_bench" --instr "$c" minimal \
  "$steps" "$((p1 * 1000))" > /dev/null 2>&1
m=$(total "$out/cgm")
awk -v c="$c" -v a="$a" -v b="$b" -v m="$m" -v n="$steps" -v o="$*" 'BEGIN {
  t = (b - a) / n; h = m / n
  printf "3-DOF case %d transient%s%s: %.0f instructions/step, hand-written loop %.0f, ratio %.2f (%s)\n", c, o == "" ? "" : " ", o, t, h,
         t / h, t <= 1.5 * h ? "meets <= 1.5" : "above 1.5" }'
