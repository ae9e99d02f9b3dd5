#!/bin/bash
# Issue 18 item 4: the reduced brake's limit cycle against a transient of the FULL model.
#   brake_cycle_vs_full.sh SQUEAL SCENE CCX_JOB OUT_DIR [reduction options...]
# Shooting on the half brake reduced by Craig-Bampton at 90 kHz (mu = 0.15, V = 1 m/s: one unstable
# mode, 8 297 Hz, nothing else up to 60 kHz; the rest from the model's defaults), its cycle expanded to all 3 600 DOFs (/expanded/orbit); then the
# unreduced model's transient from its own unstable mode at the energy estimate's amplitude, 400
# periods at the cycle's step; check_pad_cycle.py --expanded compares them on every DOF: period
# within 2e-3 and peak-to-peak within 10 % of the largest (measured 2026-11-29: 1.16e-4 and 0.34 %,
# 4 Newton iterations, docs/fe-workflow.md). About 2 minutes of one core. Every 8th step recorded
# (25 records a period): 0.6 GB of file instead of 1.2 GB at every 4th, and the same comparison
# (2026-11-30: 1.16e-4 and 0.30 %).
set -euo pipefail
squeal=$1 scene=$2 job=$3 out=$4
shift 4
reduce=(-reduce_type craig_bampton -reduce_fmax 90000 "$@")
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
rm -f "$out/cycle.h5" "$out/full_transient.h5"
op=(-scene "$scene" -model_ccx_job "$job" -contact_mu 0.15 -contact_v 1)
"$squeal" "${op[@]}" -analyses stability,energy,shooting "${reduce[@]}" \
  -shoot_ksp_max_it 600 -floquet_nev 4 -output "$out/cycle.h5" | grep -E "^shooting:|limit cycle|Craig-Bampton|interface reduction|expansion"
read -r h q0 < <(/usr/bin/python3 -c "import h5py, sys; f = h5py.File(sys.argv[1], 'r'); s = f['shooting']
print(s['period'][()] / s.attrs['steps_per_period'], f['energy'].attrs['q0'])" "$out/cycle.h5")
"$squeal" "${op[@]}" -analyses stability,transient -transient_periods 400 -transient_h "$h" -transient_keep_every 8 \
  -transient_amplitude "$q0" -output "$out/full_transient.h5" | grep -E "^transient:|settled"
exec /usr/bin/python3 "$here/check_pad_cycle.py" --expanded --shooting "$out/cycle.h5" --output "$out/full_transient.h5" \
  --period-tol 2e-3 --ptp-tol 0.1 --max-return 2e-2 --max-iterations 10
