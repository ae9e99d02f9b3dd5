#!/usr/bin/python3
"""Reads back the XDMF of scripts/squeal_xdmf.py with meshio's reader and checks it against the
results file it came from.

    check_xdmf.py RESULTS.h5 PREFIX

For PREFIX_mode0.xdmf: the points are /mesh/x, the cells /mesh/cells, the time series has the
requested phases, and at each phase theta the field u at every node equals Re(phi e^{i theta})
read straight from /stability/modes at the node's rows /mesh/dof (1e-12); nodes without rows are 0.
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
    x, dof = r.mesh["x"], r.mesh["dof"]
    m = r.stability.unstable[0]
    phi = r.stability.mode(m)
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
sys.exit(1 if fails else 0)
