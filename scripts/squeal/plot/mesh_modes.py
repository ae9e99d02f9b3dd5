"""Unstable mode shapes of an FE model, seen on one plane of its mesh (e.g. a disc's face).

    plot_mesh_modes.py RESULTS.h5 --plane-z Z [--modes 2] [--r-hole R] -o modes.png

Colours the normal (z) component of Re(phi) at the mesh nodes with z = Z (from /mesh and
/stability/modes of a squeal results file; -model_type calculix), one panel per unstable mode,
most unstable first. --r-hole masks the triangles inside radius R (an annulus's hole).
"""
import argparse

import matplotlib.tri as mtri
import numpy as np

from ..results import Results
from .common import plt


def plot(results, plane_z, modes=2, r_hole=0.0, out="modes.png"):
    with Results(results) as r:
        x, dof = r.mesh["x"], r.mesh["dof"]
        s = r.stability
        ev, freq = s.eigenvalues, s.frequency
        unstable = s.unstable[:modes]
        re = s.dataset("modes/re")
        sel = np.where((np.abs(x[:, 2] - plane_z) < 1e-9) & (dof[:, 2] >= 0))[0]
        w = [re[:, m][dof[sel, 2]] for m in unstable]

    tri = mtri.Triangulation(x[sel, 0], x[sel, 1])
    if r_hole > 0:
        c = x[sel][tri.triangles].mean(axis=1)
        tri.set_mask(np.hypot(c[:, 0], c[:, 1]) < r_hole)
    fig, axes = plt.subplots(1, len(unstable), figsize=(5 * len(unstable), 4.6), squeeze=False)
    for ax, m, wm in zip(axes[0], unstable, w):
        lim = np.abs(wm).max()
        tc = ax.tripcolor(tri, wm / lim, shading="gouraud", cmap="RdBu_r", vmin=-1, vmax=1)
        ax.set_aspect("equal")
        ax.set_title(f"{freq[m]:.0f} Hz, growth rate {ev[m, 0]:.0f} 1/s")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.colorbar(tc, ax=axes[0].tolist(), shrink=0.8, label="normal displacement (scaled)")
    fig.savefig(out, dpi=110)


def main(argv=None, prog=None):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("--plane-z", type=float, required=True)
    ap.add_argument("--modes", type=int, default=2)
    ap.add_argument("--r-hole", type=float, default=0.0)
    ap.add_argument("-o", "--output", default="modes.png")
    a = ap.parse_args(argv)
    plot(a.results, a.plane_z, a.modes, a.r_hole, a.output)
    print(f"plot_mesh_modes.py: wrote {a.output}")
