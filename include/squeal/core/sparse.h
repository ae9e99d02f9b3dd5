// Assembly of distributed AIJ matrices from (row, column, value) lists with exact preallocation.
// Used wherever squeal builds a sparse operator of its own (H, Q, L, the bordered equilibrium
// matrix), so that preallocation is right once, in one place.
#pragma once

#include <petscmat.h>

#include <vector>

namespace squeal {

struct Triplets {
  std::vector<PetscInt>    rows, cols;
  std::vector<PetscScalar> vals;
  void Add(PetscInt i, PetscInt j, PetscScalar v)
  {
    rows.push_back(i);
    cols.push_back(j);
    vals.push_back(v);
  }
  void Clear()
  {
    rows.clear();
    cols.clear();
    vals.clear();
  }
};

// Creates a MATAIJ with the given local/global sizes (PETSC_DECIDE allowed for local sizes) and
// fills it with t, summing duplicates. Triplets in rows owned by another rank are an error, or
// are skipped with drop_unowned (for builders that list the whole matrix on every rank).
PetscErrorCode MatCreateFromTriplets(MPI_Comm comm, PetscInt m_local, PetscInt n_local, PetscInt M, PetscInt N,
                                     const Triplets &t, Mat *A, bool drop_unowned = false);

// Appends the locally owned rows of A (shifted by row_shift/col_shift) to t.
PetscErrorCode AppendLocalRows(Mat A, PetscScalar scale, PetscInt row_shift, PetscInt col_shift, Triplets &t);

} // namespace squeal
