#!/usr/bin/python3
"""Runs started from a state in a results file (-transient_start, -shoot_start), on the 3-DOF case 1.

  check_start_from_file.py SCENE OUT_DIR SQUEAL...   (SQUEAL...: the program, after a launcher if any)

1. Going on from a transient: 10 periods, then 10 more from its last record, against 20 periods in
   one run. The start is the last record's (U, dU) and its reactions as the contact's warm start;
   on the 3-DOF kernel that is the whole state, so the last records must agree to 1e-12.
2. From a shooting cycle: /shooting/Z0 integrated over one period at the cycle's own step is the
   shooting's flow, so it must come back to Z0 within the residual shooting reports (||H|| / ||Z0||,
   its last entry of /shooting/residual_history), to 1e-12 besides.
3. Shooting from that cycle at twice the steps per period (what the Floquet verdict's hint asks
   for): Newton needs at most 2 iterations, and the finer cycle's period is within 1e-4 of the
   coarser one's (the theta-method's error at 1000 steps a period).
4. Shooting from a transient's last record (10 periods of the linear mode's motion) converges to
   the cycle found from the energy estimate: period within 1e-6 (the discrete cycle's period
   moves with the phase Newton settles at, by 1.4e-8 here).
5. A transient from a statistical steady state's end (/steady_state/Z_end) starts on it exactly.
"""
import subprocess
import sys

import h5py
import numpy as np


def run(cmd):
    print("+", " ".join(cmd), flush=True)
    out = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    print(out.stdout)
    if out.returncode != 0:
        sys.exit(f"check_start_from_file: exit code {out.returncode}")
    return out.stdout


def last_state(path):
    with h5py.File(path, "r") as f:
        t = f["transient"]
        return np.concatenate([t["U"][-1], t["V"][-1]]), t.attrs.get("start", b"")


def main():
    scene, out, squeal = sys.argv[1], sys.argv[2], sys.argv[3:]
    base = squeal + ["-scene", scene, "-analyses", "stability,transient"]
    run(base + ["-transient_periods", "20", "-output", f"{out}/start_whole.h5"])
    run(base + ["-transient_periods", "10", "-output", f"{out}/start_first.h5"])
    log = run(base + ["-transient_periods", "10", "-transient_start", f"{out}/start_first.h5", "-output", f"{out}/start_second.h5"])
    if "transient: start from the last record of /transient" not in log:
        sys.exit("check_start_from_file: the run does not say where it started")
    whole, _ = last_state(f"{out}/start_whole.h5")
    second, start = last_state(f"{out}/start_second.h5")
    if b"start_first.h5" not in start:
        sys.exit(f"check_start_from_file: /transient's start attribute is {start!r}")
    err = np.abs(second - whole).max() / np.abs(whole).max()
    print(f"10 + 10 periods against 20: largest difference {err:.2e} of the largest entry")
    if not err <= 1e-12:
        sys.exit("check_start_from_file: going on from the last record is not the same run")

    run(squeal + ["-scene", scene, "-analyses", "stability,shooting", "-output", f"{out}/start_cycle.h5"])
    with h5py.File(f"{out}/start_cycle.h5", "r") as f:
        s = f["shooting"]
        T, steps, Z0, res = s["period"][()], int(s.attrs["steps_per_period"]), s["Z0"][:], s["residual_history"][-1]
    run(base + ["-transient_start", f"{out}/start_cycle.h5", "-transient_start_from", "shooting", "-transient_h", repr(T / steps),
                "-transient_t_final", repr(T), "-output", f"{out}/start_from_cycle.h5"])
    with h5py.File(f"{out}/start_from_cycle.h5", "r") as f:
        t = f["transient"]
        if len(t["t"]) != steps + 1:
            sys.exit(f"check_start_from_file: {len(t['t']) - 1} steps, expected one period of {steps}")
        first = np.concatenate([t["U"][0], t["V"][0]])
        end = np.concatenate([t["U"][-1], t["V"][-1]])
    if not np.array_equal(first, Z0):
        sys.exit("check_start_from_file: the first record is not /shooting/Z0")
    back = np.linalg.norm(end - Z0) / np.linalg.norm(Z0)
    print(f"one period from /shooting/Z0: ||Z(T) - Z0|| / ||Z0|| = {back:.3e}, shooting's residual {res:.3e}")
    if not back <= res + 1e-12:
        sys.exit("check_start_from_file: the transient from the cycle does not return as shooting's flow did")

    fine = run(squeal + ["-scene", scene, "-analyses", "stability,shooting", "-shoot_start", f"{out}/start_cycle.h5", "-shoot_steps",
                         str(2 * steps), "-output", f"{out}/start_cycle_fine.h5"])
    if "shooting: start from /shooting/Z0 of" not in fine:
        sys.exit("check_start_from_file: shooting does not say where it started")
    with h5py.File(f"{out}/start_cycle_fine.h5", "r") as f:
        s = f["shooting"]
        ok, its, T2, steps2 = int(s.attrs["converged"]), int(s["iterations"][()]), s["period"][()], int(s.attrs["steps_per_period"])
    print(f"from the cycle at {steps2} steps a period: converged {ok} in {its} Newton iteration(s), period {T2:.12g} s "
          f"against {T:.12g} s ({abs(T2 - T) / T:.2e})")
    if not (ok and steps2 == 2 * steps and its <= 2 and abs(T2 - T) <= 1e-4 * T):
        sys.exit("check_start_from_file: shooting from the cycle at twice the steps")

    run(squeal + ["-scene", scene, "-analyses", "stability,shooting", "-shoot_start", f"{out}/start_first.h5", "-output",
                  f"{out}/start_cycle_from_transient.h5"])
    with h5py.File(f"{out}/start_cycle_from_transient.h5", "r") as f:
        s = f["shooting"]
        ok, T3 = int(s.attrs["converged"]), s["period"][()]
    print(f"from the transient's last record: converged {ok}, period {T3:.12g} s ({abs(T3 - T) / T:.2e} from the estimate's)")
    if not (ok and abs(T3 - T) <= 1e-6 * T):
        sys.exit("check_start_from_file: shooting from a transient's last record")

    run(squeal + ["-scene", scene, "-analyses", "steady", "-steady_max_periods", "100", "-output", f"{out}/start_steady.h5"])
    run(base + ["-transient_periods", "1", "-transient_start", f"{out}/start_steady.h5", "-output", f"{out}/start_from_steady.h5"])
    with h5py.File(f"{out}/start_steady.h5", "r") as f:
        z = f["steady_state/Z_end"][:]
    with h5py.File(f"{out}/start_from_steady.h5", "r") as f:
        t = f["transient"]
        first, start = np.concatenate([t["U"][0], t["V"][0]]), t.attrs["start"]
    if not (np.array_equal(first, z) and b"/steady_state/Z_end" in start):
        sys.exit(f"check_start_from_file: the transient from the steady state's end starts at {start!r}, not on Z_end")
    print("check_start_from_file: OK")


if __name__ == "__main__":
    main()
