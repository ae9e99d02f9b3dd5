#!/usr/bin/python3
"""Craig-Bampton reduction error against run time (issue 8, item 3).

Runs squeal's stability analysis on the full pad model once and on its Craig-Bampton reductions
for a list of cut-off frequencies, and prints, per cut-off: reduced size, modes kept, reduction
time, stability time, and the largest relative error of the unstable eigenvalues of the full
model (each matched to the nearest reduced eigenvalue).

  /usr/bin/python3 scripts/reduction_report.py --squeal build/squeal --scene examples/pad/pad.yaml \
      --fmax 12000 15000 20000 30000 40000 [--band 10000] [--np 2]
  31119-DOF pad (full stability run ~3 min; keep its results file and pass it with --full-h5):
  /usr/bin/python3 scripts/reduction_report.py --scene examples/pad/pad_large.yaml --band 10000 \
      --fmax 10000 20000 30000 [--full-h5 full.h5]
  With interface reduction (-reduce_interface_modes k; -1: none) for each cut-off:
  /usr/bin/python3 scripts/reduction_report.py --scene examples/pad/pad.yaml --band 10000 \
      --fmax 20000 --interface-modes -1 100 200 300 350
"""
import argparse
import os
import re
import subprocess
import tempfile
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.results import Results  # noqa: E402


def run(cmd, np_):
    if np_ > 1:
        cmd = ["mpiexec", "--oversubscribe", "-n", str(np_)] + cmd
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    t0 = time.time()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.time() - t0
    if p.returncode != 0:
        raise SystemExit("failed: %s\n%s%s" % (" ".join(cmd), p.stdout[-2000:], p.stderr[-2000:]))
    return p.stdout, wall


def unstable(h5):
    with Results(h5) as r:
        ev, idx = r.stability.eigenvalues, r.stability.unstable
        lam = ev[:, 0] + 1j * ev[:, 1]
        return lam, np.array([lam[i] for i in idx])


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--squeal", default="build/squeal")
    ap.add_argument("--scene", default="examples/pad/pad.yaml")
    ap.add_argument("--fmax", type=float, nargs="+", default=[12000, 15000, 20000, 30000, 40000])
    ap.add_argument("--band", type=float, default=0, help="only unstable eigenvalues of the full model below this frequency (Hz)")
    ap.add_argument("--np", type=int, default=1)
    ap.add_argument("--full-np", type=int, default=1)
    ap.add_argument("--full-h5", default="", help="reuse this results file of the full model's stability run (skips that run)")
    ap.add_argument("--interface-modes", type=int, nargs="+", default=[-1],
                    help="in-plane interface modes kept (-reduce_interface_modes; -1: no interface reduction)")
    ap.add_argument("--extra", nargs=argparse.REMAINDER, default=[])
    a = ap.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix="reduction_report_")
    base = [a.squeal, "-scene", a.scene, "-analyses", "stability", "-eq_mat_mumps_icntl_14", "200"] + a.extra
    if a.full_h5:
        _, ref = unstable(a.full_h5)
        n, wall = "(from %s)" % a.full_h5, float("nan")
    else:
        out, wall = run(base + ["-output", os.path.join(tmp, "full.h5")], a.full_np)
        _, ref = unstable(os.path.join(tmp, "full.h5"))
        n = re.search(r"(\d+) DOFs", out).group(1)
    if a.band > 0:
        ref = np.array([l for l in ref if l.imag / (2 * np.pi) <= a.band])
    print("full model: %s DOFs, %d unstable eigenvalue(s), stability run %.2f s (wall, %d rank(s))" % (n, len(ref), wall, a.full_np))
    for l in ref:
        print("  sigma = %.6g 1/s, f = %.6g Hz" % (l.real, l.imag / (2 * np.pi)))
    print("%9s %7s %6s %7s %10s %10s %12s %12s %8s" % ("fmax(Hz)", "N_red", "modes", "k_iface", "reduce(s)", "run(s)", "max rel err",
                                                      "max |dsig|/|l|", "unstable"))
    for fm in a.fmax:
        for k in a.interface_modes:
            h5 = os.path.join(tmp, "red_%g_%d.h5" % (fm, k))
            out, wall = run(base + ["-reduce_type", "craig_bampton", "-reduce_fmax", str(fm), "-reduce_interface_modes", str(k),
                                    "-output", h5], a.np)
            m = re.search(r"-> (\d+) \((\d+) interface DOFs of the contact nodes \+ (\d+) fixed-interface", out)
            mi = re.search(r"characteristic constraint modes of the interface \(.*\): (\d+) DOFs", out)
            # k_iface: the interface modes kept, "+ s" the statics of the normals added to them
            # (-reduce_interface_statics, on by default for pairs).
            ms = re.search(r"\+ (\d+) characteristic constraint modes of the interface(?: \((\d+) of them the statics)?", out)
            kcol = "-" if k < 0 or not ms else (ms.group(1) if not ms.group(2) else
                                                "%d+%s" % (int(ms.group(1)) - int(ms.group(2)), ms.group(2)))
            t = re.search(r"time ([0-9.]+) s", out)
            lam, unst = unstable(h5)
            err = [np.min(np.abs(lam - r)) / abs(r) for r in ref]
            dsig = [abs(lam[np.argmin(np.abs(lam - r))].real - r.real) / abs(r) for r in ref]
            print("%9g %7s %6s %7s %10s %10.2f %12.3e %12.3e %8d" % (fm, mi.group(1) if mi else m.group(1), m.group(3), kcol,
                                                            t.group(1), wall, max(err), max(dsig), len(unst)))


if __name__ == "__main__":
    main()
