#!/usr/bin/python3
"""A transient started from a results file (-transient_start), on the 3-DOF case 1.

  check_transient_start.py SCENE OUT_DIR SQUEAL...   (SQUEAL...: the program, after a launcher if any)

1. Going on from a transient: 10 periods, then 10 more from its last record, against 20 periods in
   one run. The start is the last record's (U, dU) and its reactions as the contact's warm start;
   on the 3-DOF kernel that is the whole state, so the last records must agree to 1e-12.
2. From a shooting cycle: /shooting/Z0 integrated over one period at the cycle's own step is the
   shooting's flow, so it must come back to Z0 within the residual shooting reports (||H|| / ||Z0||,
   its last entry of /shooting/residual_history), to 1e-12 besides.
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
        sys.exit(f"check_transient_start: exit code {out.returncode}")
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
        sys.exit("check_transient_start: the run does not say where it started")
    whole, _ = last_state(f"{out}/start_whole.h5")
    second, start = last_state(f"{out}/start_second.h5")
    if b"start_first.h5" not in start:
        sys.exit(f"check_transient_start: /transient's start attribute is {start!r}")
    err = np.abs(second - whole).max() / np.abs(whole).max()
    print(f"10 + 10 periods against 20: largest difference {err:.2e} of the largest entry")
    if not err <= 1e-12:
        sys.exit("check_transient_start: going on from the last record is not the same run")

    run(squeal + ["-scene", scene, "-analyses", "stability,shooting", "-output", f"{out}/start_cycle.h5"])
    with h5py.File(f"{out}/start_cycle.h5", "r") as f:
        s = f["shooting"]
        T, steps, Z0, res = s["period"][()], int(s.attrs["steps_per_period"]), s["Z0"][:], s["residual_history"][-1]
    run(base + ["-transient_start", f"{out}/start_cycle.h5", "-transient_start_from", "shooting", "-transient_h", repr(T / steps),
                "-transient_t_final", repr(T), "-output", f"{out}/start_from_cycle.h5"])
    with h5py.File(f"{out}/start_from_cycle.h5", "r") as f:
        t = f["transient"]
        if len(t["t"]) != steps + 1:
            sys.exit(f"check_transient_start: {len(t['t']) - 1} steps, expected one period of {steps}")
        first = np.concatenate([t["U"][0], t["V"][0]])
        end = np.concatenate([t["U"][-1], t["V"][-1]])
    if not np.array_equal(first, Z0):
        sys.exit("check_transient_start: the first record is not /shooting/Z0")
    back = np.linalg.norm(end - Z0) / np.linalg.norm(Z0)
    print(f"one period from /shooting/Z0: ||Z(T) - Z0|| / ||Z0|| = {back:.3e}, shooting's residual {res:.3e}")
    if not back <= res + 1e-12:
        sys.exit("check_transient_start: the transient from the cycle does not return as shooting's flow did")
    print("check_transient_start: OK")


if __name__ == "__main__":
    main()
