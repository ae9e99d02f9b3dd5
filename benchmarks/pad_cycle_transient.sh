#!/bin/bash
# A pad's limit cycle by shooting against a long transient of the same reduced model (issue 8,
# item 5: period to 1e-4, peak-to-peak to 1e-2), as two runs of one scene: the scene's own
# pipeline (stability, energy, shooting, Floquet), then stability + transient from the unstable
# mode at amplitude AMPLITUDE with the shooting cycle's step h = T / (shooting steps), checked by
# tests/scenes/check_pad_cycle.py (--shooting FILE). The transient starts from the linear mode,
# not from the shooting solution, so the two are independent routes to the cycle.
#   bash benchmarks/pad_cycle_transient.sh [BUILD_DIR (build)] [SCENE (pad_large_cycle.yaml)]
# Environment: PERIODS (320 periods of the unstable mode), AMPLITUDE (4e-6 m), KEEP_EVERY (4),
#   SHOOTING=FILE reuses the results of an earlier run of the scene instead of running it,
#   OUT (a new directory under /tmp) keeps the files, ARGS (options for both runs), SHOOT_ARGS
#   (for the shooting run only), CHECK_ARGS (for check_pad_cycle.py).
# Reduced cycle against the FULL model (issue 18 item 4): give the reduction in SHOOT_ARGS only
# (it keeps its expansion by default for a model with a mesh; -reduce_expand 1 otherwise) and add --expanded to
# CHECK_ARGS: the transient then runs on the unreduced model, and the check on its DOFs, e.g.
#   ARGS="-model_ccx_job build/brake-0.5/brake -contact_mu 0.15 -contact_v 1" \
#   SHOOT_ARGS="-analyses stability,energy,shooting -reduce_type craig_bampton -reduce_fmax 60000" CHECK_ARGS="--expanded" \
#   bash benchmarks/pad_cycle_transient.sh build ../brake/brake.yaml
# The 31119-DOF pad takes ~14 min for the scene and ~45 min of one core for 320 periods (63 270 steps).
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$here/build}
scene=$here/examples/pad/${2:-pad_large_cycle.yaml}
squeal=$build/squeal
[ -x "$squeal" ] || { echo "no squeal binary at $squeal: build first or give the build directory" >&2; exit 2; }
[ -f "$scene" ] || { echo "no scene $scene" >&2; exit 2; }
out=${OUT:-$(mktemp -d /tmp/pad_cycle_transient.XXXXXX)}
mkdir -p "$out"
echo "results in $out; load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
shoot=${SHOOTING:-$out/shooting.h5}
if [ -z "${SHOOTING:-}" ]; then
  # shellcheck disable=SC2086 # ARGS and SHOOT_ARGS are option lists
  /usr/bin/time -f "%e %U %M" -o "$out/shooting.time" "$squeal" -scene "$scene" ${ARGS:-} ${SHOOT_ARGS:-} -output "$shoot" > "$out/shooting.out" 2>&1 ||
    { echo "the scene's run FAILED:" >&2; tail -5 "$out/shooting.out" >&2; exit 1; }
  read -r wall user rss < "$out/shooting.time"
  echo "scene: wall $wall s (user CPU $user s), peak RSS $((rss / 1024)) MB"
fi
# The transient's step is the shooting cycle's: T / steps.
h=$(/usr/bin/python3 -c "import h5py, sys; f = h5py.File(sys.argv[1], 'r'); print(f['shooting/period'][()] / f['shooting'].attrs['steps_per_period'])" "$shoot") ||
  { echo "no shooting solution in $shoot" >&2; exit 1; }
# shellcheck disable=SC2086
/usr/bin/time -f "%e %U %M" -o "$out/transient.time" "$squeal" -scene "$scene" ${ARGS:-} -analyses stability,transient \
  -transient_periods "${PERIODS:-320}" -transient_h "$h" -transient_keep_every "${KEEP_EVERY:-4}" \
  -transient_amplitude "${AMPLITUDE:-4e-6}" -output "$out/transient.h5" > "$out/transient.out" 2>&1 ||
  { echo "the transient FAILED:" >&2; tail -5 "$out/transient.out" >&2; exit 1; }
read -r wall user rss < "$out/transient.time"
echo "transient (h = $h s): wall $wall s (user CPU $user s), peak RSS $((rss / 1024)) MB"
grep -E "^transient:|settled|not settled" "$out/transient.out" | sed 's/^/  /'
# shellcheck disable=SC2086
/usr/bin/python3 "$here/tests/scenes/check_pad_cycle.py" ${CHECK_ARGS:-} --shooting "$shoot" --output "$out/transient.h5"
rc=$?
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
exit $rc
