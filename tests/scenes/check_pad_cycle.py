#!/usr/bin/python3
"""Limit cycle of a reduced FE pad: shooting (started from the energy estimate) against a long
transient of the same reduced model, both in one squeal run (the command after --, analyses
stability, energy, shooting, transient), or from two finished runs: --shooting FILE for the
shooting run's results and --output for the transient's, no command (the 31119-DOF pad, whose
transient takes an hour: docs/records.md "Limit cycles of the reduced pads"). The transient starts from a small multiple of the
unstable mode, not from the shooting solution, so the two are independent routes to the cycle.
Checks:
  - shooting converged in at most --max-iterations Newton iterations from the energy estimate;
  - the transient has settled onto a cycle: its state (U - U_e, dU / omega) returns within
    --max-return after one period over its last cycles (a period-1 orbit, as shooting assumes);
  - the period of the transient, measured here from upward crossings of the mean of the
    largest-amplitude DOF (Hermite interpolation with the stored velocities), agrees with the
    shooting period to --period-tol;
  - the peak-to-peak of every DOF over the transient's last cycles agrees with that of the
    shooting orbit to --ptp-tol (relative to the largest);
  - the Floquet multipliers say the cycle is stable (it attracts the transient) and the trivial
    multiplier is within 1e-2 of 1.
With --expanded the shooting run is of a reduced model that kept its expansion (/expanded/orbit:
the cycle on the full model's DOFs) and the transient is of the full model itself: every check
above is then made on the full model's DOFs, the reduced cycle against the unreduced dynamics."""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402
import scene_run  # noqa: E402


def crossings(t, y, v, level, hyst):
    """Times of the upward crossings of `level`, counted only after y went below level - hyst
    (a Schmitt trigger: harmonics cannot add crossings); cubic Hermite root between records."""
    out, armed = [], False
    for i in range(len(y) - 1):
        if y[i] < level - hyst:
            armed = True
        if armed and y[i] < level <= y[i + 1]:
            h = t[i + 1] - t[i]
            a, b = y[i] - level, y[i + 1] - level
            ma, mb = v[i] * h, v[i + 1] * h
            s = a / (a - b)
            for _ in range(50):  # Newton on the Hermite cubic, from the linear root
                h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
                h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
                f = h00 * a + h10 * ma + h01 * b + h11 * mb
                df = (6 * s**2 - 6 * s) * a + (3 * s**2 - 4 * s + 1) * ma + (-6 * s**2 + 6 * s) * b + (3 * s**2 - 2 * s) * mb
                if df == 0:
                    break
                ds = f / df
                s = min(1.0, max(0.0, s - ds))
                if abs(ds) < 1e-14:
                    break
            out.append(t[i] + s * h)
            armed = False
    return np.array(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True, help="results file with the transient (and the shooting)")
    ap.add_argument("--shooting", help="results file with the shooting solution (default: --output)")
    ap.add_argument("--max-iterations", type=int, default=8)
    ap.add_argument("--max-return", type=float, default=1e-2)
    ap.add_argument("--period-tol", type=float, default=1e-4)
    ap.add_argument("--ptp-tol", type=float, default=1e-2)
    ap.add_argument("--cycles", type=int, default=20, help="transient cycles compared (the last ones)")
    ap.add_argument("--expanded", action="store_true",
                    help="compare the shooting run's /expanded/orbit with a transient of the full model")
    ap.add_argument("--no-floquet", action="store_true",
                    help="the run computed no Floquet multipliers (-floquet_compute 0): do not ask for them")
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = scene_run.command(a.cmd)
    if cmd:
        r = scene_run.run(cmd, "check_pad_cycle")
    fails = []
    with Results(a.shooting or a.output) as rs:
        s = rs.shooting
        converged = s.converged
        its = s.iterations
        T_s = s.period
        Uo = rs.h5["expanded/orbit/U"][()] if a.expanded else s["orbit/U"]
        L = s.floquet
        trivial = s.trivial
        q0 = float(rs.energy.attrs["q0"])
    with Results(a.output) as r:
        t = r.transient["t"]
        U = r.transient["U"]
        V = r.transient["V"]
        Ue = r.equilibrium["U"]
    if not converged:
        fails.append("shooting did not converge")
    if its > a.max_iterations:
        fails.append(f"shooting took {its} Newton iterations > {a.max_iterations}")

    ptp_s = np.ptp(Uo, axis=0)
    d = int(np.argmax(ptp_s))
    y, v = U[:, d], V[:, d]
    n = len(t)
    tail = slice(n // 2, n)
    level = 0.5 * (y[tail].max() + y[tail].min())
    hyst = 0.25 * np.ptp(y[tail])
    tc = crossings(t[tail], y[tail], v[tail], level, hyst)
    if len(tc) < a.cycles + 2:
        sys.exit(f"check_pad_cycle: only {len(tc)} cycles in the second half of the transient")
    tc = tc[-(a.cycles + 1):]
    T_t = (tc[-1] - tc[0]) / a.cycles
    spread = np.std(np.diff(tc)) / T_t
    i0 = np.searchsorted(t, tc[0])
    ptp_t = np.ptp(U[i0:], axis=0)
    ptp_err = np.max(np.abs(ptp_t - ptp_s)) / np.max(ptp_s)

    # Return error of the whole state after one period over the compared cycles.
    om = 2 * np.pi / T_t
    Z = np.hstack([U[i0:] - Ue, V[i0:] / om])
    dt = t[1] - t[0]
    lag = T_t / dt
    k = int(np.floor(lag))
    al = lag - k
    m = len(Z) - k - 1
    Zl = (1 - al) * Z[k:k + m] + al * Z[k + 1:k + 1 + m]
    ret = np.linalg.norm(Zl - Z[:m], axis=1).mean() / np.linalg.norm(Z, axis=1).mean()

    mod = np.hypot(L[:, 0], L[:, 1]) if len(L) else np.array([])
    nontrivial = np.delete(mod, trivial) if trivial >= 0 else mod
    print(f"check_pad_cycle: shooting {its} Newton iterations from q0 = {q0:.4e} m, T = {T_s:.9e} s")
    print(f"  transient, last {a.cycles} cycles: T = {T_t:.9e} s (cycle-to-cycle spread {spread:.2e}), "
          f"period error {abs(T_t / T_s - 1):.2e}; state return after one period {ret:.2e}")
    print(f"  peak-to-peak: largest DOF {d}, {ptp_s[d]:.5e} m (shooting) vs {ptp_t[d]:.5e} m (transient); "
          f"largest difference {ptp_err:.2e} of the largest")
    if len(mod):
        print(f"  Floquet: trivial |L - 1| = {abs(complex(*L[trivial]) - 1) if trivial >= 0 else float('nan'):.2e}, "
              f"largest non-trivial |L| = {nontrivial.max():.6f}")
    if ret > a.max_return:
        fails.append(f"the transient has not settled onto a period-1 cycle (return error {ret:.2e} > {a.max_return})")
    if abs(T_t / T_s - 1) > a.period_tol:
        fails.append(f"period {T_s:.9e} s (shooting) vs {T_t:.9e} s (transient): {abs(T_t / T_s - 1):.2e} > {a.period_tol}")
    if ptp_err > a.ptp_tol:
        fails.append(f"peak-to-peak differs by {ptp_err:.2e} > {a.ptp_tol}")
    if a.no_floquet:
        pass
    elif not len(mod):
        fails.append("no Floquet multipliers written")
    else:
        if trivial < 0 or abs(complex(*L[trivial]) - 1) > 1e-2:
            fails.append("trivial Floquet multiplier not within 1e-2 of 1")
        if nontrivial.max() >= 1:
            fails.append(f"a non-trivial multiplier |L| = {nontrivial.max():.6f} >= 1 for a cycle the transient settles on")
    if fails:
        sys.exit("check_pad_cycle: FAILED: " + "; ".join(fails))
    print("check_pad_cycle: OK")


if __name__ == "__main__":
    main()
