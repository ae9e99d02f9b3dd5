#!/usr/bin/python3
"""Runs squeal -analyses auto (the command after --) and checks the route it chose (/route) and
what that route wrote: with --route shooting a converged /shooting; with --route steady_state a
/steady_state whose levels and Welch PSD are those numpy computes (scripts/steady_state.py's
levels and welch) on the records it wrote, its RMS inside its own interval, and --verdict among
the allowed ones."""
import argparse
import math
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402
import steady_state as ss  # noqa: E402


def fail(msg):
    sys.exit(f"check_route: {msg}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--route", choices=["shooting", "steady_state"], required=True)
    ap.add_argument("--verdict", action="append", help="allowed verdicts (steady_state); default any")
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = a.cmd[1:] if a.cmd and a.cmd[0] == "--" else a.cmd
    r = subprocess.run(cmd, capture_output=True, text=True)
    sys.stdout.write(r.stdout)
    sys.stderr.write(r.stderr)
    if r.returncode != 0:
        fail(f"{' '.join(cmd[:3])} ... exited with {r.returncode}")
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("route: ")]
    if not lines:
        fail("no 'route:' line printed")
    with Results(a.output) as res:
        g = res.group("route")
        if g is None:
            fail("no /route group")
        route = g.attrs["route"]
        if route != a.route:
            fail(f"route {route}, expected {a.route} ({g.attrs['reason']})")
        d, tol = float(g.attrs["return_distance"]), float(g.attrs["pre_tol"])
        if (route == "shooting") != (d < tol) and not int(g.attrs["newton_failed"]):
            fail(f"route {route} with return distance {d:.3g} against -shoot_pre_tol {tol:g}")
        if route == "shooting":
            if res.shooting is None or not res.shooting.converged:
                fail("route shooting without a converged /shooting")
            print(f"check_route: shooting, return distance {d:.2e} < {tol:g}, period {res.shooting.period:.7g} s")
            return
        s = res.steady_state
        if s is None:
            fail("route steady_state without /steady_state")
        at = s.attrs
        t, x = s["t"], s["signal"]
        dt = t[1] - t[0]
        if np.max(np.abs(np.diff(t) - dt)) > 1e-9 * dt:
            fail("the analysed records are not uniformly spaced (chunks off one grid)")
        lv = ss.levels(x, int(at["batches"]))
        for k in ("rms", "rms_lo", "rms_hi", "peak"):
            if abs(lv[k] - float(at[k])) > 1e-9 * abs(lv[k]):
                fail(f"{k} {float(at[k]):.9e}, numpy gives {lv[k]:.9e}")
        if not float(at["rms_lo"]) <= float(at["rms"]) <= float(at["rms_hi"]):
            fail("the RMS is outside its own interval")
        f, p = ss.welch(x, dt)
        if len(f) != len(s["psd"]) or np.max(np.abs(p - s["psd"])) > 1e-9 * np.max(p):
            fail("the PSD differs from numpy's Welch on the same records")
        if a.verdict and at["verdict"] not in a.verdict:
            fail(f"verdict {at['verdict']} ({at['evidence']}), expected one of {a.verdict}")
        if len(s["lines"]) == 0:
            fail("no spectral line")
        print(f"check_route: steady_state, return distance {d:.2e} >= {tol:g}; RMS {lv['rms']:.4e} in "
              f"[{lv['rms_lo']:.4e}, {lv['rms_hi']:.4e}] as numpy's; PSD as numpy's; verdict {at['verdict']}")


if __name__ == "__main__":
    main()
