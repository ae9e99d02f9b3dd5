#!/bin/bash
# Issue 18 item 4: continuation in mu on the reduced brake, checked against stand-alone shooting.
#   brake_continuation.sh SQUEAL SCENE CCX_JOB OUT_DIR MU_END
# The half brake reduced by Craig-Bampton at 90 kHz (mu = 0.15, V = 1 m/s, as
# scenes_brake_half_cycle_vs_full): shooting from the energy estimate, then the branch up to
# mu = MU_END by both correctors: the default on FE models (arclength, GMRES on exact tangents with
# shooting's preconditioner bordered; unpreconditioned, it broke down at every step size here) and
# -cont_corrector parameter (shooting's Newton at the predicted mu). Each branch's last point,
# exactly at MU_END, against a stand-alone run at MU_END (energy estimate, pre-periods, Newton): the
# same cycle, reached along another path. Without Floquet multipliers (-floquet_compute 0), which
# are most of a point's time and not what is checked here.
set -euo pipefail
squeal=$1 scene=$2 job=$3 out=$4 mu_end=$5
op=(-scene "$scene" -model_ccx_job "$job" -contact_v 1 -reduce_type craig_bampton -reduce_fmax 90000
    -shoot_ksp_max_it 600 -floquet_compute 0)
mkdir -p "$out"
rm -f "$out/branch.h5" "$out/branch_parameter.h5" "$out/alone.h5"
"$squeal" "${op[@]}" -contact_mu 0.15 -analyses stability,energy,shooting,continuation -cont_both 0 \
  -cont_max "$mu_end" -cont_monitor -output "$out/branch.h5" | tee "$out/branch.log" | grep -E "^cont|^shooting:"
grep -q "^cont: corrector: arclength, GMRES on exact tangents preconditioned" "$out/branch.log"
"$squeal" "${op[@]}" -contact_mu 0.15 -analyses shooting,continuation -cont_both 0 -cont_corrector parameter \
  -cont_max "$mu_end" -cont_monitor -output "$out/branch_parameter.h5" | tee "$out/branch_parameter.log" | grep -E "^cont"
grep -q "^cont: corrector: shooting at the predicted mu (-cont_corrector parameter)" "$out/branch_parameter.log"
"$squeal" "${op[@]}" -contact_mu "$mu_end" -analyses stability,energy,shooting -output "$out/alone.h5" | grep -E "^shooting:"
exec /usr/bin/python3 - "$out/alone.h5" "$mu_end" "$out/branch.h5" "$out/branch_parameter.h5" <<'EOF'
import sys
import h5py
import numpy as np

fails = []
def check(cond, msg):
    print(("ok   " if cond else "FAIL ") + msg)
    if not cond:
        fails.append(msg)

a, mu_end = h5py.File(sys.argv[1], "r"), float(sys.argv[2])
s = a["shooting"]
Ta = s["period"][()]
ampa = float(np.ptp(s["orbit/U"][()], axis=0).max())  # as the branch's amplitude: the largest peak-to-peak over DOFs
print(f"stand-alone at mu = {mu_end}: T = {Ta:.9e} s, amplitude {ampa:.6e} m")
for path in sys.argv[3:]:
    c = h5py.File(path, "r")["continuation"]
    mu, T, amp = c["param"][()], c["period"][()], c["amplitude"][()]
    print(f"{path}: mu {mu}\n  T {T}\n  amplitude {amp}")
    check(int(c.attrs["complete"]) == 1, "the branch reaches the end of the range")
    check(mu.size >= 3, f"{mu.size} points (>= 3)")
    check(abs(mu[-1] - mu_end) < 1e-12, f"last point at mu = {mu[-1]}")
    check(np.all(np.diff(mu) > 0) and np.all(np.diff(amp) > 0), "mu and the amplitude grow along the branch")
    dT, dA = abs(T[-1] - Ta) / Ta, abs(amp[-1] - ampa) / ampa
    check(dT < 1e-5, f"period against the stand-alone run: {dT:.2e} (< 1e-5)")
    check(dA < 1e-3, f"amplitude against the stand-alone run: {dA:.2e} (< 1e-3)")
sys.exit(1 if fails else 0)
EOF
