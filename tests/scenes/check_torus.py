#!/usr/bin/python3
"""Runs squeal -analyses torus (the command after --) and checks /torus: converged, its residual
below --rtol, and its two frequencies (f1 = 1/T and the modulation f1 min(rho, 1 - rho)) against
lines of the transient's spectrum given as references (--f1, --fmod, from the statistical steady
state of a long transient: -analyses steady, docs/steady-state.md), within --ftol Hz."""
import argparse
import sys

import h5py

import scene_run


def fail(msg):
    sys.exit(f"check_torus: {msg}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--f1", type=float, required=True)
    ap.add_argument("--fmod", type=float, required=True)
    ap.add_argument("--ftol", type=float, default=0.5)
    ap.add_argument("--rtol", type=float, default=1e-6)
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = scene_run.command(a.cmd)
    scene_run.run(cmd, "check_torus")
    with h5py.File(a.output, "r") as f:
        if "torus" not in f:
            fail("no /torus group")
        at = f["torus"].attrs
        if not int(at["converged"]):
            fail(f"not converged: {at['reason']}")
        res, f1, fm = float(at["residual"]), float(at["f1"]), float(at["f_modulation"])
        if not res < a.rtol:
            fail(f"residual {res:.3e} >= {a.rtol:g}")
        if abs(f1 - a.f1) > a.ftol or abs(fm - a.fmod) > a.ftol:
            fail(f"f1 {f1:.4f} Hz, modulation {fm:.4f} Hz; the spectrum's {a.f1:.4f} and {a.fmod:.4f} (+- {a.ftol:g})")
        M = f["torus/circle"].shape[0]
        if M != int(at.get("points", M)):
            fail("circle's rows differ from the points")
        print(f"check_torus: converged, residual {res:.2e}, f1 {f1:.3f} Hz (spectrum {a.f1:.3f}), "
              f"modulation {fm:.3f} Hz (spectrum {a.fmod:.3f})")


if __name__ == "__main__":
    main()
