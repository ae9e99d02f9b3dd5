#!/usr/bin/python3
"""Run squeal on the brake example and check what it imported against the files themselves.

Usage: check_brake.py DIR [--reduced [--interface] [--expanded FULL.h5 [--eig-tol TOL] [--shape-tol TOL]]] -- <command...>
       (the command writes its -output, by default DIR/stability.h5, with --reduced DIR/stability_reduced.h5)

DIR holds make_brake.py's brake_mesh.inp and ccx's brake.dof. Checks: exit 0; the model's DOFs
are the .dof file's lines; its contact points are the PAD_FACE node set's nodes (conforming
faces: one node-to-node pair each); the stability run found at least one unstable mode (the
default brake at mu = 0.4 has several) with a finite frequency. With --expanded FULL.h5 (the full
model's stability run at the same operating point): /mesh/dof_full is FULL.h5's /mesh/dof, and
the reduced model's most unstable mode expanded to the whole mesh (/expanded/modes) is the full
model's mode of the nearest eigenvalue, to 1e-2 after the best complex scaling (both normalised
alike; the distance is printed). --interface: the reduction has interface reduction, so no DOF of
the mesh stays physical (/mesh rows all -1). --eig-tol TOL: every unstable eigenvalue of FULL.h5
has a reduced one within TOL (relative). --shape-tol: the mode shape's tolerance (default 1e-2).
"""
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402

d = sys.argv[1]
opts = sys.argv[:sys.argv.index("--")]
reduced = "--reduced" in opts
interface = "--interface" in opts
shape_tol = float(opts[opts.index("--shape-tol") + 1]) if "--shape-tol" in opts else 1e-2
eig_tol = float(opts[opts.index("--eig-tol") + 1]) if "--eig-tol" in opts else None
full_h5 = opts[opts.index("--expanded") + 1] if "--expanded" in opts else None
cmd = sys.argv[sys.argv.index("--") + 1:]
out = cmd[cmd.index("-output") + 1] if "-output" in cmd else os.path.join(d, "stability_reduced.h5" if reduced else "stability.h5")
if os.path.exists(out):
    os.remove(out)
rc = subprocess.call(cmd)
fails = 0


def check(cond, msg):
    global fails
    print(("ok:   " if cond else "FAIL: ") + msg)
    fails += not cond


check(rc == 0, f"squeal exit code {rc}")
if rc == 0:
    ndof = sum(1 for line in open(os.path.join(d, "brake.dof")) if line.strip())
    pad, inset = set(), False
    for line in open(os.path.join(d, "brake_mesh.inp")):
        if line.startswith("*"):
            inset = line.upper().replace(" ", "").startswith("*NSET,NSET=PAD_FACE")
        elif inset:
            pad.update(int(t) for t in line.replace(",", " ").split())
    with Results(out) as r:
        m = r.model
        rows = r.mesh["dof"]
        if reduced and interface:
            # One relative normal coordinate per pair and modes: no mesh DOF stays physical.
            check(int(r.mesh.attrs["partial"]) == 1, "/mesh is partial")
            check(int((rows >= 0).sum()) == 0, "no mesh row physical (interface reduction)")
        elif reduced:
            # Craig-Bampton keeps the pad- and disc-face nodes' DOFs physical, and only those.
            check(int(r.mesh.attrs["partial"]) == 1, "/mesh is partial")
            check(int((rows >= 0).sum()) == 6 * len(pad), f"{int((rows >= 0).sum())} mesh rows = 2 x 3 x PAD_FACE nodes")
            check(int(rows.max()) < int(m["dofs"]), "mesh rows inside the reduced model")
        else:
            check(int(m["dofs"]) == ndof, f"model DOFs {int(m['dofs'])} = rows of brake.dof {ndof}")
            check(int((rows >= 0).sum()) == ndof, "every row of brake.dof on the mesh")
        check(int(m["contact_points"]) == len(pad), f"contact points {int(m['contact_points'])} = PAD_FACE nodes {len(pad)}")
        unstable = r.stability.unstable
        freq = r.stability.frequency
        check(len(unstable) >= 1, f"{len(unstable)} unstable mode(s)")
        check(all(0 < freq[i] < 1e5 for i in unstable), "unstable frequencies finite, in (0, 100 kHz)")
        if full_h5:
            import numpy as np
            check("expanded/modes/re" in r and "dof_full" in r.mesh, "/expanded/modes and /mesh/dof_full written")
            with Results(full_h5) as f:
                check(np.array_equal(r.mesh["dof_full"], f.mesh["dof"]), "/mesh/dof_full = the full model's /mesh/dof")
                lam = complex(*r.stability.eigenvalues[unstable[0]])
                ev = f.stability.eigenvalues[:, 0] + 1j * f.stability.eigenvalues[:, 1]
                j = int(np.argmin(np.abs(ev - lam)))
                ref = f.stability.mode(j)
                e = r.h5["expanded/modes/re"][:, 0] + 1j * r.h5["expanded/modes/im"][:, 0]
                a = np.vdot(e, ref) / np.vdot(e, e)
                dist = np.linalg.norm(ref - a * e) / np.linalg.norm(ref)
                check(abs(ev[j] - lam) < 1e-2 * abs(lam), f"reduced {lam.imag / 2 / np.pi:.2f} Hz (sigma {lam.real:.1f}) next to "
                      f"the full model's {ev[j].imag / 2 / np.pi:.2f} Hz (sigma {ev[j].real:.1f})")
                check(dist < shape_tol, f"expanded mode shape against the full model's: relative distance {dist:.2e} "
                      f"(scale {abs(a):.4f})")
                if eig_tol is not None:
                    mine = r.stability.eigenvalues[:, 0] + 1j * r.stability.eigenvalues[:, 1]
                    worst = max(np.min(np.abs(mine - ev[i])) / abs(ev[i]) for i in f.stability.unstable)
                    check(worst < eig_tol, f"{len(f.stability.unstable)} unstable eigenvalues of the full model matched within "
                          f"{worst:.2e} (relative; tolerance {eig_tol:g})")
sys.exit(1 if fails else 0)
