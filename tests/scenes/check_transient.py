#!/usr/bin/python3
"""Runs a squeal transient (the command after --), then checks its HDF5 results: the contact
regime of the settled cycle over the last 20 % of the records, the energy balance, and that
every record is finite."""
import argparse
import subprocess
import sys

import h5py
import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--regime", choices=["separation_slip", "stick_slip"], required=True)
    ap.add_argument("--energy-tol", type=float, default=1e-8)
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = a.cmd[1:] if a.cmd and a.cmd[0] == "--" else a.cmd
    run = subprocess.run(cmd, capture_output=True, text=True)
    sys.stdout.write(run.stdout)
    sys.stderr.write(run.stderr)
    if run.returncode != 0:
        sys.exit(f"check_transient: squeal exited with {run.returncode}")
    fails = []
    with h5py.File(a.output, "r") as f:
        g = f["/transient"]
        status = g["status"][()]
        U, V, E = g["U"][()], g["V"][()], g["energy"][()]
        if not g.attrs["complete"]:
            fails.append("run incomplete")
        if not (np.isfinite(U).all() and np.isfinite(V).all()):
            fails.append("non-finite records")
        last = status[-max(len(status) // 5, 2):]
        sep, stuck = np.mean(last == 0), np.mean(last == 1)
        if a.regime == "separation_slip" and not (sep > 0.05 and stuck == 0):
            fails.append(f"expected separation and no stick, got separated {sep:.3f}, stuck {stuck:.3f}")
        if a.regime == "stick_slip" and not (stuck > 0.01 and sep == 0):
            fails.append(f"expected stick and no separation, got separated {sep:.3f}, stuck {stuck:.3f}")
        # E(t) - E(0) = W_reactions + W_load - W_damping, to the discretisation error (theta = 1/2).
        defect = np.max(np.abs((E[:, 0] - E[0, 0]) - (E[:, 2] + E[:, 3] - E[:, 1]))) / np.max(np.abs(E[:, 0]))
        if defect > a.energy_tol:
            fails.append(f"energy balance defect {defect:.2e} > {a.energy_tol:.0e}")
        period = g.attrs["period"]
        if not (0.009 < period < 0.0125):
            fails.append(f"cycle period {period} s far from the linear 0.0107-0.0109 s")
    print(f"check_transient: separated {sep:.3f}, stuck {stuck:.3f}, period {period:.7f} s, energy defect {defect:.1e}")
    if fails:
        sys.exit("check_transient: FAILED: " + "; ".join(fails))
    print("check_transient: OK")


if __name__ == "__main__":
    main()
