#!/bin/bash
# The full model started on a reduced cycle (-transient_start on /expanded/Z0, the cycle's start
# expanded to every DOF), against that cycle:
#   brake_full_from_cycle.sh SQUEAL SCENE CCX_JOB CYCLE_H5 OUT_H5
# CYCLE_H5 is scenes_brake_half_cycle_vs_full's (CB 90 kHz, mu = 0.15, V = 1 m/s). 50 periods of the
# unreduced 3 600-DOF model at the cycle's step; check_pad_cycle.py --expanded then compares its last
# cycles with the reduced cycle on every DOF. Where the full model has a cycle near the reduced one,
# the run starts on it, so 50 periods say what the 400 from the mode (brake_cycle_vs_full.sh) say,
# in a tenth of the time. Measured 2026-11-30: period 9.1e-5, peak-to-peak 2.3e-3 of the largest
# (from the mode: 1.2e-4 and 3.4e-3), 12 s. Every other step recorded (100 records a period): 0.3 GB
# of file instead of 0.6 GB, and the same comparison (9.1e-5 and 2.2e-3).
set -euo pipefail
squeal=$1 scene=$2 job=$3 cycle=$4 out=$5
here=$(cd "$(dirname "$0")" && pwd)
h=$(/usr/bin/python3 -c "import h5py, sys; s = h5py.File(sys.argv[1], 'r')['shooting']
print(repr(s['period'][()] / s.attrs['steps_per_period']))" "$cycle")
rm -f "$out"
"$squeal" -scene "$scene" -model_ccx_job "$job" -contact_mu 0.15 -contact_v 1 -analyses stability,transient \
  -transient_start "$cycle" -transient_start_from expanded -transient_h "$h" -transient_periods 50 -transient_keep_every 2 -output "$out" |
  grep -E "^transient:|settled"
exec /usr/bin/python3 "$here/check_pad_cycle.py" --expanded --shooting "$cycle" --output "$out" \
  --period-tol 5e-4 --ptp-tol 0.02 --max-return 2e-2 --max-iterations 10
