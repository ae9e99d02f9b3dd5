#!/usr/bin/python3
"""Results of an FE model on its mesh, as XDMF + HDF5 time series that ParaView opens.

    squeal_xdmf.py RESULTS.h5 [-o PREFIX] [--phases 24] [--modes K]

RESULTS.h5 is a squeal results file of a model with a mesh (-model_type calculix): it holds
/mesh (node coordinates, cells, and the row of the model's vectors for each node's x, y, z).
Writes, next to PREFIX (default: RESULTS without .h5), one time series each:
  PREFIX_mode<k>.xdmf   unstable mode k (most unstable first) over one period of phase:
                        Re(phi exp(i theta)), theta = 2 pi j / phases, as time j / phases;
  PREFIX_cycle.xdmf     the limit cycle's period (/shooting/orbit), time in s;
  PREFIX_transient.xdmf the transient's records (/transient), time in s.
Each has the point field "u" (m; modes normalised so that the largest contact tangential
component is 1) and "has_value" (1 where the model holds the node's DOFs: a Craig-Bampton
reduction keeps only the contact nodes' DOFs physical, the rest are 0 and drawn at rest).
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.results import Results  # noqa: E402

try:
    import meshio
except ImportError:
    sys.exit("squeal_xdmf.py: error: the meshio module is missing; install Debian's python3-meshio")

XDMF_TO_MESHIO = {"Hexahedron": "hexahedron", "Hexahedron_20": "hexahedron20", "Tetrahedron": "tetra",
                  "Tetrahedron_10": "tetra10", "Wedge": "wedge", "Wedge_15": "wedge15"}


def nodal(dof, vec):
    """Vector rows -> (n, 3) nodal values; 0 where the node has no row."""
    u = np.zeros(dof.shape)
    has = dof >= 0
    u[has] = vec[dof[has]]
    return u


def write_series(path, points, cells, dof, frames):
    has = (dof >= 0).all(axis=1).astype(float)
    # meshio 7.0 (Debian 12) writes the .h5 into the working folder but names it relative to the
    # .xdmf: write from the .xdmf's folder so that both land together.
    here = os.getcwd()
    os.chdir(os.path.dirname(os.path.abspath(path)))
    try:
        with meshio.xdmf.TimeSeriesWriter(os.path.basename(path)) as w:
            w.write_points_cells(points, cells)
            for t, vec in frames:
                w.write_data(float(t), point_data={"u": nodal(dof, vec), "has_value": has})
    finally:
        os.chdir(here)
    return path


def main(argv=None, prog=None):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("-o", "--prefix")
    ap.add_argument("--phases", type=int, default=24)
    ap.add_argument("--modes", type=int, default=3, help="unstable modes to write, most unstable first (default 3)")
    a = ap.parse_args(argv)
    prefix = a.prefix or os.path.splitext(a.results)[0]
    written = []
    with Results(a.results) as r:
        if r.mesh is None:
            sys.exit(f"squeal_xdmf.py: error: '{a.results}' has no /mesh group: only models read from an FE code "
                     "(-model_type calculix) carry their mesh")
        points = r.mesh["x"]
        dof = r.mesh["dof"].astype(np.int64)
        cells = [(XDMF_TO_MESHIO[name], r.mesh["cells"][name]) for name in r.mesh["cells"].keys()]
        s = r.stability
        if s is not None and "unstable" in s and "modes" in s:
            for rank, m in enumerate(s.unstable[:a.modes]):
                phi = s.mode(m)
                frames = [(j / a.phases, np.real(phi * np.exp(2j * np.pi * j / a.phases))) for j in range(a.phases)]
                written.append(write_series(f"{prefix}_mode{rank}.xdmf", points, cells, dof, frames))
        if "shooting/orbit/U" in r:
            t, U = r.shooting["orbit/t"], r.shooting["orbit/U"]
            written.append(write_series(f"{prefix}_cycle.xdmf", points, cells, dof, zip(t, U)))
        if "transient/U" in r and "transient/t" in r:
            t, U = r.transient["t"], r.transient["U"]
            written.append(write_series(f"{prefix}_transient.xdmf", points, cells, dof, zip(t, U)))
    if not written:
        sys.exit(f"squeal_xdmf.py: error: '{a.results}' holds no unstable mode, cycle or transient to write")
    for w in written:
        print(f"squeal_xdmf.py: wrote {w} (+ .h5)")


if __name__ == "__main__":
    main()
