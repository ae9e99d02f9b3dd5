#!/usr/bin/python3
"""Diagnosis of the limit cycle of the reduced small pad (examples/pad/pad_small_shooting.yaml).
Runs squeal (the command after --: stability, energy, transient) and checks, against the linear
eigenvalue and the transient itself (no pasted numbers of the code under test):
  - the transient saturates: the peak-to-peak of the largest contact DOF, per period of the
    dominant frequency, is steady over the last 40 % (relative spread and drift < --ptp-spread);
  - it oscillates at the unstable mode: dominant frequency within --freq-tol of the linear one;
  - contact separates part of the time (the motion is non-smooth);
  - the motion is not a period-1, 2 or 3 cycle: the whole state (U - U_e, dU / omega) returns
    only within > --min-return (relative, mean over the last 20 %) after 1, 2 or 3 periods;
  - the energy estimate's amplitude q0 is more than --q0-ratio times the cycle's largest in-plane
    contact amplitude: the shooting start from the energy estimate is that far from the cycle.
The last check asserts the diagnosis of why shooting from the energy estimate fails on this scene;
it is expected to fail once the energy estimate is fixed (then turn it into a shooting test)."""
import argparse
import subprocess
import sys

import h5py
import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--ptp-spread", type=float, default=0.1)
    ap.add_argument("--freq-tol", type=float, default=0.02)
    ap.add_argument("--q0-ratio", type=float, default=10.0)
    ap.add_argument("--min-return", type=float, default=0.01)
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = a.cmd[1:] if a.cmd and a.cmd[0] == "--" else a.cmd
    r = subprocess.run(cmd, capture_output=True, text=True)
    sys.stdout.write(r.stdout)
    sys.stderr.write(r.stderr)
    if r.returncode != 0:
        sys.exit(f"check_pad_cycle: squeal exited with {r.returncode}")
    fails = []
    with h5py.File(a.output, "r") as f:
        ev = f["stability/eigenvalues"][()]
        unstable = f["stability/unstable"][()]
        mode = int(f["energy"].attrs["mode"])
        q0 = float(f["energy"].attrs["q0"])
        f_lin = ev[mode, 1] / (2 * np.pi)
        t = f["transient/t"][()]
        U = f["transient/U"][()]
        V = f["transient/V"][()]
        Ue = f["equilibrium/U"][()]
        sep = float(f["transient"].attrs["fraction_separated"])
        ncontact = f["equilibrium/N"].shape[0]
    dt = t[1] - t[0]
    n = len(t)
    X = U[int(0.6 * n):, :3 * ncontact] - Ue[:3 * ncontact]
    d = int(np.argmax(np.ptp(X, axis=0)))
    y = X[:, d] - X[:, d].mean()
    nfft = 16 * len(y)
    F = np.abs(np.fft.rfft(y * np.hanning(len(y)), nfft))
    k = int(np.argmax(F[1:])) + 1
    # parabolic interpolation of the peak
    al, be, ga = np.log(F[k - 1]), np.log(F[k]), np.log(F[k + 1])
    f_c = (k + 0.5 * (al - ga) / (al - 2 * be + ga)) / (nfft * dt)
    w = max(2, int(round(1.0 / (f_c * dt))))
    ptp = np.array([np.ptp(X[i * w:(i + 1) * w, d]) for i in range(len(X) // w)])
    spread = np.std(ptp) / np.mean(ptp)
    half = len(ptp) // 2
    drift = abs(np.mean(ptp[half:]) / np.mean(ptp[:half]) - 1)
    # Return error after k periods of the whole state (U - U_e, dU / omega), last 20 %, at the
    # best fractional lag near k / f_c (linear interpolation between records).
    om = 2 * np.pi * f_c
    Z = np.hstack([U[int(0.8 * n):] - Ue, V[int(0.8 * n):] / om])
    nz = np.linalg.norm(Z, axis=1).mean()
    m = len(Z) - int(4 / (f_c * dt)) - 4
    ret = []
    for k in (1, 2, 3):
        best = np.inf
        for lag in np.arange(k / (f_c * dt) - 2, k / (f_c * dt) + 2, 0.05):
            i = int(np.floor(lag))
            al = lag - i
            Zl = (1 - al) * Z[i:i + m] + al * Z[i + 1:i + 1 + m]
            best = min(best, np.linalg.norm(Zl - Z[:m], axis=1).mean() / nz)
        ret.append(best)
    P = X.reshape(len(X), ncontact, 3)
    inplane = np.max(np.hypot(np.ptp(P[:, :, 0], axis=0), np.ptp(P[:, :, 1], axis=0)) / 2)
    print(f"check_pad_cycle: {len(unstable)} unstable mode(s), energy mode {mode} at {f_lin:.4f} Hz")
    print(f"  transient, last 40 %: DOF {d}, peak-to-peak {np.mean(ptp):.4e} m per period, "
          f"spread {spread:.3e}, drift {drift:.3e}; dominant frequency {f_c:.2f} Hz "
          f"(T = {1 / f_c:.7e} s, {f_c / f_lin - 1:+.3e} from linear); separated {sep:.3f}")
    print(f"  largest in-plane contact amplitude {inplane:.4e} m; energy estimate q0 = {q0:.4e} m "
          f"({q0 / inplane:.1f} x)")
    print("  return error of the state after 1, 2, 3 periods: " + ", ".join(f"{e:.3e}" for e in ret))
    if spread > a.ptp_spread or drift > a.ptp_spread:
        fails.append(f"transient not saturated: spread {spread:.3e}, drift {drift:.3e} > {a.ptp_spread}")
    if abs(f_c / f_lin - 1) > a.freq_tol:
        fails.append(f"dominant frequency {f_c:.2f} Hz not within {a.freq_tol} of the linear {f_lin:.2f} Hz")
    if sep <= 0.0:
        fails.append("no separation: the cycle would be that of a linear system")
    if q0 < a.q0_ratio * inplane:
        fails.append(f"energy estimate q0 {q0:.4e} within {a.q0_ratio} x of the cycle amplitude {inplane:.4e}: "
                     "the diagnosis no longer holds, try shooting from the energy estimate")
    if min(ret) < a.min_return:
        fails.append(f"the transient returns within {min(ret):.3e} < {a.min_return} after 1-3 periods: it is a cycle, "
                     "shoot from it")
    if fails:
        sys.exit("check_pad_cycle: " + "; ".join(fails))
    print("check_pad_cycle: OK")


if __name__ == "__main__":
    main()
