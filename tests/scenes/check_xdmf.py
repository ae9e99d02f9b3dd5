#!/usr/bin/python3
"""Reads back the XDMF of scripts/squeal_xdmf.py with meshio's reader and checks it against the
results file it came from.

    check_xdmf.py RESULTS.h5 PREFIX

For PREFIX_mode0.xdmf: the points are /mesh/x, the cells /mesh/cells, the time series has the
requested phases, and at each phase theta the field u at every node equals Re(phi e^{i theta})
read straight from /stability/modes at the node's rows /mesh/dof (1e-12); nodes without rows are 0.
A reduced model's file with /expanded: the mode is /expanded/modes' first column, at the rows
/mesh/dof_full; every node then has a value, and the cycle (if any) is checked alike.
"""
import os
import sys

import meshio
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402

res, prefix = sys.argv[1], sys.argv[2]
fails = 0


def check(cond, msg):
    global fails
    print(("ok:   " if cond else "FAIL: ") + msg)
    fails += not cond


with Results(res) as r:
    x = r.mesh["x"]
    expanded = "expanded/modes/re" in r
    if expanded:
        dof = r.mesh["dof_full"]
        phi = r.h5["expanded/modes/re"][:, 0] + 1j * r.h5["expanded/modes/im"][:, 0]
        n_full = r.h5["expanded/modes/re"].shape[0]
        check(int((dof >= 0).sum()) == n_full, f"expanded: the mesh nodes' rows are the full model's {n_full} DOFs")
    else:
        dof = r.mesh["dof"]
        phi = r.stability.mode(r.stability.unstable[0])
    cycle = (r.h5["expanded/orbit/t"][()], r.h5["expanded/orbit/U"][()]) if "expanded/orbit/U" in r else None
    cells = r.mesh["cells"]
    ncells = sum(cells.dataset(k).shape[0] for k in cells.keys())

r = meshio.xdmf.TimeSeriesReader(prefix + "_mode0.xdmf")
points, cells = r.read_points_cells()
check(np.array_equal(points, x), f"{len(points)} points = /mesh/x")
check(sum(len(c.data) for c in cells) == ncells, f"{ncells} cells")
n = r.num_steps
check(n == 24, f"{n} phases")
worst = 0.0
for k in range(n):
    t, pd, _ = r.read_data(k)
    ref = np.where(dof >= 0, np.real(phi * np.exp(2j * np.pi * t))[np.maximum(dof, 0)], 0.0)
    worst = max(worst, np.abs(pd["u"] - ref).max())
check(worst < 1e-12, f"u = Re(phi exp(i theta)) at every node and phase (max difference {worst:.1e})")
if cycle is not None:
    r = meshio.xdmf.TimeSeriesReader(prefix + "_cycle.xdmf")
    r.read_points_cells()
    check(r.num_steps == len(cycle[0]), f"{r.num_steps} cycle samples")
    worst = 0.0
    for k in range(r.num_steps):
        t, pd, _ = r.read_data(k)
        worst = max(worst, np.abs(pd["u"] - np.where(dof >= 0, cycle[1][k][np.maximum(dof, 0)], 0.0)).max())
    check(worst < 1e-15, f"cycle: u = /expanded/orbit/U at every node and sample (max difference {worst:.1e})")
sys.exit(1 if fails else 0)
