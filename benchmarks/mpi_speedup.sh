#!/bin/bash
# 1 rank against 2 ranks, back to back, on the four parts issue 10 asks to pay under MPI:
#   (a) the Craig-Bampton reduction of the 31119-DOF pad (pad_large.yaml, -reduce_fmax FMAX),
#       time = the four CB stages of -log_view (model generation and start-up excluded), and the
#       CPU time of the busiest rank per CB stage as the reduction prints it (the load-independent
#       measure; the run's cpu2max also counts the stability analysis of the reduced model);
#   (b) the stability analysis of the full 31119-DOF pad (the STAB_NEV eigenvalues nearest 0, no
#       band certificate), time = stages Equilibrium + Stability (two MUMPS LU factorisations of
#       ~30 000 unknowns, 2.35e10 flops each for the stability one);
#   (c) a transient of the chain of CHAIN_CELLS 3-DOF cells (N = 3 x CHAIN_CELLS, a contact every
#       100 cells), STEPS steps on the sparse back end, time = stage Transient (its set-up,
#       factorisation and Delassus matrix included; the stability run it starts from is not);
#   (d) the stability map over mu and V of the 468-DOF pad (pad_small.yaml, SWEEP_MU x SWEEP_V
#       points): each rank solves its own points on its own copy of the model (PETSC_COMM_SELF),
#       time = stage Sweep.
# Per item: the stage time on 1 and on 2 ranks (-log_view, average over ranks), the wall time of
# the whole run, the CPU time summed over the ranks (/usr/bin/time: user + sys), the speed-up of
# the stage, and the load average before and after. On a shared machine the 2-rank run is slowed
# far more than the 1-rank run (each rank waits for the other's time slices): compare the CPU
# times (load-independent to first order) and only quote a speed-up taken at a load below ~0.5.
#   bash benchmarks/mpi_speedup.sh [BUILD_DIR (build)] [items (abcd)]
# Environment: FMAX (10000), STAB_NEV (4), CHAIN_CELLS (10000), STEPS (300), SWEEP_MU (24), SWEEP_V (4),
#   MPIEXEC_EXTRA (mpiexec options; default "--mca mpi_yield_when_idle 1": a waiting rank gives its
#   core away instead of polling, which made the loaded 2-rank transient 2.7x faster; "" to drop it),
#   KEEP=1 keeps the logs.
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$here/build}
items=${2:-abcd}
squeal=$build/squeal
[ -x "$squeal" ] || { echo "no squeal binary at $squeal: build first or give the build directory" >&2; exit 2; }
fmax=${FMAX:-10000}
nev=${STAB_NEV:-4}
cells=${CHAIN_CELLS:-10000}
steps=${STEPS:-300}
smu=${SWEEP_MU:-24}
extra=${MPIEXEC_EXTRA---mca mpi_yield_when_idle 1}
sv=${SWEEP_V:-4}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
tmp=$(mktemp -d /tmp/mpi_speedup.XXXXXX)
if [ "${KEEP:-0}" = 1 ]; then echo "logs kept in $tmp"; else trap 'rm -rf "$tmp"' EXIT; fi

load() { cut -d' ' -f1 /proc/loadavg; }

# run NP TAG OPTIONS...: squeal on NP ranks with -log_view; sets wall, cpu.
run() {
  local np=$1 tag=$2
  shift 2
  # Each rank under its own /usr/bin/time (appending one line each): the CPU time of the busiest rank.
  local cmd=(/usr/bin/time -a -f "%U %S" -o "$tmp/$tag.ranks" "$squeal" -output "$tmp/$tag.h5" -log_view ":$tmp/$tag.log" "$@")
  rm -f "$tmp/$tag.ranks"
  # shellcheck disable=SC2086
  [ "$np" -gt 1 ] && cmd=(mpiexec --oversubscribe $extra -n "$np" "${cmd[@]}")
  if ! /usr/bin/time -f "%e %U %S" -o "$tmp/$tag.time" "${cmd[@]}" > "$tmp/$tag.out" 2>&1; then
    echo "FAILED: ${cmd[*]}" >&2
    tail -5 "$tmp/$tag.out" >&2
    return 1
  fi
  read -r wall user sys < "$tmp/$tag.time"
  cpu=$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')
  rankcpu=$(awk '{ t = $1 + $2; if (t > m) m = t } END { printf "%.2f", m }' "$tmp/$tag.ranks")
}

# stage_sum TAG REGEX: sum of the -log_view times (average over ranks) of the stages matching REGEX.
stage_sum() {
  sed -n '/Summary of Stages/,/^---/p' "$tmp/$1.log" |
    sed -n 's/^ *[0-9]*: *\(.*\): \([0-9.e+-]*\) .*/\1|\2/p' |
    awk -F'|' -v re="$2" '$1 ~ re { t += $2 } END { printf "%.2f", t }'
}

printf "%-44s %8s %8s %7s %7s %7s %7s %7s %7s %6s %11s\n" "item" "stage1" "stage2" "speedup" "wall1" "wall2" "cpu1" "cpu2" \
  "cpu2max" "work" "load"
# item NAME STAGE_REGEX OPTIONS...: the same run on 1 then 2 ranks.
item() {
  local name=$1 re=$2 tag
  shift 2
  tag=$(tr -c 'a-zA-Z0-9\n' _ <<< "$name")
  local l0 s1 s2 w1 w2 c1 c2 m2
  l0=$(load)
  run 1 "${tag}_1" "$@" || return
  s1=$(stage_sum "${tag}_1" "$re") w1=$wall c1=$cpu
  run 2 "${tag}_2" "$@" || return
  s2=$(stage_sum "${tag}_2" "$re") w2=$wall c2=$cpu m2=$rankcpu
  printf "%-44s %8s %8s %7s %7s %7s %7s %7s %7s %6s %5s-%-5s\n" "$name" "$s1" "$s2" \
    "$(awk -v a="$s1" -v b="$s2" 'BEGIN { printf "%.2f", (b > 0 ? a / b : 0) }')" "$w1" "$w2" "$c1" "$c2" "$m2" \
    "$(awk -v a="$c1" -v b="$m2" 'BEGIN { printf "%.2f", (a > 0 ? b / a : 0) }')" "$l0" "$(load)"
  # The CB reduction prints the CPU time of its busiest rank per stage: the same ratio per stage.
  local r1 r2
  r1=$(sed -n 's/.*CPU time of the busiest rank: //p' "$tmp/${tag}_1.out")
  r2=$(sed -n 's/.*CPU time of the busiest rank: //p' "$tmp/${tag}_2.out")
  [ -n "$r1" ] && [ -n "$r2" ] && echo "    CB CPU of the busiest rank, total (factor, modes, constraint, project): 1 rank $r1; 2 ranks $r2;" \
    "ratio $(awk -v a="${r1%% s*}" -v b="${r2%% s*}" 'BEGIN { printf "%.2f", (b > 0 ? a / b : 0) }')"
  return 0
}

case $items in *a*)
  item "(a) reduction 31119-DOF pad, fmax $fmax" "^CB " -scene "$here/examples/pad/pad_large.yaml" \
    -reduce_type craig_bampton -reduce_fmax "$fmax" -analyses stability -stab_pep_nev 2 -stab_fmax 0 ;;
esac
case $items in *b*)
  item "(b) stability 31119-DOF pad, nev $nev" "^(Equilibrium|Stability)$" -scene "$here/examples/pad/pad_large.yaml" \
    -analyses stability -stab_fmax 0 -stab_pep_nev "$nev" ;;
esac
case $items in *c*)
  item "(c) transient chain N = $((3 * cells)), $steps steps" "^Transient$" -model_type chain -model_cells "$cells" \
    -model_contact_every 100 -analyses transient -transient_periods 1 -transient_steps_per_period "$steps" -stab_fmax 0 ;;
esac
case $items in *d*)
  item "(d) sweep 468-DOF pad, $smu x $sv points" "^Sweep$" -scene "$here/examples/pad/pad_small.yaml" \
    -analyses sweep -sweep_mu_n "$smu" -sweep_v_min 5 -sweep_v_max 20 -sweep_v_n "$sv" -stab_fmax 0 ;;
esac
echo "stage: -log_view stage time (s, average over ranks); wall: whole run (s); cpu: user + sys summed over ranks (s);"
echo "cpu2max: the busiest rank's CPU time (s); work = cpu2max / cpu1, the share of the 1-rank work the busiest rank"
echo "did (start-up included; a rank that polls while waiting counts that too): on a quiet machine the speed-up is"
echo "about 1 / work; load: 1-minute load average before item - after it (2 cores)"
