#!/usr/bin/python3
"""Unstable mode shapes of an FE model, seen on one plane of its mesh (e.g. a disc's face).

    plot_mesh_modes.py RESULTS.h5 --plane-z Z [--modes 2] [--r-hole R] -o modes.png

Colours the normal (z) component of Re(phi) at the mesh nodes with z = Z (from /mesh and
/stability/modes of a squeal results file; -model_type calculix), one panel per unstable mode,
most unstable first. --r-hole masks the triangles inside radius R (an annulus's hole).
"""
import argparse

import h5py
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.tri as mtri
import numpy as np

ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
ap.add_argument("results")
ap.add_argument("--plane-z", type=float, required=True)
ap.add_argument("--modes", type=int, default=2)
ap.add_argument("--r-hole", type=float, default=0.0)
ap.add_argument("-o", "--output", default="modes.png")
a = ap.parse_args()

with h5py.File(a.results, "r") as f:
    x, dof = f["mesh/x"][()], f["mesh/dof"][()]
    ev, freq = f["stability/eigenvalues"][()], f["stability/frequency"][()]
    unstable = f["stability/unstable"][()][:a.modes]
    re = f["stability/modes/re"]
    sel = np.where((np.abs(x[:, 2] - a.plane_z) < 1e-9) & (dof[:, 2] >= 0))[0]
    w = [re[:, m][dof[sel, 2]] for m in unstable]

tri = mtri.Triangulation(x[sel, 0], x[sel, 1])
if a.r_hole > 0:
    c = x[sel][tri.triangles].mean(axis=1)
    tri.set_mask(np.hypot(c[:, 0], c[:, 1]) < a.r_hole)
fig, axes = plt.subplots(1, len(unstable), figsize=(5 * len(unstable), 4.6), squeeze=False)
for ax, m, wm in zip(axes[0], unstable, w):
    lim = np.abs(wm).max()
    tc = ax.tripcolor(tri, wm / lim, shading="gouraud", cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_aspect("equal")
    ax.set_title(f"{freq[m]:.0f} Hz, growth rate {ev[m, 0]:.0f} 1/s")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
fig.colorbar(tc, ax=axes[0].tolist(), shrink=0.8, label="normal displacement (scaled)")
fig.savefig(a.output, dpi=110)
print(f"plot_mesh_modes.py: wrote {a.output}")
