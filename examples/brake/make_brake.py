#!/usr/bin/env python3
"""A disc brake for squeal, meshed by gmsh and assembled by CalculiX (docs/fe-workflow.md).

    make_brake.py OUTDIR [--size S] [--job brake] [--no-ccx]

Geometry (m): a steel disc, annulus r in [0.08, 0.15], 0.012 thick (z in [-0.012, 0]), clamped on
its inner rim; a pad (0.010 lining on a 0.005 steel backplate) on the sector r in [0.10, 0.14],
angle in [-25, 25] degrees, resting on the disc's top face z = 0. Both bodies are hexahedral
(transfinite, recombined) and their meshes conform on the contact face: the pad's friction-face
nodes sit on disc nodes, at the same place but distinct (node-to-node pairs). The pad's back is held
by springs (the caliper) and pushed by a pressure (the piston; the scene's -model_ccx_pressure).
--size S multiplies the numbers of divisions (S = 1: about 16 000 DOFs and 176 contact pairs).

Writes OUTDIR/JOB_mesh.inp (gmsh's Abaqus export: nodes, C3D8 cells, node sets of the physical
groups), OUTDIR/JOB.inp (the CalculiX deck: materials, springs, clamp, the MATRIXSTORAGE step),
OUTDIR/JOB_lining.inp and JOB_lining_mesh.inp (the lining alone, whose stiffness the scene damps
on its own: -model_ccx_damping_parts) and, unless --no-ccx, runs `ccx -i JOB` and
`ccx -i JOB_lining` there, which write JOB.sti, JOB.mas, JOB.dof and JOB_lining.sti, .mas, .dof.
Node sets: PAD_FACE, DISC_FACE, PAD_BACK, DISC_CLAMP.
"""
import argparse
import math
import os
import shutil
import subprocess
import sys
import time

ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
ap.add_argument("outdir")
ap.add_argument("--size", type=float, default=1.0, help="mesh refinement factor (default 1)")
ap.add_argument("--job", default="brake")
ap.add_argument("--no-ccx", action="store_true", help="write the deck only")
ap.add_argument("--support-kt", type=float, default=5.0e10,
                help="caliper's in-plane support stiffness per unit back-face area, N/m per m^2 (default 5e10)")
ap.add_argument("--support-kn", type=float, default=2.0e10,
                help="normal support stiffness (piston) per unit back-face area, N/m per m^2 (default 2e10)")
a = ap.parse_args()

try:
    import gmsh
except ImportError:
    sys.exit("make_brake.py: error: the gmsh Python module is missing; install Debian's python3-gmsh "
             "(apt-get install python3-gmsh) and run with /usr/bin/python3")
if not a.no_ccx and shutil.which("ccx") is None:
    sys.exit("make_brake.py: error: CalculiX's ccx is not on PATH; install Debian's calculix-ccx "
             "(apt-get install calculix-ccx), or pass --no-ccx to write the deck only")

R_IN, R_OUT, H_DISC = 0.08, 0.15, 0.012
P_IN, P_OUT, P_HALF = 0.10, 0.14, math.radians(25.0)
H_LINING, H_BACK = 0.010, 0.005
S = a.size
n_pad_t = max(2, round(15 * S))                     # divisions of the pad sector in angle
n_pad_r = max(2, round(10 * S))                     # ... in radius (and the disc's between P_IN and P_OUT)
dtheta = 2 * P_HALF / n_pad_t
n_rest_t = max(3, round((2 * math.pi - 2 * P_HALF) / (1.5 * dtheta)))  # the rest of the disc: 1.5x longer cells
n_in_r = max(1, round((P_IN - R_IN) / ((P_OUT - P_IN) / n_pad_r)))
n_out_r = max(1, round((R_OUT - P_OUT) / ((P_OUT - P_IN) / n_pad_r)))
n_disc_z = max(2, round(3 * S))
n_lin_z, n_back_z = max(2, round(2 * S)), max(1, round(1 * S))

os.makedirs(a.outdir, exist_ok=True)
t0 = time.time()
# Errors only: at -v 2 gmsh prints a warning per projection on the curved faces (xyz error ~5e-5 m,
# 40 lines at size 1) that changes nothing here (the pad and disc faces still conform to 1e-10 m).
gmsh.initialize(["gmsh", "-v", "1"])
gmsh.model.add("brake")
geo = gmsh.model.geo


def ring_patch(r0, r1, th0, th1, z, nr, nt):
    """A transfinite quadrilateral patch of an annulus at height z."""
    c = geo.addPoint(0, 0, z)
    p = [geo.addPoint(r * math.cos(t), r * math.sin(t), z) for r, t in ((r0, th0), (r1, th0), (r1, th1), (r0, th1))]
    l0 = geo.addLine(p[0], p[1])
    a1 = geo.addCircleArc(p[1], c, p[2])
    l2 = geo.addLine(p[2], p[3])
    a3 = geo.addCircleArc(p[3], c, p[0])
    for ln, n in ((l0, nr), (l2, nr), (a1, nt), (a3, nt)):
        geo.mesh.setTransfiniteCurve(ln, n + 1)
    s = geo.addPlaneSurface([geo.addCurveLoop([l0, a1, l2, a3])])
    geo.mesh.setTransfiniteSurface(s)
    geo.mesh.setRecombine(2, s)
    return s, (l0, a1, l2, a3)


# Disc top face z = 0 as 3 x 2 patches: radial bands [R_IN, P_IN], [P_IN, P_OUT], [P_OUT, R_OUT]
# times the pad's sector and the rest of the turn (two arcs of at most 180 degrees each).
rest = 2 * math.pi - 2 * P_HALF
sectors = [(-P_HALF, P_HALF, n_pad_t), (P_HALF, P_HALF + rest / 2, n_rest_t // 2),
           (P_HALF + rest / 2, 2 * math.pi - P_HALF, n_rest_t - n_rest_t // 2)]
bands = [(R_IN, P_IN, n_in_r), (P_IN, P_OUT, n_pad_r), (P_OUT, R_OUT, n_out_r)]
disc_top, contact_top, inner_curves = [], [], []
for bi, (r0, r1, nr) in enumerate(bands):
    for si, (t0_, t1_, nt) in enumerate(sectors):
        s, curves = ring_patch(r0, r1, t0_, t1_, 0.0, nr, nt)
        disc_top.append(s)
        if bi == 1 and si == 0:
            contact_top.append(s)
        if bi == 0:
            inner_curves.append(curves[3])  # the arc at r0 = R_IN
geo.removeAllDuplicates()  # the disc's patches share their edges (one body)

# The pad is built PAD_LIFT above its place, so that gmsh keeps its nodes apart from the disc's,
# and moved down onto the disc after meshing: coincident but distinct nodes.
PAD_LIFT = 0.05
pad_face, _ = ring_patch(P_IN, P_OUT, -P_HALF, P_HALF, PAD_LIFT, n_pad_r, n_pad_t)
geo.synchronize()

disc_vols, disc_bottom_lat = [], []
ext_disc = {}
for s in disc_top:
    out = geo.extrude([(2, s)], 0, 0, -H_DISC, numElements=[n_disc_z], recombine=True)
    ext_disc[s] = out
    disc_vols.append(out[1][1])
lin = geo.extrude([(2, pad_face)], 0, 0, H_LINING, numElements=[n_lin_z], recombine=True)
back = geo.extrude([(2, lin[0][1])], 0, 0, H_BACK, numElements=[n_back_z], recombine=True)
geo.synchronize()

# The inner rim: lateral faces of the disc's extrusions that lie on r = R_IN.
clamp = []
for s in disc_top:
    for dim, tag in ext_disc[s][2:]:
        pts = gmsh.model.getBoundary([(dim, tag)], recursive=True)
        rs = [math.hypot(*gmsh.model.getValue(0, p[1], [])[:2]) for p in pts]
        if rs and max(rs) < R_IN * (1 + 1e-9):
            clamp.append(tag)

groups = {}


def group(dim, tags, name):
    # gmsh 4.8 (Debian 12) has no name= argument yet
    groups[name] = gmsh.model.addPhysicalGroup(dim, tags)
    gmsh.model.setPhysicalName(dim, groups[name], name)


group(3, disc_vols, "DISC")
group(3, [lin[1][1]], "LINING")
group(3, [back[1][1]], "BACKPLATE")
group(2, contact_top, "DISC_FACE")
group(2, [pad_face], "PAD_FACE")
group(2, [back[0][1]], "PAD_BACK")
group(2, clamp, "DISC_CLAMP")
gmsh.option.setNumber("Mesh.SaveGroupsOfNodes", 1)
gmsh.model.mesh.generate(3)
moved = set()
for vol in (lin[1][1], back[1][1]):
    tags, xyz, _ = gmsh.model.mesh.getNodes(3, vol, includeBoundary=True)
    for i, t in enumerate(tags):
        if t not in moved:
            moved.add(t)
            gmsh.model.mesh.setNode(int(t), [xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2] - PAD_LIFT], [])
mesh_file = os.path.join(a.outdir, a.job + "_mesh.inp")
gmsh.write(mesh_file)
# gmsh writes the 2D physical groups' faces as CPS4 elements (and their element sets), which ccx
# takes for a plane-stress structure: keep only their node sets.
face_groups = {"DISC_FACE", "PAD_FACE", "PAD_BACK", "DISC_CLAMP"}
kept, skip = [], False
for line in open(mesh_file):
    if line.startswith("*"):
        head = line.upper().replace(" ", "")
        skip = ("TYPE=CPS" in head and head.startswith("*ELEMENT")) or (
            head.startswith("*ELSET,ELSET=") and head.strip().split("=", 1)[1] in face_groups)
    if not skip:
        kept.append(line)
open(mesh_file, "w").writelines(kept)

# The lining on its own (its nodes and cells, no boundary): ccx writes its stiffness K_L in
# JOB_lining.sti with its own JOB_lining.dof, which the scene adds to the damping as b_L K_L
# (-model_ccx_damping_parts), the lining's loss factor apart from the steel's.
lining_ids, in_lining = set(), False
for line in kept:
    if line.startswith("*"):
        in_lining = line.upper().replace(" ", "").strip() == "*ELSET,ELSET=LINING"
    elif in_lining:
        lining_ids.update(int(t) for t in line.replace(",", " ").split())
lining_mesh, block = [], None
for line in kept:
    if line.startswith("*"):
        head = line.upper().replace(" ", "")
        block = "node" if head.startswith("*NODE") and not head.startswith("*NODE,NSET") else \
                "cell" if head.startswith("*ELEMENT") else None
        if block:
            lining_mesh.append(line)
    elif block == "node" or (block == "cell" and int(line.split(",")[0]) in lining_ids):
        lining_mesh.append(line)
ids = sorted(lining_ids)
lining_mesh.append("*ELSET, ELSET=LINING\n")
lining_mesh += [", ".join(map(str, ids[i:i + 10])) + "\n" for i in range(0, len(ids), 10)]
open(os.path.join(a.outdir, a.job + "_lining_mesh.inp"), "w").writelines(lining_mesh)

# The caliper's springs: the back face's nodes, each with its share of the face area.
back_nodes, back_xyz = gmsh.model.mesh.getNodesForPhysicalGroup(2, groups["PAD_BACK"])
gmsh.finalize()
n_back = len(back_nodes)
area_back = 0.5 * (2 * P_HALF) * (P_OUT ** 2 - P_IN ** 2)
k_node = [k * area_back / n_back for k in (a.support_kt, a.support_kt, a.support_kn)]

LINING = """*MATERIAL, NAME=LINING
*ELASTIC
1.5e9, 0.25
*DENSITY
2200.
"""
STEP = """*STEP
*FREQUENCY, SOLVER=MATRIXSTORAGE
*END STEP
"""
deck = os.path.join(a.outdir, a.job + ".inp")
with open(deck, "w") as f:
    f.write(f"""** squeal brake example: written by examples/brake/make_brake.py --size {a.size}
*INCLUDE, INPUT={a.job}_mesh.inp
*ELEMENT, TYPE=SPRING1, ELSET=CALIPER_X
""")
    first = 10_000_000
    for d, es in enumerate(("CALIPER_X", "CALIPER_Y", "CALIPER_Z")):
        if d:
            f.write(f"*ELEMENT, TYPE=SPRING1, ELSET={es}\n")
        for i, n in enumerate(back_nodes):
            f.write(f"{first + d * n_back + i}, {int(n)}\n")
    f.write(f"""*MATERIAL, NAME=STEEL
*ELASTIC
210e9, 0.3
*DENSITY
7850.
{LINING}*SOLID SECTION, ELSET=DISC, MATERIAL=STEEL
*SOLID SECTION, ELSET=BACKPLATE, MATERIAL=STEEL
*SOLID SECTION, ELSET=LINING, MATERIAL=LINING
""")
    for d, es in enumerate(("CALIPER_X", "CALIPER_Y", "CALIPER_Z")):
        f.write(f"*SPRING, ELSET={es}\n{d + 1}\n{k_node[d]:.9g}\n")
    f.write(f"""*BOUNDARY
DISC_CLAMP, 1, 3
{STEP}""")
with open(os.path.join(a.outdir, a.job + "_lining.inp"), "w") as f:
    f.write(f"""** the lining of {a.job}.inp alone, for its damping: written by examples/brake/make_brake.py
*INCLUDE, INPUT={a.job}_lining_mesh.inp
{LINING}*SOLID SECTION, ELSET=LINING, MATERIAL=LINING
{STEP}""")
t_mesh = time.time() - t0
print(f"make_brake.py: {deck}: size {a.size}, pad face {n_pad_r + 1} x {n_pad_t + 1} nodes, "
      f"disc {n_in_r + n_pad_r + n_out_r} x {n_pad_t + n_rest_t} x {n_disc_z} cells; gmsh {t_mesh:.1f} s")
if not a.no_ccx:
    for job in (a.job, a.job + "_lining"):
        t1 = time.time()
        with open(os.path.join(a.outdir, job + ".ccx.log"), "w") as log:
            rc = subprocess.call(["ccx", "-i", job], cwd=a.outdir, stdout=log, stderr=subprocess.STDOUT)
        if rc != 0 or not os.path.exists(os.path.join(a.outdir, job + ".sti")):
            sys.exit(f"make_brake.py: error: ccx failed (exit {rc}); see {os.path.join(a.outdir, job + '.ccx.log')}")
        ndof = sum(1 for _ in open(os.path.join(a.outdir, job + ".dof")))
        print(f"make_brake.py: ccx wrote {job}.sti/.mas/.dof: {ndof} DOFs in {time.time() - t1:.1f} s")
