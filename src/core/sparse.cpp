#include "squeal/core/sparse.h"

#include <algorithm>
#include <numeric>

namespace squeal {

PetscErrorCode MatCreateFromTriplets(MPI_Comm comm, PetscInt m_local, PetscInt n_local, PetscInt M, PetscInt N,
                                     const Triplets &t, Mat *A, bool drop_unowned)
{
  PetscLayout     rmap, cmap;
  PetscInt        rstart, rend, cstart, cend;
  const PetscInt  nt = (PetscInt)t.rows.size();
  PetscFunctionBeginUser;
  PetscCall(PetscLayoutCreateFromSizes(comm, m_local, M, 1, &rmap));
  PetscCall(PetscLayoutCreateFromSizes(comm, n_local, N, 1, &cmap));
  PetscCall(PetscLayoutGetRange(rmap, &rstart, &rend));
  PetscCall(PetscLayoutGetRange(cmap, &cstart, &cend));
  const PetscInt mloc = rend - rstart, nloc = cend - cstart;

  // Count distinct (row, col) pairs per row, split into diagonal and off-diagonal blocks.
  std::vector<PetscInt> order(nt);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](PetscInt a, PetscInt b) {
    return t.rows[a] != t.rows[b] ? t.rows[a] < t.rows[b] : t.cols[a] < t.cols[b];
  });
  std::vector<PetscInt> dnz(mloc, 0), onz(mloc, 0);
  for (PetscInt k = 0; k < nt; ++k) {
    const PetscInt i = t.rows[order[k]], j = t.cols[order[k]];
    if (drop_unowned && (i < rstart || i >= rend)) continue;
    PetscCheck(i >= rstart && i < rend, comm, PETSC_ERR_PLIB, "triplet row %" PetscInt_FMT " not owned", i);
    PetscCheck(j >= 0 && j < N, comm, PETSC_ERR_PLIB, "triplet column %" PetscInt_FMT " out of range", j);
    if (k > 0 && t.rows[order[k - 1]] == i && t.cols[order[k - 1]] == j) continue;
    if (j >= cstart && j < cend) dnz[i - rstart]++;
    else onz[i - rstart]++;
  }
  PetscCall(MatCreate(comm, A));
  PetscCall(MatSetSizes(*A, mloc, nloc, M, N));
  PetscCall(MatSetType(*A, MATAIJ));
  PetscCall(MatSeqAIJSetPreallocation(*A, 0, dnz.data()));
  PetscCall(MatMPIAIJSetPreallocation(*A, 0, dnz.data(), 0, onz.data()));
  PetscCall(MatSetOption(*A, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  for (PetscInt k = 0; k < nt; ++k)
    if (t.rows[k] >= rstart && t.rows[k] < rend) PetscCall(MatSetValue(*A, t.rows[k], t.cols[k], t.vals[k], ADD_VALUES));
  PetscCall(MatAssemblyBegin(*A, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(*A, MAT_FINAL_ASSEMBLY));
  PetscCall(PetscLayoutDestroy(&rmap));
  PetscCall(PetscLayoutDestroy(&cmap));
  PetscFunctionReturn(0);
}

PetscErrorCode AppendLocalRows(Mat A, PetscScalar scale, PetscInt row_shift, PetscInt col_shift, Triplets &t)
{
  PetscInt rstart, rend;
  PetscFunctionBeginUser;
  PetscCall(MatGetOwnershipRange(A, &rstart, &rend));
  for (PetscInt i = rstart; i < rend; ++i) {
    PetscInt           ncols;
    const PetscInt    *cols;
    const PetscScalar *vals;
    PetscCall(MatGetRow(A, i, &ncols, &cols, &vals));
    for (PetscInt k = 0; k < ncols; ++k) t.Add(i + row_shift, cols[k] + col_shift, scale * vals[k]);
    PetscCall(MatRestoreRow(A, i, &ncols, &cols, &vals));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
