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

// -log_view events: the solves, and on several ranks the transfer of the solved columns to W.
PetscLogEvent ev_solve = 0, ev_exchange = 0;
PetscErrorCode RegisterEvents()
{
  PetscFunctionBeginUser;
  if (!ev_solve) {
    PetscCall(PetscLogEventRegister("CBConstraintSolve", MAT_CLASSID, &ev_solve));
    PetscCall(PetscLogEventRegister("CBConstraintXchg", MAT_CLASSID, &ev_exchange));
  }
  PetscFunctionReturn(0);
}

// Columns per block: block (<= 0: all n at once), at least 1.
PetscInt BlockSize(PetscInt block, PetscInt n) { return PetscMax(1, block > 0 ? PetscMin(block, n) : n); }

// X(:, x0:x0 + j1 - j0) = F^{-1} B(:, j0:j1): B holds the right-hand sides either as the sparse
// transpose (-K_IB)^T (rows j0 .. j1 - 1 taken on rcomm's rank 0 alone: MUMPS takes a sparse
// right-hand side centralised, by columns, i.e. its transpose by rows) or as a dense block with the
// rows of X.
PetscErrorCode SolveBlock(Mat F, Mat B, PetscBool sparse, MPI_Comm rcomm, PetscInt j0, PetscInt j1, PetscInt x0, PetscInt nI, Mat X)
{
  Mat Xb;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(ev_solve, F, 0, 0, 0));
  PetscCall(MatDenseGetSubMatrix(X, PETSC_DECIDE, PETSC_DECIDE, x0, x0 + j1 - j0, &Xb));
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
  PetscCall(PetscLogEventEnd(ev_solve, F, 0, 0, 0));
  PetscFunctionReturn(0);
}

// Psi = -K_II^{-1} K_IB into the first nB columns of W, with a sequential factor F of the whole
// K_II on every rank: each rank solves a contiguous share of the columns alone (the same
// sequential solve as on one rank: no distributed solution to scatter). After each block of
// columns, every rank sends every other rank the rows of its block that rank owns in W, in one
// all-to-all. Block by block, so that no rank holds more than one block of all its rows besides
// its rows of W: a rank's whole share of Psi with every row, and its send and receive copies, took
// 5 GB a rank more on the 126 861-DOF brake (1953 columns a rank).
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
  // The columns are dealt out in chunks of b, round robin: chunk c = q size + r, global columns
  // [c b, c b + n), is block q of rank r. Round robin, not one contiguous share a rank: the
  // interface DOFs come body by body, and on the 126 861-DOF brake one rank's contiguous half took
  // 3.4 times the other's time. Every rank takes as many blocks (some empty), so that all meet at
  // each all-to-all and each poll. Only the last chunk can be short, so block q of this rank is
  // its local columns [q b, q b + n).
  const PetscInt b       = PetscMax(1, PetscMin(block > 0 ? block : nB, (nB + size - 1) / size));
  const PetscInt nblocks = (nB + b * size - 1) / (b * size);
  auto           ncols   = [&](PetscMPIInt r, PetscInt q) { return PetscMax(0, PetscMin(b, nB - (q * size + r) * b)); };
  auto           col0    = [&](PetscMPIInt r, PetscInt q) { return (q * size + r) * b; };
  std::vector<PetscInt> mine; // this rank's columns, in its blocks' order
  for (PetscInt q = 0; q < nblocks; ++q)
    for (PetscInt j = 0; j < ncols(rank, q); ++j) mine.push_back(col0(rank, q) + j);
  const PetscInt k = (PetscInt)mine.size();

  // (-K_IB)^T, this rank's rows, on this rank alone: MUMPS takes a sparse right-hand side by
  // columns, i.e. its transpose by rows (MatMatTransposeSolve).
  Mat *sub;
  {
    MatH KbiT;
    IS   isr, isc;
    PetscCall(MatTranspose(Kib, MAT_INITIAL_MATRIX, KbiT.out()));
    PetscCall(ISCreateGeneral(PETSC_COMM_SELF, k, mine.data(), PETSC_USE_POINTER, &isr));
    PetscCall(ISCreateStride(PETSC_COMM_SELF, nI, 0, 1, &isc));
    PetscCall(MatCreateSubMatrices(KbiT, 1, &isr, &isc, MAT_INITIAL_MATRIX, &sub));
    PetscCall(ISDestroy(&isr));
    PetscCall(ISDestroy(&isc));
    PetscCall(MatScale(sub[0], -1.0));
  }
  MatH X; // nI x b: one block of this rank's columns of Psi, every row
  PetscCall(MatCreateSeqDense(fcomm, nI, b, nullptr, X.out()));
  PetscInt ldx;
  PetscCall(MatDenseGetLDA(X, &ldx));
  std::vector<PetscMPIInt> scnt(size), sdsp(size), rcnt(size), rdsp(size);
  std::vector<PetscScalar> sbuf((size_t)nI * b), rbuf((size_t)nIloc * b * size);
  PetscCall(MatDenseGetLDA(W, &lda));
  for (PetscInt q = 0; q < nblocks; ++q) {
    const PetscInt j0 = PetscMin(k, q * b), j1 = PetscMin(k, j0 + b), kq = j1 - j0;
    if (kq > 0) {
      if (sparse_rhs) PetscCall(SolveBlock(F, sub[0], PETSC_TRUE, PETSC_COMM_SELF, j0, j1, 0, nI, X));
      else {
        // The block's dense right-hand sides, made here: all of a rank's share at once took
        // nI x k doubles.
        MatH  Bt, Bs;
        IS    isr, isc;
        Mat  *blk;
        PetscCall(ISCreateStride(PETSC_COMM_SELF, kq, j0, 1, &isr));
        PetscCall(ISCreateStride(PETSC_COMM_SELF, nI, 0, 1, &isc));
        PetscCall(MatCreateSubMatrices(sub[0], 1, &isr, &isc, MAT_INITIAL_MATRIX, &blk));
        PetscCall(ISDestroy(&isr));
        PetscCall(ISDestroy(&isc));
        PetscCall(MatTranspose(blk[0], MAT_INITIAL_MATRIX, Bt.out()));
        PetscCall(MatDestroySubMatrices(1, &blk));
        PetscCall(MatConvert(Bt, MATSEQDENSE, MAT_INITIAL_MATRIX, Bs.out()));
        PetscCall(SolveBlock(F, Bs, PETSC_FALSE, PETSC_COMM_SELF, 0, kq, 0, nI, X));
      }
    }
    // Rank p receives rows [rows[p], rows[p + 1]) of every rank's block, column by column.
    PetscCall(PetscLogEventBegin(ev_exchange, W, 0, 0, 0));
    PetscInt soff = 0, roff = 0;
    for (PetscMPIInt p = 0; p < size; ++p) {
      PetscCall(PetscMPIIntCast(soff, &sdsp[p]));
      PetscCall(PetscMPIIntCast(roff, &rdsp[p]));
      PetscCall(PetscMPIIntCast((rows[p + 1] - rows[p]) * kq, &scnt[p]));
      PetscCall(PetscMPIIntCast(nIloc * ncols(p, q), &rcnt[p]));
      soff += (rows[p + 1] - rows[p]) * kq;
      roff += nIloc * ncols(p, q);
    }
    {
      const PetscScalar *x;
      PetscCall(MatDenseGetArrayRead(X, &x));
      for (PetscMPIInt p = 0; p < size; ++p) {
        const PetscInt m = rows[p + 1] - rows[p];
        for (PetscInt j = 0; j < kq; ++j)
          std::copy(x + rows[p] + (size_t)j * ldx, x + rows[p] + m + (size_t)j * ldx, sbuf.begin() + sdsp[p] + (size_t)j * m);
      }
      PetscCall(MatDenseRestoreArrayRead(X, &x));
    }
    PetscCallMPI(MPI_Alltoallv(sbuf.data(), scnt.data(), sdsp.data(), MPIU_SCALAR, rbuf.data(), rcnt.data(), rdsp.data(),
                               MPIU_SCALAR, comm));
    PetscScalar *w;
    PetscCall(MatDenseGetArray(W, &w)); // read-write: W holds the modes already
    for (PetscMPIInt r = 0; r < size; ++r)
      for (PetscInt j = 0; j < ncols(r, q); ++j)
        std::copy(rbuf.begin() + rdsp[r] + (size_t)j * nIloc, rbuf.begin() + rdsp[r] + (size_t)(j + 1) * nIloc,
                  w + (size_t)(col0(r, q) + j) * lda);
    PetscCall(MatDenseRestoreArray(W, &w));
    PetscCall(PetscLogEventEnd(ev_exchange, W, 0, 0, 0));
    if (q + 1 < nblocks) PetscCall(InterruptPoint(comm, kConstraintWhere));
  }
  PetscCall(MatDestroySubMatrices(1, &sub));
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
  PetscCall(RegisterEvents());
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
      PetscCall(SolveBlock(F, R, sparse_rhs, comm, j0, PetscMin(nB, j0 + b), j0, nI, W));
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
