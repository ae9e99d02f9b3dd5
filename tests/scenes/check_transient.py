#!/usr/bin/python3
"""Runs a squeal transient (the command after --), then checks its HDF5 results: the contact
regime of the settled cycle over the last 20 % of the records, the energy balance, that every
record is finite, and, for a cycle squeal calls settled, its period against an independent one:
the lag after which the displacements of the last period return to themselves (least squares
over its records, displacements between records by their cubic Hermite interpolant)."""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402
import scene_run  # noqa: E402


def hermite(t, U, V, tq):
    """U at the times tq by the cubic Hermite interpolant of (U, V) between records."""
    k = np.clip(np.searchsorted(t, tq) - 1, 0, len(t) - 2)
    h = t[k + 1] - t[k]
    s = ((tq - t[k]) / h)[:, None]
    h = h[:, None]
    return ((2 * s**3 - 3 * s**2 + 1) * U[k] + (s**3 - 2 * s**2 + s) * h * V[k] + (-2 * s**3 + 3 * s**2) * U[k + 1]
            + (s**3 - s**2) * h * V[k + 1])


def return_period(t, U, V, guess):
    """The lag tau near guess minimising sum over the records of the last period of |U(t - tau) - U(t)|^2,
    each DOF scaled by its peak-to-peak (DOFs that do not move are left out)."""
    n = len(t)
    last = slice(n - n // 5, n)
    ptp = np.ptp(U[last], axis=0)
    keep = ptp > 1e-9 * ptp.max()
    U, V, ptp = U[:, keep] / ptp[keep], V[:, keep] / ptp[keep], ptp[keep]
    nlast = int(np.sum(t > t[-1] - guess))
    te = t[-nlast:]
    f = lambda tau: np.sum((hermite(t, U, V, te - tau) - U[-nlast:]) ** 2)
    grid = np.linspace(0.95 * guess, 1.05 * guess, 401)
    i = int(np.argmin([f(x) for x in grid]))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    g = (np.sqrt(5) - 1) / 2
    for _ in range(80):  # golden section
        c, d = b - g * (b - a), a + g * (b - a)
        if f(c) < f(d):
            b = d
        else:
            a = c
    return 0.5 * (a + b)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--regime", choices=["separation_slip", "stick_slip"], required=True)
    ap.add_argument("--energy-tol", type=float, default=1e-8)
    ap.add_argument("--period-tol", type=float, default=1e-5,
                    help="settled cycle: relative agreement of the period with the state's return lag")
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = scene_run.command(a.cmd)
    scene_run.run(cmd, "check_transient")
    fails = []
    with Results(a.output) as r:
        g = r.transient
        status = g["status"]
        U, V, E = g["U"], g["V"], g["energy"]
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
        trend = g.attrs["trend"]
        ret = ""
        if trend == "settled":
            T_ret = return_period(g["t"], U, V, period)
            ret = f", state return lag {T_ret:.10e} s ({period / T_ret - 1:+.1e})"
            if abs(period / T_ret - 1) > a.period_tol:
                fails.append(f"settled period {period:.10e} s differs from the state's return lag {T_ret:.10e} s by more than {a.period_tol:.0e}")
    print(f"check_transient: separated {sep:.3f}, stuck {stuck:.3f}, {trend}, period {period:.10e} s{ret}, energy defect {defect:.1e}")
    if fails:
        sys.exit("check_transient: FAILED: " + "; ".join(fails))
    print("check_transient: OK")


if __name__ == "__main__":
    main()
