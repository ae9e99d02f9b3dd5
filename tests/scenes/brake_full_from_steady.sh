#!/bin/bash
# The full model started where the reduced model's statistical steady state ended (-transient_start on
# /expanded/Z_end), against that steady state:
#   brake_full_from_steady.sh SQUEAL SCENE CCX_JOB OUT_DIR
# The half brake at the scene's own operating point (mu = 0.4, V = 5 m/s: three unstable modes),
# -analyses auto on its default CB reduction (90 kHz, 782 DOFs): the flow does not return, so the
# statistical steady state, periodic, and from its end at T = 1 / f1 the cycle (-shoot_after_steady):
# its period within 1e-3 of 1 / f1. Then the unreduced 3 600-DOF model's steady state from that end state, and
# on its own from its most unstable mode (the independent check: 50 periods of this motion are enough
# here). Each one's normal reaction mean within 1 % and RMS within 5 %, and its fundamental within
# 1e-3, of the reduced model's. Measured 2026-11-30, all three periodic after one chunk of 50 periods:
# f1 9 226.86 Hz reduced, 9 224.10 from its end (3.0e-4), 9 230.96 from the mode (4.4e-4); mean
# 3 006.5 / 3 007.0 / 3 002.7 N; RMS 969.4 / 969.3 / 964.8 N. The cycle: 9 226.56 Hz (3.2e-5 from
# f1) in 4 Newton iterations after 7 pre-periods. 47 s in all, 20 of them the cycle's.
set -euo pipefail
squeal=$1 scene=$2 job=$3 out=$4
mkdir -p "$out"
rm -f "$out/steady.h5" "$out/full_steady.h5" "$out/full_steady_mode.h5"
"$squeal" -scene "$scene" -model_ccx_job "$job" -analyses auto -reduce_type craig_bampton -output "$out/steady.h5" |
  grep -E "^route:|Craig-Bampton|verdict|total normal reaction|limit cycle"
"$squeal" -scene "$scene" -model_ccx_job "$job" -analyses steady -transient_start "$out/steady.h5" -transient_start_from expanded_end -output "$out/full_steady.h5" |
  grep -E "start from|statistical steady state of|verdict|total normal reaction"
"$squeal" -scene "$scene" -model_ccx_job "$job" -analyses steady -output "$out/full_steady_mode.h5" |
  grep -E "statistical steady state of|verdict|total normal reaction"
exec /usr/bin/python3 - "$out/steady.h5" "$out/full_steady.h5" "$out/full_steady_mode.h5" <<'PY'
import sys
import h5py

def levels(path):
    with h5py.File(path, "r") as f:
        g = f["steady_state"]
        a = g.attrs
        return a["normal_mean"], a["normal_rms"], a["bases"][0], a["verdict"].decode() if isinstance(a["verdict"], bytes) else a["verdict"]

red = levels(sys.argv[1])
with h5py.File(sys.argv[1], "r") as f:
    if "/expanded/Z_end" not in f:
        sys.exit("brake_full_from_steady: the reduced run wrote no /expanded/Z_end")
    cycle = f["route"].attrs.get("cycle", b"")
    cycle = cycle.decode() if isinstance(cycle, bytes) else cycle
    if cycle != "converged" or "shooting" not in f:
        sys.exit(f"brake_full_from_steady: the cycle after the periodic steady state: {cycle!r}")
    T = f["shooting/period"][()]
print(f"cycle after the steady state: {1 / T:.3f} Hz, {abs(T * red[2] - 1):.2e} from 1 / f1")
if not abs(T * red[2] - 1) <= 1e-3:
    sys.exit("brake_full_from_steady: the cycle's period is not the steady state's 1 / f1")
print(f"reduced:              normal reaction mean {red[0]:.1f} N, RMS {red[1]:.1f} N, f1 {red[2]:.2f} Hz ({red[3]})")
bad = False
for name, path in (("full from its end", sys.argv[2]), ("full from its mode", sys.argv[3])):
    full = levels(path)
    e_mean, e_rms, e_f1 = abs(full[0] / red[0] - 1), abs(full[1] / red[1] - 1), abs(full[2] / red[2] - 1)
    print(f"{name + ':':21s} normal reaction mean {full[0]:.1f} N, RMS {full[1]:.1f} N, f1 {full[2]:.2f} Hz ({full[3]}); "
          f"differences: mean {e_mean:.2e}, RMS {e_rms:.2e}, f1 {e_f1:.2e}")
    bad |= not (e_mean <= 0.01 and e_rms <= 0.05 and e_f1 <= 1e-3)
if bad:
    sys.exit("brake_full_from_steady: the full model's steady state differs from the reduced one's")
print("brake_full_from_steady: OK")
PY
