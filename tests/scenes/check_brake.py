#!/usr/bin/python3
"""Run squeal on the brake example and check what it imported against the files themselves.

Usage: check_brake.py DIR [--reduced] -- <command...>   (the command writes DIR/stability.h5)

DIR holds make_brake.py's brake_mesh.inp and ccx's brake.dof. Checks: exit 0; the model's DOFs
are the .dof file's lines; its contact points are the PAD_FACE node set's nodes (conforming
faces: one node-to-node pair each); the stability run found at least one unstable mode (the
default brake at mu = 0.4 has several) with a finite frequency.
"""
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402

d = sys.argv[1]
reduced = "--reduced" in sys.argv[:sys.argv.index("--")]
cmd = sys.argv[sys.argv.index("--") + 1:]
out = os.path.join(d, "stability_reduced.h5" if reduced else "stability.h5")
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
        if reduced:
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
sys.exit(1 if fails else 0)
