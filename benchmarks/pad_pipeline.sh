#!/bin/bash
# Cost of the Craig-Bampton reduction and of the reduced pipeline on the FE pads (issue 8, items 2
# and 5). Prints, back to back:
#   1. the reduction of the 2625-DOF pad (fmax 20 kHz) and of the 31119-DOF pad (FMAX_LARGE) on 1
#      and 2 ranks: time per phase (as squeal prints it), resident memory after the reduction (sum
#      over ranks) and the largest process's peak RSS (/usr/bin/time);
#   2. the pipeline reduction + stability + energy on the reduced large pad (1 rank): -log_view
#      stage times and wall time.
# The load average is printed before and after: on a shared machine, 2-rank runs are slowed far
# more than 1-rank runs (ranks wait for each other's time slices), so compare only runs taken
# under the same load.
#   bash benchmarks/pad_pipeline.sh [BUILD_DIR (build)] [FMAX_LARGE (Hz, 20000)] [what: all|reduce|pipeline]
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$here/build}
fmax_large=${2:-20000}
what=${3:-all}
squeal=$build/squeal
[ -x "$squeal" ] || { echo "no squeal binary at $squeal: build first or give the build directory" >&2; exit 2; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
tmp=$(mktemp -d /tmp/pad_pipeline.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

run() { # np scene fmax tag [extra options...]
  local np=$1 scene=$2 fmax=$3 tag=$4
  shift 4
  local cmd=("$squeal" -scene "$here/examples/pad/$scene" -reduce_type craig_bampton -reduce_fmax "$fmax"
             -output "$tmp/$tag.h5" -log_view ":$tmp/$tag.log" "$@")
  [ "$np" -gt 1 ] && cmd=(mpiexec --oversubscribe --mca mpi_yield_when_idle 1 -n "$np" "${cmd[@]}")
  /usr/bin/time -f "%e %M" -o "$tmp/$tag.time" "${cmd[@]}" > "$tmp/$tag.out" 2>&1 || {
    echo "FAILED: ${cmd[*]}" >&2; tail -5 "$tmp/$tag.out" >&2; return 1; }
}

echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
if [ "$what" = all ] || [ "$what" = reduce ]; then
  printf "%-22s %3s %7s %9s %9s %9s %9s %9s %9s %9s\n" "pad" "np" "N_red" "reduce(s)" "factor" "modes" "constr." \
    "project" "mem(MB)" "maxRSS"
  for spec in "pad.yaml 20000 2625" "pad_large.yaml $fmax_large 31119"; do
    set -- $spec
    for np in 1 2; do
      tag=r_${3}_$np
      run "$np" "$1" "$2" "$tag" -analyses stability -stab_pep_nev 2 || continue
      line=$(grep -A1 "Craig-Bampton reduction" "$tmp/$tag.out" | tr '\n' ' ')
      nred=$(sed -n 's/.*-> \([0-9]*\) (.*/\1/p' <<< "$line")
      num() { sed -n "s/.*$1 \([0-9.]*\) s.*/\1/p" <<< "$line"; }
      mem=$(sed -n 's/.*resident memory \([0-9.]*\) MB.*/\1/p' <<< "$line")
      read -r wall rss < "$tmp/$tag.time"
      printf "%-22s %3s %7s %9s %9s %9s %9s %9s %9s %9.0f\n" "$3 DOFs, fmax $2" "$np" "$nred" \
        "$(sed -n 's/.*time \([0-9.]*\) s (.*/\1/p' <<< "$line")" "$(num 'factorisation of K_II')" \
        "$(num 'fixed-interface modes')" "$(num 'constraint modes')" "$(num 'projection')" "$mem" "$((rss / 1024))"
    done
  done
fi
if [ "$what" = all ] || [ "$what" = pipeline ]; then
  tag=pipe
  if run 1 pad_large.yaml "$fmax_large" "$tag" -analyses stability,energy; then
    read -r wall rss < "$tmp/$tag.time"
    echo "pipeline reduction + stability + energy, 31119-DOF pad, fmax $fmax_large Hz, 1 rank: wall $wall s, peak RSS $((rss / 1024)) MB"
    grep -A1 "Craig-Bampton reduction" "$tmp/$tag.out"
    # Stage times: the reduction's phases run inside model creation (Main Stage holds the rest).
    sed -n '/Summary of Stages/,/^---/p' "$tmp/$tag.log" |
      sed -n 's/^ *[0-9]*: *\(.*\): \([0-9.e+-]*\) .*/\1 \2/p' |
      awk '{t = $NF; $NF = ""; printf "  stage %-18s %9.2f s\n", $0, t}'
    grep -E "^energy|limit cycle|amplitude|balance" "$tmp/$tag.out" | head -6 | sed 's/^/  /'
  fi
fi
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
