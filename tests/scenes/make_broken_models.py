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

    with open(os.path.join(d, "contacts_dof7.txt"), "w") as f:
        f.write("# contact table with a DOF index out of range (3 DOFs: 0..2)\n")
        f.write("0 1 7  1 0 0  0 0 1  1 0\n")


if __name__ == "__main__":
    main()
