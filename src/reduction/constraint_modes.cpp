// Constraint modes of the Craig-Bampton reduction, Psi = -K_II^{-1} K_IB, from the factor of K_II
// that the eigensolver set up (src/reduction/internal.h).
#include "internal.h"

#include "squeal/core/errors.h"
#include "squeal/core/inf.h"
#include "squeal/core/interrupt.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace squeal::cb {

namespace {

// The constraint modes are solved in blocks of right-hand-side columns, with an interrupt poll
// between blocks: one multi-RHS solve cannot be polled inside, and the 1353 columns of the
// 31119-DOF pad take 12-17 s of CPU time in one solve (docs/records.md, "Constraint modes in
// blocks"). The factor is reused; only the right-hand side is split.
constexpr const char *kConstraintWhere = "the Craig-Bampton constraint modes (between two blocks of right-hand sides)";

// Columns per block: block (<= 0: all n at once), at least 1.
PetscInt BlockSize(PetscInt block, PetscInt n) { return PetscMax(1, block > 0 ? PetscMin(block, n) : n); }

// X(:, j0:j1) = F^{-1} B(:, j0:j1): B holds the right-hand sides either as the sparse transpose
// (-K_IB)^T (rows j0 .. j1 - 1 taken on rcomm's rank 0 alone: MUMPS takes a sparse right-hand side
// centralised, by columns, i.e. its transpose by rows) or as a dense block with the rows of X.
PetscErrorCode SolveBlock(Mat F, Mat B, PetscBool sparse, MPI_Comm rcomm, PetscInt j0, PetscInt j1, PetscInt nI, Mat X)
{
  Mat Xb;
  PetscFunctionBeginUser;
  PetscCall(MatDenseGetSubMatrix(X, PETSC_DECIDE, PETSC_DECIDE, j0, j1, &Xb));
  if (sparse) {
    MatH        Rb;
    IS          rows, cols;
    PetscMPIInt rank;
    PetscCallMPI(MPI_Comm_rank(rcomm, &rank));
    PetscCall(ISCreateStride(rcomm, rank == 0 ? j1 - j0 : 0, j0, 1, &rows));
    PetscCall(ISCreateStride(rcomm, rank == 0 ? nI : 0, 0, 1, &cols));
    PetscCall(MatCreateSubMatrix(B, rows, cols, MAT_INITIAL_MATRIX, Rb.out()));
    PetscCall(ISDestroy(&rows));
    PetscCall(ISDestroy(&cols));
    PetscCall(MatMatTransposeSolve(F, Rb, Xb));
  } else {
    Mat Bb;
    PetscCall(MatDenseGetSubMatrix(B, PETSC_DECIDE, PETSC_DECIDE, j0, j1, &Bb));
    PetscCall(MatMatSolve(F, Bb, Xb));
    PetscCall(MatDenseRestoreSubMatrix(B, &Bb));
  }
  PetscCall(MatDenseRestoreSubMatrix(X, &Xb));
  PetscFunctionReturn(0);
}

// Psi = -K_II^{-1} K_IB into the first nB columns of W, with a sequential factor F of the whole
// K_II on every rank: each rank solves a contiguous share of the columns alone (the same
// sequential solve as on one rank: no distributed solution to scatter), then sends every other
// rank the rows of its share that rank owns in W, in one all-to-all.
PetscErrorCode RedundantConstraintModes(Mat F, Mat Kib, PetscBool sparse_rhs, PetscInt block, Mat W)
{
  MPI_Comm        comm, fcomm;
  PetscMPIInt     size, rank;
  PetscInt        nI, nB, nIloc, lda;
  const PetscInt *rows;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)W, &comm));
  PetscCall(PetscObjectGetComm((PetscObject)F, &fcomm));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCall(MatGetSize(Kib, &nI, &nB));
  PetscCall(MatGetLocalSize(W, &nIloc, nullptr));
  PetscCall(MatGetOwnershipRanges(W, &rows));
  std::vector<PetscInt> cols(size + 1, 0); // the columns rank r solves: [cols[r], cols[r + 1])
  for (PetscMPIInt r = 0; r < size; ++r) cols[r + 1] = cols[r] + nB / size + (r < nB % size ? 1 : 0);
  const PetscInt c0 = cols[rank], k = cols[rank + 1] - c0;

  MatH X; // nI x k, this rank's columns of Psi, every row
  PetscCall(MatCreateSeqDense(fcomm, nI, k, nullptr, X.out()));
  {
    // (-K_IB)^T, rows c0 .. c0 + k - 1, on this rank alone: MUMPS takes a sparse right-hand side
    // by columns, i.e. its transpose by rows (MatMatTransposeSolve).
    MatH KbiT, B;
    IS   isr, isc;
    Mat *sub;
    PetscCall(MatTranspose(Kib, MAT_INITIAL_MATRIX, KbiT.out()));
    PetscCall(ISCreateStride(PETSC_COMM_SELF, k, c0, 1, &isr));
    PetscCall(ISCreateStride(PETSC_COMM_SELF, nI, 0, 1, &isc));
    PetscCall(MatCreateSubMatrices(KbiT, 1, &isr, &isc, MAT_INITIAL_MATRIX, &sub));
    PetscCall(ISDestroy(&isr));
    PetscCall(ISDestroy(&isc));
    PetscCall(MatScale(sub[0], -1.0));
    if (k > 0 && !sparse_rhs) {
      MatH Bt;
      PetscCall(MatTranspose(sub[0], MAT_INITIAL_MATRIX, Bt.out()));
      PetscCall(MatConvert(Bt, MATSEQDENSE, MAT_INITIAL_MATRIX, B.out()));
    }
    // Every rank takes as many blocks as rank 0 (the largest share), so that all meet at each poll.
    const PetscInt b = BlockSize(block, cols[1]), nblocks = (cols[1] + b - 1) / b;
    for (PetscInt q = 0; q < nblocks; ++q) {
      const PetscInt j0 = PetscMin(k, q * b), j1 = PetscMin(k, j0 + b);
      if (j1 > j0) PetscCall(SolveBlock(F, sparse_rhs ? sub[0] : (Mat)B, sparse_rhs, PETSC_COMM_SELF, j0, j1, nI, X));
      if (q + 1 < nblocks) PetscCall(InterruptPoint(comm, kConstraintWhere));
    }
    PetscCall(MatDestroySubMatrices(1, &sub));
  }

  // Rank q receives rows [rows[q], rows[q + 1]) of every rank's columns, column by column.
  std::vector<PetscMPIInt> scnt(size), sdsp(size), rcnt(size), rdsp(size);
  PetscInt                 soff = 0, roff = 0;
  for (PetscMPIInt q = 0; q < size; ++q) {
    PetscCall(PetscMPIIntCast(soff, &sdsp[q]));
    PetscCall(PetscMPIIntCast(roff, &rdsp[q]));
    PetscCall(PetscMPIIntCast((rows[q + 1] - rows[q]) * k, &scnt[q]));
    PetscCall(PetscMPIIntCast(nIloc * (cols[q + 1] - cols[q]), &rcnt[q]));
    soff += (rows[q + 1] - rows[q]) * k;
    roff += nIloc * (cols[q + 1] - cols[q]);
  }
  std::vector<PetscScalar> sbuf((size_t)soff), rbuf((size_t)roff);
  {
    const PetscScalar *x;
    PetscInt           ldx;
    PetscCall(MatDenseGetLDA(X, &ldx));
    PetscCall(MatDenseGetArrayRead(X, &x));
    for (PetscMPIInt q = 0; q < size; ++q) {
      const PetscInt m = rows[q + 1] - rows[q];
      for (PetscInt j = 0; j < k; ++j)
        std::copy(x + rows[q] + (size_t)j * ldx, x + rows[q] + m + (size_t)j * ldx, sbuf.begin() + sdsp[q] + (size_t)j * m);
    }
    PetscCall(MatDenseRestoreArrayRead(X, &x));
  }
  X.reset();
  PetscCallMPI(MPI_Alltoallv(sbuf.data(), scnt.data(), sdsp.data(), MPIU_SCALAR, rbuf.data(), rcnt.data(), rdsp.data(),
                             MPIU_SCALAR, comm));
  PetscScalar *w;
  PetscCall(MatDenseGetLDA(W, &lda));
  PetscCall(MatDenseGetArray(W, &w)); // read-write: W holds the modes already
  for (PetscMPIInt r = 0; r < size; ++r)
    for (PetscInt j = cols[r]; j < cols[r + 1]; ++j)
      std::copy(rbuf.begin() + rdsp[r] + (size_t)(j - cols[r]) * nIloc, rbuf.begin() + rdsp[r] + (size_t)(j - cols[r] + 1) * nIloc,
                w + (size_t)j * lda);
  PetscCall(MatDenseRestoreArray(W, &w));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode ConstraintModes(MPI_Comm comm, Mat F, Mat Kib, bool redundant, PetscBool sparse_rhs, PetscInt block, Mat W)
{
  MatH      R;
  Mat       Wpsi;
  PetscReal nrm;
  PetscInt  nI, nB;
  PetscFunctionBeginUser;
  PetscCall(MatGetSize(Kib, &nI, &nB));
  if (redundant) PetscCall(RedundantConstraintModes(F, Kib, sparse_rhs, block, W));
  else {
    // Sparse: -K_IB as a sparse right-hand side (MUMPS ICNTL(20) = 1): the forward substitution
    // prunes the elimination tree to the paths its few nonzero rows reach. MUMPS takes it
    // centralised and transposed, so each block of (-K_IB)^T is gathered on rank 0.
    if (sparse_rhs) PetscCall(MatTranspose(Kib, MAT_INITIAL_MATRIX, R.out()));
    else PetscCall(MatConvert(Kib, MATDENSE, MAT_INITIAL_MATRIX, R.out()));
    PetscCall(MatScale(R, -1.0));
    const PetscInt b = BlockSize(block, nB);
    for (PetscInt j0 = 0; j0 < nB; j0 += b) {
      if (j0 > 0) PetscCall(InterruptPoint(comm, kConstraintWhere));
      PetscCall(SolveBlock(F, R, sparse_rhs, comm, j0, PetscMin(nB, j0 + b), nI, W));
    }
  }
  PetscCall(MatDenseGetSubMatrix(W, PETSC_DECIDE, PETSC_DECIDE, 0, nB, &Wpsi));
  PetscCall(MatNorm(Wpsi, NORM_FROBENIUS, &nrm));
  PetscCall(MatDenseRestoreSubMatrix(W, &Wpsi));
  PetscCheck(!PetscIsInfOrNanReal(nrm) && nrm < 1e12 * std::sqrt((PetscReal)nB), comm, kErrInput,
             "reduction: K_II is singular or nearly so (constraint modes of norm %g): part of the structure is not held by "
             "the contact nodes or supports; add supports (e.g. -model_support_kn/-model_support_kt)",
             (double)nrm);
  PetscFunctionReturn(0);
}

} // namespace squeal::cb
