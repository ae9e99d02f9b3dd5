#!/usr/bin/python3
"""Run squeal on a scene and check its HDF5 results against reference values.

Usage:
  check_scene.py --output FILE.h5 [checks...] -- <command...>

The command (squeal ... -output FILE.h5, possibly under mpiexec) must exit 0 and write FILE.h5
(any old FILE.h5 is removed first, so a stale file cannot pass). Then, from FILE.h5:

  --period T --period-rtol R   the most unstable mode (/stability/unstable[0]) has sigma > 0 and
                               period 2*pi/omega (from /stability/eigenvalues) within R of T
  --n-unstable N               /stability/unstable has exactly N entries
  --same-period-as OTHER.h5    the unstable period equals that in OTHER.h5 within --same-rtol
  --critical-mu MU --mu-rtol R every entry of the /sweep attribute critical_mu within R of MU
  --sweep-v V [V ...]          /sweep/V holds exactly these speeds (one critical_mu each)

Reference values come from the test definitions (docs/method.md §8 numbers), not from the program.
"""
import argparse
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402


class Checker:
    def __init__(self):
        self.failures = 0

    def ok(self, cond, msg):
        print(("ok:   " if cond else "FAIL: ") + msg)
        if not cond:
            self.failures += 1
        return cond


def rel_err(x, ref):
    return abs(x - ref) / abs(ref)


def unstable_period(r, chk, label):
    """Period 2*pi/omega and sigma of the most unstable mode of an open results file."""
    if not chk.ok("stability/eigenvalues" in r and "stability/unstable" in r,
                  f"{label}: has /stability/eigenvalues and /stability/unstable"):
        return None
    ev = r.stability.eigenvalues
    un = r.stability.unstable
    if not chk.ok(ev.ndim == 2 and ev.shape[1] == 2,
                  f"{label}: /stability/eigenvalues is k x 2 (shape {ev.shape})"):
        return None
    if not chk.ok(un.size >= 1, f"{label}: at least one unstable mode ({un.size})"):
        return None
    i = int(un[0])
    if not chk.ok(0 <= i < ev.shape[0], f"{label}: unstable index {i} within [0, {ev.shape[0]})"):
        return None
    sigma, omega = ev[i]
    chk.ok(np.isfinite(sigma) and sigma > 0, f"{label}: most unstable mode {i} has sigma = {sigma:g} > 0")
    if not chk.ok(np.isfinite(omega) and omega > 0, f"{label}: mode {i} has omega = {omega:g} > 0"):
        return None
    # "most unstable first": unstable[0] has the largest growth rate
    sig_all = ev[un.astype(int), 0]
    chk.ok(sigma >= np.max(sig_all), f"{label}: unstable[0] has the largest sigma of the unstable modes")
    return 2.0 * math.pi / omega


def main():
    argv = sys.argv[1:]
    if "--" not in argv:
        sys.exit(__doc__)
    k = argv.index("--")
    opts, cmd = argv[:k], argv[k + 1:]
    p = argparse.ArgumentParser()
    p.add_argument("--output", required=True)
    p.add_argument("--period", type=float)
    p.add_argument("--period-rtol", type=float, default=0.005)
    p.add_argument("--n-unstable", type=int)
    p.add_argument("--same-period-as")
    p.add_argument("--same-rtol", type=float, default=1e-6)
    p.add_argument("--critical-mu", type=float)
    p.add_argument("--mu-rtol", type=float, default=0.01)
    p.add_argument("--sweep-v", type=float, nargs="+")
    a = p.parse_args(opts)
    if not cmd:
        sys.exit("no command given after --")

    if os.path.exists(a.output):
        os.remove(a.output)
    os.makedirs(os.path.dirname(os.path.abspath(a.output)), exist_ok=True)

    print("+ " + " ".join(cmd), flush=True)
    r = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, universal_newlines=True)
    print("--- exit code:", r.returncode)
    print("--- stdout+stderr:")
    print(r.stdout, end="" if r.stdout.endswith("\n") else "\n")
    print("---")

    chk = Checker()
    chk.ok(r.returncode == 0, f"exit code {r.returncode} == 0")
    if not chk.ok(os.path.isfile(a.output), f"results file {a.output} written"):
        sys.exit(1)

    with Results(a.output) as r:
        if a.period is not None or a.n_unstable is not None or a.same_period_as:
            T = unstable_period(r, chk, "result")
            if a.n_unstable is not None:
                n = r.stability.unstable.size if "stability/unstable" in r else -1
                chk.ok(n == a.n_unstable, f"number of unstable modes {n} == {a.n_unstable}")
            if T is not None and a.period is not None:
                e = rel_err(T, a.period)
                chk.ok(e <= a.period_rtol,
                       f"unstable period {T:.7g} s vs reference {a.period:.7g} s: "
                       f"rel. error {e:.2e} <= {a.period_rtol:g}")
            if T is not None and a.same_period_as:
                with Results(a.same_period_as) as g:
                    T0 = unstable_period(g, chk, os.path.basename(a.same_period_as))
                if T0 is not None:
                    e = rel_err(T, T0)
                    chk.ok(e <= a.same_rtol,
                           f"unstable period {T:.9g} s vs {T0:.9g} s in {a.same_period_as}: "
                           f"rel. difference {e:.2e} <= {a.same_rtol:g}")

        if a.critical_mu is not None or a.sweep_v is not None:
            if chk.ok("sweep" in r, "has /sweep"):
                sw = r.sweep
                V = sw.V
                chk.ok(V is not None, "has /sweep/V")
                crit = sw.critical_mu
                if chk.ok(crit is not None, "/sweep has attribute critical_mu"):
                    if V is not None:
                        chk.ok(crit.size == V.size,
                               f"critical_mu has one entry per V ({crit.size} vs {V.size})")
                    if a.critical_mu is not None:
                        for j, c in enumerate(crit):
                            e = rel_err(c, a.critical_mu) if np.isfinite(c) else float("inf")
                            chk.ok(e <= a.mu_rtol,
                                   f"critical_mu[{j}] = {c:.7g} vs reference {a.critical_mu:.7g}: "
                                   f"rel. error {e:.2e} <= {a.mu_rtol:g}")
                if V is not None and a.sweep_v is not None:
                    chk.ok(V.size == len(a.sweep_v) and np.allclose(V, a.sweep_v, rtol=1e-12, atol=0),
                           f"/sweep/V = {V.tolist()} == {a.sweep_v}")
                if "eigenvalues" in sw and "mu" in sw and V is not None:
                    shp = sw.dataset("eigenvalues").shape
                    nmu = sw.dataset("mu").shape[0]
                    chk.ok(len(shp) == 4 and shp[0] == V.size and shp[1] == nmu and shp[3] == 2,
                           f"/sweep/eigenvalues shape {shp} is [V={V.size}][mu={nmu}][slot][2]")

    if chk.failures:
        print(f"FAILED: {chk.failures} check(s)")
        sys.exit(1)
    print("PASS")


if __name__ == "__main__":
    main()
