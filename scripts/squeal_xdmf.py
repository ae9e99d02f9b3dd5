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
component is 1) and "has_value" (1 where the node has a value).

A reduced model's results are written expanded to the whole mesh when the file has them
(/expanded and /mesh/dof_full: squeal keeps the reduction's expansion for a model with a mesh,
-reduce_expand): the unstable modes, the cycle and the transient's last records
(-reduce_expand_records). Without them, or with --no-expanded, only the DOFs the reduced model keeps
physical are on the mesh (Craig-Bampton: the contact nodes'); the others have has_value 0 and are
drawn at rest.
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
    ap.add_argument("--no-expanded", action="store_true",
                    help="write the reduced model's own vectors (contact nodes only) even when /expanded is there")
    a = ap.parse_args(argv)
    prefix = a.prefix or os.path.splitext(a.results)[0]
    written = []
    with Results(a.results) as r:
        if r.mesh is None:
            sys.exit(f"squeal_xdmf.py: error: '{a.results}' has no /mesh group: only models read from an FE code "
                     "(-model_type calculix) carry their mesh")
        points = r.mesh["x"]
        cells = [(XDMF_TO_MESHIO[name], r.mesh["cells"][name]) for name in r.mesh["cells"].keys()]
        expanded = "expanded" in r and "dof_full" in r.mesh and not a.no_expanded
        dof = (r.mesh["dof_full"] if expanded else r.mesh["dof"]).astype(np.int64)
        s = r.stability
        if expanded and "expanded/modes/re" in r:
            re, im = r.h5["expanded/modes/re"][()], r.h5["expanded/modes/im"][()]
            shapes = [re[:, j] + 1j * im[:, j] for j in range(re.shape[1])]
        elif not expanded and s is not None and "unstable" in s and "modes" in s:
            shapes = [s.mode(m) for m in s.unstable]
        else:
            shapes = []
        for rank, phi in enumerate(shapes[:a.modes]):
            frames = [(j / a.phases, np.real(phi * np.exp(2j * np.pi * j / a.phases))) for j in range(a.phases)]
            written.append(write_series(f"{prefix}_mode{rank}.xdmf", points, cells, dof, frames))
        orbit = "expanded/orbit" if expanded else "shooting/orbit"
        if f"{orbit}/U" in r:
            t, U = r.h5[f"{orbit}/t"][()], r.h5[f"{orbit}/U"][()]
            written.append(write_series(f"{prefix}_cycle.xdmf", points, cells, dof, zip(t, U)))
        records = "expanded/transient" if expanded and "expanded/transient/U" in r else "transient"
        if f"{records}/U" in r and f"{records}/t" in r:
            t, U = r.h5[f"{records}/t"][()], r.h5[f"{records}/U"][()]
            written.append(write_series(f"{prefix}_transient.xdmf", points, cells, dof, zip(t, U)))
    if not written:
        sys.exit(f"squeal_xdmf.py: error: '{a.results}' holds no unstable mode, cycle or transient to write")
    for w in written:
        print(f"squeal_xdmf.py: wrote {w} (+ .h5)")


if __name__ == "__main__":
    main()
