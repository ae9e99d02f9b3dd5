"""Unstable mode shapes, or snapshots of the limit cycle, of an FE model seen on one plane of its
mesh (e.g. a disc's face).

    plot_mesh_modes.py RESULTS.h5 --plane-z Z [--modes 2] [--r-hole R] -o modes.png
    plot_mesh_modes.py RESULTS.h5 --plane-z Z --cycle 4 [--r-hole R] -o cycle.png

Colours the normal (z) component at the mesh nodes with z = Z (from /mesh and the results of a
squeal results file; -model_type calculix): of Re(phi), one panel per unstable mode, most unstable
first; with --cycle K, of the cycle's displacement about its mean over the period at K instants of
the period, on one colour scale. A reduced model's expanded results (/expanded, /mesh/dof_full) are
used when the file has them, so every node of the plane is drawn. --r-hole masks the triangles
inside radius R (an annulus's hole).
"""
import argparse

import matplotlib.tri as mtri
import numpy as np

from ..results import Results
from .common import plt


def _source(r, cycle):
    """(dof map, panels as (title, values per DOF)) from the expanded results when there are some."""
    expanded = "expanded" in r and "dof_full" in r.mesh
    dof = r.mesh["dof_full"] if expanded else r.mesh["dof"]
    if cycle:
        orbit = "expanded/orbit" if expanded else "shooting/orbit"
        if f"{orbit}/U" not in r:
            raise SystemExit(f"plot_mesh_modes.py: error: '{r.path}' has no /{orbit} (run -analyses shooting or auto to a cycle)")
        t, U = r.h5[f"{orbit}/t"][()], r.h5[f"{orbit}/U"][()]
        T = t[-1] - t[0]
        dU = U - U[:-1].mean(axis=0)
        picks = [int(round(k * (len(t) - 1) / cycle)) for k in range(cycle)]
        return dof, [(f"t = {k}/{cycle} T (T = {T * 1e3:.4f} ms)", dU[i]) for k, i in enumerate(picks)], "normal displacement about the mean (m)"
    s = r.stability
    ev, freq = s.eigenvalues, s.frequency
    if expanded and "expanded/modes/re" in r:
        re, idx = r.h5["expanded/modes/re"][()], r.h5["expanded/modes/index"][()]
    else:
        re, idx = s.dataset("modes/re")[()], s.unstable
        re = re[:, idx]
    return dof, [(f"{freq[m]:.0f} Hz, growth rate {ev[m, 0]:.0f} 1/s", re[:, j]) for j, m in enumerate(idx)], None


def plot(results, plane_z, modes=2, r_hole=0.0, out="modes.png", cycle=0):
    with Results(results) as r:
        x = r.mesh["x"]
        dof, panels, label = _source(r, cycle)
        if not cycle:
            panels = panels[:modes]
        sel = np.where((np.abs(x[:, 2] - plane_z) < 1e-9) & (dof[:, 2] >= 0))[0]
        if sel.size < 3:
            raise SystemExit(f"plot_mesh_modes.py: error: fewer than 3 nodes with values on the plane z = {plane_z:g}")
        w = [v[dof[sel, 2]] for _, v in panels]

    tri = mtri.Triangulation(x[sel, 0], x[sel, 1])
    if r_hole > 0:
        c = x[sel][tri.triangles].mean(axis=1)
        tri.set_mask(np.hypot(c[:, 0], c[:, 1]) < r_hole)
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.6), squeeze=False)
    common = max(np.abs(wm).max() for wm in w) if cycle else None
    for i, (ax, (title, _), wm) in enumerate(zip(axes[0], panels, w)):
        lim = common or np.abs(wm).max()
        scale = 1 if cycle else lim
        tc = ax.tripcolor(tri, wm / scale, shading="gouraud", cmap="RdBu_r", vmin=-lim / scale, vmax=lim / scale)
        ax.set_aspect("equal")
        ax.set_title(title)
        ax.set_xlabel("x (m)")
        if i == 0:
            ax.set_ylabel("y (m)")
    fig.colorbar(tc, ax=axes[0].tolist(), shrink=0.8, label=label or "normal displacement (scaled)")
    fig.savefig(out, dpi=110, bbox_inches="tight")


def main(argv=None, prog=None):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("--plane-z", type=float, required=True)
    ap.add_argument("--modes", type=int, default=2)
    ap.add_argument("--r-hole", type=float, default=0.0)
    ap.add_argument("--cycle", type=int, default=0, help="snapshots of the limit cycle at K instants of its period instead of modes")
    ap.add_argument("-o", "--output", default="modes.png")
    a = ap.parse_args(argv)
    plot(a.results, a.plane_z, a.modes, a.r_hole, a.output, a.cycle)
    print(f"plot_mesh_modes.py: wrote {a.output}")
