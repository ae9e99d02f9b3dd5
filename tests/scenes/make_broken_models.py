#!/usr/bin/python3
"""Make broken variants of an exported 3-DOF model (directory written by squeal -model_export).

Usage: make_broken_models.py MODEL_DIR

Reads MODEL_DIR/{M,K}.bin (PETSc binary AIJ) and writes, next to them:
  K_ok.mtx       the exported K as Matrix Market (sanity: must be accepted)
  M_ok.mtx       the exported M as Matrix Market
  K_nonsym.mtx   K with one off-diagonal entry changed (non-symmetric)
  M_nonsym.mtx   M with an off-diagonal entry on one side only (non-symmetric)
  M_4x4.mtx      a 4x4 mass matrix (size mismatch with the 3x3 K)
  contacts_dof7.txt  contact table naming DOF 7 (out of range for 3 DOFs)
  contacts_dof_2e32.txt  contact table naming DOF 4294967296 (beyond PetscInt: wrapped before the fix)
  M_singular.mtx     M with positive diagonal, singular (rows 0 and 1 equal)
  M_indefinite.mtx   M with positive diagonal, indefinite (eigenvalues 3, -1, 1)
  contacts_dof_twice.txt  a contact row using DOF 0 twice
  K4_singular.mtx, M4.mtx, F4.bin, contacts4.txt   a 4-DOF model whose 4th DOF has no stiffness
  F_truncated.bin, K_truncated.bin   the exported F and K cut short
  F_noF.h5           an HDF5 file without dataset /F
  F.txt, F_array.mtx, F_coord.mtx    F as a text column, Matrix Market array and coordinate
  contacts.csv       the contact table as CSV with a header naming the columns (shuffled order)
"""
import os
import sys

import numpy as np

MAT_FILE_CLASSID = 1211216


def read_petsc_mat(path):
    with open(path, "rb") as f:
        data = f.read()
    header = np.frombuffer(data, dtype=">i4", count=4)
    if header[0] != MAT_FILE_CLASSID:
        raise SystemExit(f"{path}: not a PETSc binary matrix (classid {header[0]})")
    m, n, nnz = (int(v) for v in header[1:4])
    off = 16
    rowlens = np.frombuffer(data, dtype=">i4", count=m, offset=off)
    off += 4 * m
    cols = np.frombuffer(data, dtype=">i4", count=nnz, offset=off)
    off += 4 * nnz
    vals = np.frombuffer(data, dtype=">f8", count=nnz, offset=off)
    a = np.zeros((m, n))
    k = 0
    for i in range(m):
        for _ in range(rowlens[i]):
            a[i, cols[k]] = vals[k]
            k += 1
    return a


VEC_FILE_CLASSID = 1211214


def read_petsc_vec(path):
    with open(path, "rb") as f:
        data = f.read()
    cid, n = np.frombuffer(data, dtype=">i4", count=2)
    if cid != VEC_FILE_CLASSID:
        raise SystemExit(f"{path}: not a PETSc binary vector (classid {cid})")
    return np.frombuffer(data, dtype=">f8", count=int(n), offset=8).astype(float)


def write_petsc_vec(path, x):
    with open(path, "wb") as f:
        f.write(np.array([VEC_FILE_CLASSID, x.size], dtype=">i4").tobytes() + np.asarray(x, dtype=">f8").tobytes())


def write_mtx(path, a):
    """Matrix Market coordinate real general, 1-based indices, every entry written."""
    m, n = a.shape
    with open(path, "w") as f:
        f.write("%%MatrixMarket matrix coordinate real general\n")
        f.write(f"{m} {n} {m * n}\n")
        for i in range(m):
            for j in range(n):
                f.write(f"{i + 1} {j + 1} {a[i, j]:.17g}\n")


def main():
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    d = sys.argv[1]
    M = read_petsc_mat(os.path.join(d, "M.bin"))
    K = read_petsc_mat(os.path.join(d, "K.bin"))
    if M.shape != (3, 3) or K.shape != (3, 3):
        raise SystemExit(f"expected 3x3 M and K, got {M.shape} and {K.shape}")

    write_mtx(os.path.join(d, "K_ok.mtx"), K)
    write_mtx(os.path.join(d, "M_ok.mtx"), M)

    Kn = K.copy()
    Kn[0, 1] += 0.25 * abs(K[0, 0])  # K[1,0] unchanged: clearly non-symmetric
    write_mtx(os.path.join(d, "K_nonsym.mtx"), Kn)

    Mn = M.copy()
    Mn[0, 2] += 0.5 * abs(M[0, 0])
    write_mtx(os.path.join(d, "M_nonsym.mtx"), Mn)

    M4 = np.eye(4) * M[0, 0]
    write_mtx(os.path.join(d, "M_4x4.mtx"), M4)

    m = M[0, 0]
    write_mtx(os.path.join(d, "M_singular.mtx"), m * np.array([[1.0, 1, 0], [1, 1, 0], [0, 0, 1]]))
    write_mtx(os.path.join(d, "M_indefinite.mtx"), m * np.array([[1.0, 2, 0], [2, 1, 0], [0, 0, 1]]))
    with open(os.path.join(d, "contacts_dof_twice.txt"), "w") as f:
        f.write("0 0 2  1 0 0  0 0 1  1 0\n")
    K4 = np.zeros((4, 4))
    K4[:3, :3] = K
    write_mtx(os.path.join(d, "K4_singular.mtx"), K4)
    write_mtx(os.path.join(d, "M4.mtx"), m * np.eye(4))
    F = read_petsc_vec(os.path.join(d, "F.bin"))
    write_petsc_vec(os.path.join(d, "F4.bin"), np.append(F, 0.0))
    with open(os.path.join(d, "contacts.txt")) as f:
        rows = [l.split() for l in f if l.strip() and not l.startswith("#")]
    with open(os.path.join(d, "contacts4.txt"), "w") as f:
        for r in rows:
            f.write(" ".join(r) + "\n")
    with open(os.path.join(d, "contacts.csv"), "w") as f:
        names = ["x", "y", "z", "tx", "ty", "tz", "nx", "ny", "nz", "speed_factor", "g0"]
        order = [6, 7, 8, 0, 1, 2, 3, 4, 5, 9, 10]  # normal first: columns are found by name
        f.write(",".join(names[k] for k in order) + "\n")
        for r in rows:
            f.write(",".join(r[k] for k in order) + "\n")
    with open(os.path.join(d, "F.bin"), "rb") as f:
        fb = f.read()
    with open(os.path.join(d, "F_truncated.bin"), "wb") as f:
        f.write(fb[:-8])
    with open(os.path.join(d, "K.bin"), "rb") as f:
        kb = f.read()
    with open(os.path.join(d, "K_truncated.bin"), "wb") as f:
        f.write(kb[: len(kb) - 12])
    import h5py
    with h5py.File(os.path.join(d, "F_noF.h5"), "w") as f:
        f["G"] = F
    with open(os.path.join(d, "F.txt"), "w") as f:
        f.write("# load vector, one entry per line (N)\n" + "".join(f"{v:.17g}\n" for v in F))
    with open(os.path.join(d, "F_array.mtx"), "w") as f:
        f.write(f"%%MatrixMarket matrix array real general\n{F.size} 1\n" + "".join(f"{v:.17g}\n" for v in F))
    with open(os.path.join(d, "F_coord.mtx"), "w") as f:
        nz = [(i, v) for i, v in enumerate(F) if v != 0]
        f.write(f"%%MatrixMarket matrix coordinate real general\n{F.size} 1 {len(nz)}\n" +
                "".join(f"{i + 1} 1 {v:.17g}\n" for i, v in nz))

    with open(os.path.join(d, "contacts_dof7.txt"), "w") as f:
        f.write("# contact table with a DOF index out of range (3 DOFs: 0..2)\n")
        f.write("0 1 7  1 0 0  0 0 1  1 0\n")
    with open(os.path.join(d, "contacts_dof_2e32.txt"), "w") as f:
        f.write("# contact table with a DOF index of 2^32 (a 32-bit PetscInt cast made it -2147483648)\n")
        f.write("4294967296 1 2  1 0 0  0 0 1  1 0\n")


if __name__ == "__main__":
    main()
