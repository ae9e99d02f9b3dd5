#!/usr/bin/env python3
"""Writes the CalculiX deck of the tests' two-body model: a steel plate (the "disc", clamped on
its face x = 0) and a lining block (the "pad") resting on it, with conforming meshes on the
contact face z = 0, the pad's back face held in x and y and carried by normal springs.

    two_blocks.py OUT.inp [--frequency N] [--shift DX] [--part DISC|PAD]

--frequency N writes a *FREQUENCY step for N eigenvalues instead of the matrix output (the
reference frequencies); --shift moves the pad's mesh in x by DX (non-conforming faces).
--part writes that body alone (its cells, no springs, no boundary): its stiffness for
-model_ccx_damping_parts (tb_disc.*, tb_pad.*).
Node sets: PAD_FACE, DISC_FACE, PAD_BACK, DISC_CLAMP.
"""
import argparse

ap = argparse.ArgumentParser()
ap.add_argument("out")
ap.add_argument("--frequency", type=int, default=0)
ap.add_argument("--shift", type=float, default=0.0)
ap.add_argument("--pad-nx", type=int, default=2)
ap.add_argument("--part", choices=("DISC", "PAD"))
a = ap.parse_args()

L = ["*HEADING", "squeal test: plate + pad, conforming contact face"]
nodes, elems, sets = [], [], {}


def grid(x0, x1, nx, y0, y1, ny, z0, z1, nz, first):
    ids = {}
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                nid = first + len(ids)
                ids[i, j, k] = nid
                nodes.append((nid, x0 + (x1 - x0) * i / nx, y0 + (y1 - y0) * j / ny, z0 + (z1 - z0) * k / nz))
    cells = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                cells.append([ids[i, j, k], ids[i + 1, j, k], ids[i + 1, j + 1, k], ids[i, j + 1, k],
                              ids[i, j, k + 1], ids[i + 1, j, k + 1], ids[i + 1, j + 1, k + 1], ids[i, j + 1, k + 1]])
    return ids, cells


# Plate 0.12 x 0.04 x 0.004 m, 6 x 2 x 1 cells; pad over x in [0.06, 0.10] (2 cells), full width.
dids, dcells = grid(0.0, 0.12, 6, 0.0, 0.04, 2, -0.004, 0.0, 1, 1)
pids, pcells = grid(0.06 + a.shift, 0.10 + a.shift, a.pad_nx, 0.0, 0.04, 2, 0.0, 0.01, 2, 1001)
sets["DISC_CLAMP"] = [n for (i, j, k), n in dids.items() if i == 0]
sets["DISC_FACE"] = [n for (i, j, k), n in dids.items() if k == 1 and 3 <= i <= 5]
sets["PAD_FACE"] = [n for (i, j, k), n in pids.items() if k == 0]
sets["PAD_BACK"] = [n for (i, j, k), n in pids.items() if k == 2]

L.append("*NODE, NSET=NALL")
L += [f"{n}, {x:.12g}, {y:.12g}, {z:.12g}" for n, x, y, z in nodes]
if a.part in (None, "DISC"):
    L.append("*ELEMENT, TYPE=C3D8, ELSET=DISC")
    L += [f"{e + 1}, " + ", ".join(map(str, c)) for e, c in enumerate(dcells)]
if a.part in (None, "PAD"):
    L.append("*ELEMENT, TYPE=C3D8, ELSET=PAD")
    L += [f"{e + 101}, " + ", ".join(map(str, c)) for e, c in enumerate(pcells)]
if a.part:
    L += ["*MATERIAL, NAME=STEEL", "*ELASTIC", "210e9, 0.3", "*DENSITY", "7850.",
          "*MATERIAL, NAME=LINING", "*ELASTIC", "2.0e9, 0.25", "*DENSITY", "2500.",
          f"*SOLID SECTION, ELSET={a.part}, MATERIAL={'STEEL' if a.part == 'DISC' else 'LINING'}",
          "*STEP", "*FREQUENCY, SOLVER=MATRIXSTORAGE", "*END STEP"]
    open(a.out, "w").write("\n".join(L) + "\n")
    raise SystemExit(0)
# Normal springs under the pad's back face: one SPRING1 element per node, along z.
L.append("*ELEMENT, TYPE=SPRING1, ELSET=SUPPORT")
L += [f"{e + 201}, {n}" for e, n in enumerate(sets["PAD_BACK"])]
for name, ids in sets.items():
    L.append(f"*NSET, NSET={name}")
    L += [", ".join(map(str, ids[i:i + 8])) for i in range(0, len(ids), 8)]
L += ["*MATERIAL, NAME=STEEL", "*ELASTIC", "210e9, 0.3", "*DENSITY", "7850.",
      "*MATERIAL, NAME=LINING", "*ELASTIC", "2.0e9, 0.25", "*DENSITY", "2500.",
      "*SOLID SECTION, ELSET=DISC, MATERIAL=STEEL", "*SOLID SECTION, ELSET=PAD, MATERIAL=LINING",
      "*SPRING, ELSET=SUPPORT", "3", "2.0e6",
      "*BOUNDARY", "DISC_CLAMP, 1, 3", "PAD_BACK, 1, 2",
      "*STEP", "*FREQUENCY" + ("" if a.frequency else ", SOLVER=MATRIXSTORAGE")]
if a.frequency:
    L.append(str(a.frequency))
L.append("*END STEP")
open(a.out, "w").write("\n".join(L) + "\n")
