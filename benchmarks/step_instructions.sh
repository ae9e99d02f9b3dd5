#!/bin/bash
# Instructions per 3-DOF theta step, library against the hand-written loop of bench_step.cpp, both
# reference cases, counted by callgrind inside CountedSteps* only (set-up and warm-up excluded), with
# the ratio and whether it meets issue 10's target (<= 1.5).
# Usage: benchmarks/step_instructions.sh [build dir, default build] [steps, default 20000]
# Needs valgrind (a measuring tool, not a project dependency).
set -euo pipefail
bench=${1:-build}/squeal_bench
steps=${2:-20000}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
count() { # case variant -> instructions per step
  valgrind --tool=callgrind --toggle-collect='*CountedSteps*' --callgrind-out-file="$out/cg" "$bench" --instr "$1" "$2" "$steps" \
    > "$out/log" 2> /dev/null
  awk -v n="$steps" '/^(summary|totals):/ { s = $2 } END { printf "%.0f", s / n }' "$out/cg"
}
for c in 1 2; do
  lib=$(count $c library)
  min=$(count $c minimal)
  awk -v c=$c -v l=$lib -v m=$min 'BEGIN { printf "3-DOF case %d: library %d instructions/step, hand-written %d, ratio %.2f (%s)\n", c, l, m, l / m,
                                              l <= 1.5 * m ? "meets <= 1.5" : "above 1.5: issue 10 target missed" }'
done
