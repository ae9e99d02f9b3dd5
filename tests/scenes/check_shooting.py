#!/usr/bin/python3
"""Runs squeal shooting (the command after --) and checks /shooting: converged within the
iteration budget, the trivial Floquet multiplier near 1, the regime of the cycle; with
a second command (after a second --) and --other-output, also runs that command and requires the
same period and Z0 (e.g. serial against mpiexec -n 2); --same-floquet also the same multipliers."""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402
import scene_run  # noqa: E402


def run(cmd):
    scene_run.run(cmd, "check_shooting")


def read(path):
    with Results(path) as r:
        g = r.shooting
        return dict(converged=g.converged, period=g.period, Z0=g["Z0"], iterations=g.iterations,
                    floquet=g.floquet, trivial=g.trivial, status=g["orbit/U"],
                    floquet_error=float(g.attrs.get("floquet_error", 0.0)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--max-iterations", type=int, default=5)
    ap.add_argument("--other-output")
    ap.add_argument("--same-floquet", action="store_true")
    # A reduced model's fixed-interface modes are eigenvectors, of either sign: another run (another
    # number of ranks) may flip a modal coordinate, so compare |Z0|.
    ap.add_argument("--any-mode-sign", action="store_true")
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = scene_run.command(a.cmd)
    cmds = [cmd]
    if "--" in cmd:
        k = cmd.index("--")
        cmds = [cmd[:k], cmd[k + 1:]]
    for c in cmds:
        run(c)
    s = read(a.output)
    fails = []
    if not s["converged"]:
        fails.append("not converged")
    if s["iterations"] > a.max_iterations:
        fails.append(f"{s['iterations']} Newton iterations > {a.max_iterations}")
    L = s["floquet"][:, 0] + 1j * s["floquet"][:, 1]
    if s["trivial"] < 0 or abs(L[s["trivial"]] - 1) > 1e-2:
        fails.append("trivial Floquet multiplier not within 1e-2 of 1")
    if a.other_output:
        o = read(a.other_output)
        if abs(o["period"] - s["period"]) > 1e-8 * s["period"]:
            fails.append(f"period {o['period']} differs from {s['period']}")
        zo, zs = (np.abs(o["Z0"]), np.abs(s["Z0"])) if a.any_mode_sign else (o["Z0"], s["Z0"])
        if np.linalg.norm(zo - zs) > 1e-6 * np.linalg.norm(s["Z0"]):
            fails.append("Z0 differs")
        if a.same_floquet:
            mo = np.sort(np.hypot(o["floquet"][:, 0], o["floquet"][:, 1]))
            ms = np.sort(np.hypot(s["floquet"][:, 0], s["floquet"][:, 1]))
            # The multipliers are known to the runs' own error estimate (the monodromy of a cycle
            # that opens contacts: the small pad's 6.9e-6), no closer.
            tol = max(1e-6, o["floquet_error"], s["floquet_error"])
            if mo.shape != ms.shape or np.max(np.abs(mo - ms)) > tol:
                d = np.abs(mo - ms) if mo.shape == ms.shape else None
                fails.append("Floquet multipliers differ: "
                             + (f"by {d.max():.2e} (|L| = {mo[d.argmax()]:.6f}) > {tol:.2e}" if d is not None else f"{mo.shape} vs {ms.shape}"))
    print(f"check_shooting: T = {s['period']:.9f} s, {s['iterations']} iterations, |L_trivial - 1| = {abs(L[s['trivial']] - 1):.2e}")
    if fails:
        sys.exit("check_shooting: FAILED: " + "; ".join(fails))
    print("check_shooting: OK")


if __name__ == "__main__":
    main()
