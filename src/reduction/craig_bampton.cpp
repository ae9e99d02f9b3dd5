#include "squeal/reduction/craig_bampton.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/inf.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/options.h"
#include "squeal/core/sparse.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <ctime>
#include <numeric>

namespace squeal {

namespace {

using Dense = Eigen::Matrix<PetscReal, Eigen::Dynamic, Eigen::Dynamic>;

// S = A_IB^T W (nB x n) on every rank, for a sparse A_IB with the row layout of W: each rank adds
// a_ij W(i, :) to row j of S for the nonzeros of its rows (a few per row, near the interface),
// then the shares are summed. PETSc's MatTransposeMatMult took 1.3 s per call on the 31119-DOF
// pad for 1e8 flops (symbolic transpose and sparse-dense product).
PetscErrorCode InterfaceTransposeProduct(Mat Aib, Mat W, Dense &S)
{
  MPI_Comm           comm;
  PetscInt           nB, n, rstart, rend, lda;
  const PetscScalar *w;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)W, &comm));
  PetscCall(MatGetSize(Aib, nullptr, &nB));
  PetscCall(MatGetSize(W, nullptr, &n));
  PetscCall(MatGetOwnershipRange(Aib, &rstart, &rend));
  PetscCall(MatDenseGetLDA(W, &lda));
  Dense St = Dense::Zero(n, nB); // S^T: the updates go down contiguous columns
  PetscCall(MatDenseGetArrayRead(W, &w));
  using RowMap = Eigen::Map<const Eigen::Matrix<PetscReal, Eigen::Dynamic, 1>, 0, Eigen::InnerStride<>>;
  for (PetscInt i = rstart; i < rend; ++i) {
    PetscInt           nc;
    const PetscInt    *cols;
    const PetscScalar *vals;
    const RowMap       wi(w + (i - rstart), n, Eigen::InnerStride<>(lda));
    PetscCall(MatGetRow(Aib, i, &nc, &cols, &vals));
    for (PetscInt k = 0; k < nc; ++k) St.col(cols[k]) += PetscRealPart(vals[k]) * wi;
    PetscCall(MatRestoreRow(Aib, i, &nc, &cols, &vals));
  }
  PetscCall(MatDenseRestoreArrayRead(W, &w));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, St.data(), (int)(n * nB), MPIU_REAL, MPI_SUM, comm));
  S = St.transpose();
  PetscFunctionReturn(0);
}

// Every rank receives A(rows, rows) for a (small) list of global rows, as a dense matrix.
PetscErrorCode GatherSubmatrix(Mat A, const std::vector<PetscInt> &rows, Dense &out)
{
  IS  is;
  Mat *sub;
  PetscFunctionBeginUser;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, (PetscInt)rows.size(), rows.data(), PETSC_COPY_VALUES, &is));
  PetscCall(MatCreateSubMatrices(A, 1, &is, &is, MAT_INITIAL_MATRIX, &sub));
  out = Dense::Zero(rows.size(), rows.size());
  for (PetscInt i = 0; i < (PetscInt)rows.size(); ++i) {
    PetscInt           nc;
    const PetscInt    *cols;
    const PetscScalar *vals;
    PetscCall(MatGetRow(sub[0], i, &nc, &cols, &vals));
    for (PetscInt k = 0; k < nc; ++k) out(i, cols[k]) = PetscRealPart(vals[k]);
    PetscCall(MatRestoreRow(sub[0], i, &nc, &cols, &vals));
  }
  PetscCall(MatDestroySubMatrices(1, &sub));
  PetscCall(ISDestroy(&is));
  PetscFunctionReturn(0);
}

// The reduced matrix, symmetrised, as an AIJ matrix on comm; entries below round-off of the
// projection (relative to the geometric mean of their diagonal entries) are not stored, so the
// exactly zero couplings of K_r (interface-modes block) stay zero.
PetscErrorCode CreateReducedMat(MPI_Comm comm, const Dense &A, Mat *out)
{
  const PetscInt n = (PetscInt)A.rows();
  PetscInt       nloc = PETSC_DECIDE, nglob = n, rstart = 0;
  Triplets       t;
  PetscFunctionBeginUser;
  PetscCall(PetscSplitOwnership(comm, &nloc, &nglob));
  PetscCallMPI(MPI_Scan(&nloc, &rstart, 1, MPIU_INT, MPI_SUM, comm));
  rstart -= nloc;
  for (PetscInt i = rstart; i < rstart + nloc; ++i)
    for (PetscInt j = 0; j < n; ++j) {
      const PetscReal v   = 0.5 * (A(i, j) + A(j, i));
      const PetscReal ref = std::sqrt(std::abs(A(i, i) * A(j, j)));
      if (i == j || std::abs(v) > 1e-13 * ref) t.Add(i, j, v);
    }
  PetscCall(MatCreateFromTriplets(comm, nloc, nloc, n, n, t, out));
  PetscFunctionReturn(0);
}

// P = W^T G for a P known to be symmetric (G = A W with A symmetric), on every rank. Each rank
// forms the lower triangle of its rows' share with Eigen's blocked kernels (half the flops of a
// full product; the system BLAS may be the slow reference one), the shares are summed, and the
// triangle mirrored: no N x n block leaves its rank.
PetscErrorCode SymmetricTransposeProduct(Mat W, Mat G, Dense &P)
{
  MPI_Comm           comm;
  PetscInt           nloc, n, ldw, ldg;
  const PetscScalar *w, *g;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)W, &comm));
  PetscCall(MatGetLocalSize(W, &nloc, nullptr));
  PetscCall(MatGetSize(W, nullptr, &n));
  PetscCall(MatDenseGetLDA(W, &ldw));
  PetscCall(MatDenseGetLDA(G, &ldg));
  P = Dense::Zero(n, n);
  PetscCall(MatDenseGetArrayRead(W, &w));
  PetscCall(MatDenseGetArrayRead(G, &g));
  if (nloc > 0) {
    using CMap = Eigen::Map<const Dense, 0, Eigen::OuterStride<>>;
    const CMap Wl(w, nloc, n, Eigen::OuterStride<>(ldw)), Gl(g, nloc, n, Eigen::OuterStride<>(ldg));
    P.triangularView<Eigen::Lower>() += Wl.transpose() * Gl;
  }
  PetscCall(MatDenseRestoreArrayRead(G, &g));
  PetscCall(MatDenseRestoreArrayRead(W, &w));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, P.data(), (int)(n * n), MPIU_REAL, MPI_SUM, comm));
  P.triangularView<Eigen::StrictlyUpper>() = P.transpose();
  PetscFunctionReturn(0);
}

// Whether C = a M + b K to round-off: a, b fitted to the diagonals (least squares), then the
// whole residual C - a M - b K checked against 1e-12 ||C||_F.
PetscErrorCode DetectRayleigh(Mat M, Mat K, Mat C, bool *is, PetscReal *a, PetscReal *b)
{
  VecH      dm, dk, dc;
  PetscReal nm, nk, uu, uv, vv, uc, vc;
  PetscFunctionBeginUser;
  *is = false, *a = 0, *b = 0;
  PetscCall(MatCreateVecs(M, dm.out(), nullptr));
  PetscCall(VecDuplicate(dm, dk.out()));
  PetscCall(VecDuplicate(dm, dc.out()));
  PetscCall(MatGetDiagonal(M, dm));
  PetscCall(MatGetDiagonal(K, dk));
  PetscCall(MatGetDiagonal(C, dc));
  PetscCall(VecNorm(dm, NORM_2, &nm));
  PetscCall(VecNorm(dk, NORM_2, &nk));
  if (nm == 0 || nk == 0) PetscFunctionReturn(0);
  PetscCall(VecScale(dm, 1.0 / nm)); // u
  PetscCall(VecScale(dk, 1.0 / nk)); // v
  PetscScalar s;
  PetscCall(VecDot(dm, dk, &s));
  uv = PetscRealPart(s);
  PetscCall(VecDot(dm, dc, &s));
  uc = PetscRealPart(s);
  PetscCall(VecDot(dk, dc, &s));
  vc = PetscRealPart(s);
  uu = vv = 1;
  const PetscReal det = uu * vv - uv * uv;
  PetscReal       al, be;
  if (det > 1e-10) al = (uc * vv - vc * uv) / det, be = (vc * uu - uc * uv) / det;
  else al = 0, be = vc; // M and K diagonals parallel: only the split of a and b is undetermined; try C = b K
  *a = al / nm, *b = be / nk;
  MatH      E;
  PetscReal nc, ne;
  PetscCall(MatNorm(C, NORM_FROBENIUS, &nc));
  PetscCall(MatDuplicate(C, MAT_COPY_VALUES, E.out()));
  if (*a != 0) PetscCall(MatAXPY(E, -*a, M, UNKNOWN_NONZERO_PATTERN));
  if (*b != 0) PetscCall(MatAXPY(E, -*b, K, UNKNOWN_NONZERO_PATTERN));
  PetscCall(MatNorm(E, NORM_FROBENIUS, &ne));
  *is = ne <= 1e-12 * nc;
  PetscFunctionReturn(0);
}

// The constraint modes are solved in blocks of right-hand-side columns, with an interrupt poll
// between blocks: one multi-RHS solve cannot be polled inside, and the 1353 columns of the
// 31119-DOF pad take 12-17 s in one solve (docs/records.md, "Constraint modes in blocks"). The
// factor is reused; only the right-hand side is split.
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

// Interface reduction of a Craig-Bampton model (matrices in contact order: point c's x, y, z at
// 3c .. 3c+2, then the m modes). With E_c = [t_c b_c] (3 x 2), the in-plane interface block
//   K_pp(2c+a, 2d+b) = E_c(:, a)^T K_r(3c.., 3d..) E_d(:, b)   (normals and modes held at 0), M_pp alike,
// gives the characteristic constraint modes K_pp Psi = M_pp Psi Lambda, Psi^T M_pp Psi = I; the
// k lowest replace the 2 n_c in-plane DOFs. T (n2 x n_c + k + m) maps the new coordinates
// [u_n (one per point), xi (k), eta (m)] to the CB ones: u_xyz(c) = n_c u_n,c + E_c Psi(2c.., :) xi.
// lam receives all 2 n_c eigenvalues (ascending), so the caller chooses k.
PetscErrorCode InPlaneModes(MPI_Comm comm, const ContactSet &cs, const Dense &Mp, const Dense &Kp, Dense &Psi,
                            std::vector<PetscReal> &lam)
{
  const PetscInt nc = cs.Size();
  PetscFunctionBeginUser;
  Dense Kpp(2 * nc, 2 * nc), Mpp(2 * nc, 2 * nc);
  for (PetscInt c = 0; c < nc; ++c) {
    Eigen::Matrix<PetscReal, 3, 2> Ec;
    Ec << cs.points[c].t, cs.points[c].b;
    for (PetscInt d = 0; d < nc; ++d) {
      Eigen::Matrix<PetscReal, 3, 2> Ed;
      Ed << cs.points[d].t, cs.points[d].b;
      Kpp.block<2, 2>(2 * c, 2 * d) = Ec.transpose() * Kp.block<3, 3>(3 * c, 3 * d) * Ed;
      Mpp.block<2, 2>(2 * c, 2 * d) = Ec.transpose() * Mp.block<3, 3>(3 * c, 3 * d) * Ed;
    }
  }
  Eigen::GeneralizedSelfAdjointEigenSolver<Dense> ges;
  PetscCallCXX(ges.compute(0.5 * (Kpp + Kpp.transpose()), 0.5 * (Mpp + Mpp.transpose())));
  PetscCheck(ges.info() == Eigen::Success, comm, kErrInput,
             "interface reduction: the in-plane interface block's eigenproblem failed (M_pp not positive definite?)");
  Psi = ges.eigenvectors(); // M_pp-normalised, ascending eigenvalues
  lam.assign(ges.eigenvalues().data(), ges.eigenvalues().data() + 2 * nc);
  PetscFunctionReturn(0);
}

// One log stage per phase of the reduction (-log_view), registered once per process.
struct Stages {
  PetscLogStage factor, modes, constraint, project;
};
PetscErrorCode GetStages(Stages *st)
{
  static Stages s{};
  static bool   done = false;
  PetscFunctionBeginUser;
  if (!done) {
    PetscCall(PetscLogStageRegister("CB factor K_II", &s.factor));
    PetscCall(PetscLogStageRegister("CB modes", &s.modes));
    PetscCall(PetscLogStageRegister("CB constraint", &s.constraint));
    PetscCall(PetscLogStageRegister("CB project", &s.project));
    done = true;
  }
  *st = s;
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode CraigBampton::SetOptionsPrefix(const char *prefix)
{
  PetscFunctionBeginUser;
  prefix_ = prefix ? prefix : "";
  PetscFunctionReturn(0);
}
PetscErrorCode CraigBampton::SetFMax(PetscReal fmax)
{
  PetscFunctionBeginUser;
  fmax_ = fmax;
  PetscFunctionReturn(0);
}
PetscErrorCode CraigBampton::SetNModes(PetscInt nmodes)
{
  PetscFunctionBeginUser;
  nmodes_ = nmodes;
  PetscFunctionReturn(0);
}
PetscErrorCode CraigBampton::SetFBand(PetscReal fband)
{
  PetscFunctionBeginUser;
  fband_ = fband;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::SetRayleighShortcut(bool on)
{
  PetscFunctionBeginUser;
  rayleigh_ = on ? PETSC_TRUE : PETSC_FALSE;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::SetRedundantFactor(bool on)
{
  PetscFunctionBeginUser;
  redundant_ = on ? PETSC_TRUE : PETSC_FALSE;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::SetRHSBlock(PetscInt block)
{
  PetscFunctionBeginUser;
  rhs_block_ = block;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::SetInterfaceModes(PetscInt k)
{
  PetscFunctionBeginUser;
  iface_modes_ = k;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::SetInterfaceFMax(PetscReal fmax)
{
  PetscFunctionBeginUser;
  iface_fmax_ = fmax;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::SetFromOptions(bool *enabled)
{
  const char *const types[] = {"none", "craig_bampton"};
  PetscInt          type    = 0;
  OptionChecks      checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, prefix_.c_str(), "Craig-Bampton model reduction", "CraigBampton");
  PetscCall(PetscOptionsEList("-type", "Model reduction: none or craig_bampton (contact DOFs + fixed-interface modes)",
                              "CraigBampton", types, 2, types[type], &type, nullptr));
  SquealOptionsReal("-fmax", "Cut-off frequency of the fixed-interface modes (Hz); 0: use -reduce_nmodes only", "CraigBampton",
                    &fmax_, Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-nmodes", "Number of fixed-interface modes (-1: all below -reduce_fmax)", "CraigBampton", nmodes_,
                            &nmodes_, nullptr));
  SquealOptionsReal("-fband", "Top of the frequency band of interest (Hz); a cut-off below it is refused", "CraigBampton", &fband_,
                    Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-max_modes", "Upper bound on the modes computed for -reduce_fmax", "CraigBampton", max_modes_,
                            &max_modes_, nullptr));
  PetscCall(PetscOptionsBool("-sparse_rhs", "Constraint modes from the sparse right-hand sides -K_IB (MUMPS ICNTL(20) = 1) instead of a dense block",
                             "CraigBampton", sparse_rhs_, &sparse_rhs_, nullptr));
  PetscCall(PetscOptionsInt("-rhs_block",
                            "Constraint modes solved in blocks of this many right-hand sides, a signal obeyed between blocks "
                            "(0: all in one solve)",
                            "CraigBampton", rhs_block_, &rhs_block_, nullptr));
  PetscCall(PetscOptionsBool("-count_modes", "Count the modes below -reduce_fmax by the inertia of K_II - (2 pi fmax)^2 M_II (one more factorisation) and solve once",
                             "CraigBampton", count_modes_, &count_modes_, nullptr));
  PetscCall(PetscOptionsBool("-rayleigh", "Project Rayleigh damping C = a M + b K (detected to round-off) as a M_r + b K_r",
                             "CraigBampton", rayleigh_, &rayleigh_, nullptr));
  PetscCall(PetscOptionsBool("-redundant", "On several ranks, every rank factorises the whole K_II and solves its share of the constraint modes alone (false: one distributed MUMPS factorisation and solve)",
                             "CraigBampton", redundant_, &redundant_, nullptr));
  PetscCall(PetscOptionsInt("-interface_modes",
                            "Interface reduction: keep this many in-plane characteristic constraint modes of the contact nodes "
                            "(normal DOFs stay physical; -1: no interface reduction, or all below -reduce_interface_fmax)",
                            "CraigBampton", iface_modes_, &iface_modes_, nullptr));
  SquealOptionsReal("-interface_fmax", "Interface reduction: keep the in-plane characteristic constraint modes below this frequency (Hz); 0: by count only",
                    "CraigBampton", &iface_fmax_, Range::NonNegative(), checks);
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  const std::string pre = OptionName(prefix_.c_str(), "");
  if (type == 1) {
    PetscCheck(fmax_ > 0 || nmodes_ >= 0, comm_, kErrInput,
               "%stype craig_bampton needs a cut-off: give %sfmax (Hz) or %snmodes", pre.c_str(), pre.c_str(), pre.c_str());
    PetscCheck(fband_ <= 0 || fmax_ <= 0 || fmax_ >= fband_, comm_, kErrInput,
               "cut-off %sfmax = %g Hz is below the band of interest (%sfband = %g Hz): raise %sfmax to 1.5-2 x %g Hz",
               pre.c_str(), (double)fmax_, pre.c_str(), (double)fband_, pre.c_str(), (double)fband_);
    PetscCheck(max_modes_ >= 1, comm_, kErrInput, "option %smax_modes = %" PetscInt_FMT ": expected >= 1", pre.c_str(), max_modes_);
    PetscCheck(iface_modes_ >= -1, comm_, kErrInput,
               "option %sinterface_modes = %" PetscInt_FMT ": expected >= 1 (or -1, the default: no interface reduction)", pre.c_str(),
               iface_modes_);
  }
  PetscCheck(type == 1 || (iface_modes_ < 0 && iface_fmax_ <= 0), comm_, kErrInput,
             "%sinterface_modes / %sinterface_fmax reduce the interface of a Craig-Bampton model: add %stype craig_bampton",
             pre.c_str(), pre.c_str(), pre.c_str());
  if (enabled) *enabled = type == 1;
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::Reduce(const Model &full, Model &red)
{
  MPI_Comm       comm = full.comm();
  PetscLogDouble t0, t1, t2, t3, t4, cpu[5];
  PetscInt       N, rstart, rend;
  Stages         stages{};
  PetscMPIInt    size;
  PetscFunctionBeginUser;
  PetscCall(GetStages(&stages));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  bool redundant = size > 1 && redundant_; // the final choice follows -<prefix>st_pc_type
  PetscCall(PetscTime(&t0));
  cpu[0] = (PetscLogDouble)std::clock() / CLOCKS_PER_SEC; // process CPU time, all threads (PetscGetCPUTime read ~0 here)
  info_ = ReductionInfo();
  PetscCall(MatGetSize(full.K, &N, nullptr));
  PetscCall(MatGetOwnershipRange(full.K, &rstart, &rend));

  // Interface in contact order: point c, its nodes, their x, y, z DOFs.
  PetscCheck(!full.contacts.HasExplicitColumns(), comm, kErrInput,
             "reduction: the contact set has explicit column entries (an already reduced model?); Craig-Bampton needs "
             "node-based contact points, reduce the full model instead");
  std::vector<PetscInt> iface;
  for (const ContactPoint &p : full.contacts.points)
    for (const ContactNode &nd : p.nodes)
      for (int k = 0; k < 3; ++k) iface.push_back(nd.dofs[k]);
  const PetscInt        nB = (PetscInt)iface.size();
  std::vector<PetscInt> where(N, -1); // full DOF -> position in the interface
  for (PetscInt k = 0; k < nB; ++k) {
    PetscCheck(iface[k] >= 0 && iface[k] < N, comm, kErrInput,
               "reduction: contact DOF %" PetscInt_FMT " is outside the model's %" PetscInt_FMT " DOFs", iface[k], N);
    PetscCheck(where[iface[k]] < 0, comm, kErrInput,
               "reduction: DOF %" PetscInt_FMT " belongs to two contact nodes; the interface must list each DOF once", iface[k]);
    where[iface[k]] = k;
  }
  const PetscInt nI = N - nB;
  PetscCheck(nI > 0, comm, kErrInput, "reduction: every DOF is a contact DOF, nothing to reduce (drop -reduce_type)");
  std::vector<PetscInt> Bsorted(iface), Iloc, Bloc;
  std::sort(Bsorted.begin(), Bsorted.end());
  for (PetscInt i = rstart; i < rend; ++i) (where[i] < 0 ? Iloc : Bloc).push_back(i);
  Handle<IS> isI, isB;
  PetscCall(ISCreateGeneral(comm, (PetscInt)Iloc.size(), Iloc.data(), PETSC_COPY_VALUES, isI.out()));
  PetscCall(ISCreateGeneral(comm, (PetscInt)Bloc.size(), Bloc.data(), PETSC_COPY_VALUES, isB.out()));
  info_.N           = N;
  info_.n_interface = nB;

  // One MUMPS Cholesky factorisation of K_II serves the eigensolver and the constraint modes: the
  // shift-and-invert shift is 0, so the spectral transformation's operator is K_II itself and its
  // KSP, set up here, is not factorised again inside EPSSolve.
  PetscCall(PetscLogStagePush(stages.factor));
  MatH Kii, Kib, Mii;
  PetscCall(MatCreateSubMatrix(full.K, isI, isI, MAT_INITIAL_MATRIX, Kii.out()));
  PetscCall(MatCreateSubMatrix(full.K, isI, isB, MAT_INITIAL_MATRIX, Kib.out()));
  PetscCall(MatCreateSubMatrix(full.M, isI, isI, MAT_INITIAL_MATRIX, Mii.out()));
  EPSH            eps;
  Mat             Fct; // owned by the ST's PC
  PetscInt        nev   = 0;
  const PetscReal w2max = fmax_ > 0 ? std::pow(2 * PETSC_PI * fmax_, 2) : kInf;
  {
    ST        st;
    KSP       ksp;
    PC        pc, fpc = nullptr; // fpc: the PC that holds the factor (pc itself, or the redundant PC's inner one)
    PetscBool isfactor, isredundant;
    PetscCall(EPSCreate(comm, eps.out()));
    PetscCall(EPSSetOptionsPrefix(eps, prefix_.c_str()));
    PetscCall(EPSSetOperators(eps, Kii, Mii));
    PetscCall(EPSSetProblemType(eps, EPS_GHEP));
    PetscCall(EPSSetType(eps, EPSKRYLOVSCHUR));
    PetscCall(EPSSetTarget(eps, 0.0));
    PetscCall(EPSSetWhichEigenpairs(eps, EPS_TARGET_MAGNITUDE));
    PetscCall(EPSSetTolerances(eps, 1e-10, PETSC_DEFAULT));
    PetscCall(EPSGetST(eps, &st));
    PetscCall(STSetType(st, STSINVERT));
    PetscCall(STGetKSP(st, &ksp));
    PetscCall(KSPSetType(ksp, KSPPREONLY));
    PetscCall(KSPGetPC(ksp, &pc));
    if (redundant) {
      PetscCall(PCSetType(pc, PCREDUNDANT));
      PetscCall(PCRedundantSetNumber(pc, size));
    } else {
      PetscCall(PCSetType(pc, PCCHOLESKY));
      PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
    }
    nev = nmodes_ > 0 ? nmodes_ : 24;
    nev = PetscMax(1, PetscMin(nev, PetscMin(max_modes_, nI)));
    PetscCall(EPSSetDimensions(eps, nev, PETSC_DEFAULT, PETSC_DEFAULT));
    PetscCall(EPSSetFromOptions(eps));
    PetscCall(EPSMonitorSet(
      eps,
      [](EPS e, PetscInt, PetscInt, PetscScalar *, PetscScalar *, PetscReal *, PetscInt, void *) -> PetscErrorCode {
        return InterruptPoint(PetscObjectComm((PetscObject)e), "the Craig-Bampton fixed-interface modes");
      },
      nullptr, nullptr));
    PetscCall(KSPSetOperators(ksp, Kii, Kii));
    PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCREDUNDANT, &isredundant));
    fpc = pc;
    if (isredundant) {
      // One whole copy of K_II per rank (one subcommunicator of one rank each), factorised by
      // the same sequential Cholesky as on one rank; its options under -<prefix>st_redundant_.
      KSP inner;
      PetscCall(PCRedundantGetKSP(pc, &inner));
      PetscCall(KSPSetType(inner, KSPPREONLY));
      PetscCall(KSPGetPC(inner, &fpc));
      PetscCall(PCSetType(fpc, PCCHOLESKY));
      PetscCall(PCFactorSetMatSolverType(fpc, MATSOLVERMUMPS));
    }
    PetscCall(KSPSetUp(ksp));
    PetscCall(PetscObjectTypeCompareAny((PetscObject)fpc, &isfactor, PCCHOLESKY, PCLU, ""));
    PetscCheck(isfactor, comm, kErrInput,
               "reduction: -%sst_%spc_type must be cholesky or lu: the constraint modes reuse the eigensolver's factorisation of K_II",
               prefix_.c_str(), isredundant ? "redundant_" : "");
    if (isredundant) {
      MPI_Comm fcomm;
      PetscMPIInt fsize;
      PetscCall(PetscObjectGetComm((PetscObject)fpc, &fcomm));
      PetscCallMPI(MPI_Comm_size(fcomm, &fsize));
      PetscCheck(fsize == 1, comm, kErrInput,
                 "reduction: -%sst_pc_redundant_number must be the number of ranks (%d): each rank solves its constraint modes alone",
                 prefix_.c_str(), (int)size);
    }
    redundant = isredundant;
    PetscCall(PCFactorGetMatrix(fpc, &Fct));
    MatFactorError ferr;
    PetscCall(MatFactorGetError(Fct, &ferr));
    PetscCheck(ferr == MAT_FACTOR_NOERROR, comm, kErrInput,
               "reduction: K_II (stiffness with every contact DOF held) cannot be factorised (MUMPS error %d): part of the "
               "structure is not held by the contact nodes or supports; add supports (e.g. -model_support_kn/-model_support_kt) "
               "or contact nodes there",
               (int)ferr);
  }
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&t1));
  cpu[1] = (PetscLogDouble)std::clock() / CLOCKS_PER_SEC;

  // Fixed-interface modes of (K_II, M_II) up to the cut-off.
  PetscCall(PetscLogStagePush(stages.modes));
  std::vector<PetscReal> lam;
  PetscInt               nconv = 0;
  // With a cut-off alone, the count of modes below it is the number of negative pivots of
  // K_II - (2 pi fmax)^2 M_II (Sylvester's inertia; one more factorisation): one solve then asks
  // for exactly those, instead of solving again and again with a growing request.
  bool counted = false;
  if (fmax_ > 0 && nmodes_ < 0 && count_modes_) {
    MatH     A, F;
    PetscInt nneg = 0;
    PetscCall(MatDuplicate(Kii, MAT_COPY_VALUES, A.out()));
    PetscCall(MatAXPY(A, -w2max, Mii, UNKNOWN_NONZERO_PATTERN));
    PetscCall(MatSetOption(A, MAT_SYMMETRIC, PETSC_TRUE));
    MatFactorInfo finfo;
    PetscCall(MatFactorInfoInitialize(&finfo));
    PetscCall(MatGetFactor(A, MATSOLVERMUMPS, MAT_FACTOR_CHOLESKY, F.out()));
    PetscCall(MatMumpsSetIcntl(F, 13, 1)); // the root node factorised without ScaLAPACK, so its pivots count
    PetscCall(MatCholeskyFactorSymbolic(F, A, nullptr, &finfo));
    PetscCall(MatCholeskyFactorNumeric(F, A, &finfo));
    MatFactorError ferr;
    PetscCall(MatFactorGetError(F, &ferr));
    if (ferr == MAT_FACTOR_NOERROR) {
      PetscCall(MatGetInertia(F, &nneg, nullptr, nullptr));
      counted = true;
      if (nneg > PetscMin(max_modes_, nI))
        PetscCall(PetscPrintf(comm,
                              "reduction: warning: %" PetscInt_FMT " fixed-interface modes lie below %g Hz, more than -%smax_modes = %" PetscInt_FMT
                              "; only the lowest %" PetscInt_FMT " are kept: raise -%smax_modes or lower -%sfmax\n",
                              nneg, (double)fmax_, prefix_.c_str(), max_modes_, PetscMin(max_modes_, nI), prefix_.c_str(), prefix_.c_str()));
      nev = PetscMin(nneg, PetscMin(max_modes_, nI));
      if (nev > 0) PetscCall(EPSSetDimensions(eps, nev, PETSC_DEFAULT, PETSC_DEFAULT));
    } // else (a mode at the cut-off itself): the growing requests below
  }
  if (nmodes_ != 0 && !(counted && nev == 0)) {
    for (;;) {
      PetscCall(EPSSolve(eps));
      PetscCall(EPSGetConverged(eps, &nconv));
      lam.resize(nconv);
      for (PetscInt i = 0; i < nconv; ++i) {
        PetscScalar kr, ki;
        PetscCall(EPSGetEigenvalue(eps, i, &kr, &ki));
        lam[i] = PetscRealPart(kr);
      }
      // With a frequency cut-off, grow the request until a converged mode lies above it. Every
      // solve starts afresh, so the next request is sized at once from the modes found (count
      // growing like f^2, as for a plate's in-plane and through-thickness families, + 25 %)
      // rather than doubled step by step.
      const PetscReal lmax  = nconv > 0 ? *std::max_element(lam.begin(), lam.end()) : 0;
      const bool      above = nconv > 0 && lmax > w2max;
      if (counted || nmodes_ > 0 || fmax_ <= 0 || above || nev >= PetscMin(max_modes_, nI)) break;
      PetscInt next = 2 * nev;
      if (nconv > 0 && lmax > 0) next = PetscMax(next, (PetscInt)std::ceil(1.25 * nconv * (w2max / lmax)));
      nev = PetscMin(next, PetscMin(max_modes_, nI));
      PetscCall(EPSSetDimensions(eps, nev, PETSC_DEFAULT, PETSC_DEFAULT));
    }
  }
  std::vector<PetscInt> keep(nconv);
  std::iota(keep.begin(), keep.end(), 0);
  std::sort(keep.begin(), keep.end(), [&](PetscInt a, PetscInt b) { return lam[a] < lam[b]; });
  while (!keep.empty() && lam[keep.back()] > w2max) keep.pop_back();
  if (nmodes_ > 0 && (PetscInt)keep.size() > nmodes_) keep.resize(nmodes_);
  if (!counted && fmax_ > 0 && nmodes_ < 0 && nconv > 0 && *std::max_element(lam.begin(), lam.end()) <= w2max)
    PetscCall(PetscPrintf(comm,
                          "reduction: warning: %" PetscInt_FMT " modes (-%smax_modes) do not reach the cut-off %g Hz; raise "
                          "-%smax_modes\n",
                          (PetscInt)keep.size(), prefix_.c_str(), (double)fmax_, prefix_.c_str()));
  const PetscInt m  = (PetscInt)keep.size();
  const PetscInt n2 = nB + m;
  if (m == 0 && nmodes_ < 0 && nI > 0) {
    char f[32]; // PETSc's %g would print "10."
    std::snprintf(f, sizeof f, "%g", (double)fmax_);
    PetscCall(PetscPrintf(comm,
                          "reduction: warning: no fixed-interface mode lies below -%sfmax = %s Hz: the reduction is static (Guyan, "
                          "interface DOFs only) and misses every interior resonance; raise -%sfmax, or give -%snmodes 0 to ask for "
                          "a static reduction\n",
                          prefix_.c_str(), f, prefix_.c_str(), prefix_.c_str()));
  }
  info_.n_modes     = m;
  for (PetscInt k : keep) info_.freq.push_back(std::sqrt(PetscMax(lam[k], 0.0)) / (2 * PETSC_PI));

  // W = [Psi Phi] (interior rows), Phi M_II-normalised.
  MatH     W;
  PetscInt nIloc;
  PetscCall(MatGetLocalSize(Kii, &nIloc, nullptr));
  PetscCall(MatCreateDense(comm, nIloc, PETSC_DECIDE, nI, n2, nullptr, W.out()));
  {
    VecH x, y;
    PetscCall(MatCreateVecs(Kii, x.out(), y.out()));
    for (PetscInt k = 0; k < m; ++k) {
      Vec       col;
      PetscReal nrm2;
      PetscCall(EPSGetEigenvector(eps, keep[k], x, nullptr));
      PetscCall(MatMult(Mii, x, y));
      PetscCall(VecDot(x, y, &nrm2));
      // Sign fixed by the entry of largest modulus, so that any rank count gives the same basis.
      PetscReal xmax, xmin;
      PetscCall(VecMax(x, nullptr, &xmax));
      PetscCall(VecMin(x, nullptr, &xmin));
      PetscCall(VecScale(x, (-xmin > xmax ? -1.0 : 1.0) / std::sqrt(PetscRealPart(nrm2))));
      PetscCall(MatDenseGetColumnVecWrite(W, nB + k, &col));
      PetscCall(VecCopy(x, col));
      PetscCall(MatDenseRestoreColumnVecWrite(W, nB + k, &col));
    }
  }
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&t2));
  cpu[2] = (PetscLogDouble)std::clock() / CLOCKS_PER_SEC;

  // Constraint modes Psi = -K_II^{-1} K_IB: nB right-hand sides in blocks of -reduce_rhs_block
  // (a signal is obeyed between blocks), written straight into the first nB columns of W (no
  // second N x nB copy).
  PetscCall(PetscLogStagePush(stages.constraint));
  {
    MatH      R;
    Mat       Wpsi;
    PetscReal nrm;
    if (redundant) PetscCall(RedundantConstraintModes(Fct, Kib, sparse_rhs_, rhs_block_, W));
    else {
      // Sparse: -K_IB as a sparse right-hand side (MUMPS ICNTL(20) = 1): the forward substitution
      // prunes the elimination tree to the paths its few nonzero rows reach. MUMPS takes it
      // centralised and transposed, so each block of (-K_IB)^T is gathered on rank 0.
      if (sparse_rhs_) PetscCall(MatTranspose(Kib, MAT_INITIAL_MATRIX, R.out()));
      else PetscCall(MatConvert(Kib, MATDENSE, MAT_INITIAL_MATRIX, R.out()));
      PetscCall(MatScale(R, -1.0));
      const PetscInt b = BlockSize(rhs_block_, nB);
      for (PetscInt j0 = 0; j0 < nB; j0 += b) {
        if (j0 > 0) PetscCall(InterruptPoint(comm, kConstraintWhere));
        PetscCall(SolveBlock(Fct, R, sparse_rhs_, comm, j0, PetscMin(nB, j0 + b), nI, W));
      }
    }
    PetscCall(MatDenseGetSubMatrix(W, PETSC_DECIDE, PETSC_DECIDE, 0, nB, &Wpsi));
    PetscCall(MatNorm(Wpsi, NORM_FROBENIUS, &nrm));
    PetscCall(MatDenseRestoreSubMatrix(W, &Wpsi));
    PetscCheck(!PetscIsInfOrNanReal(nrm) && nrm < 1e12 * std::sqrt((PetscReal)nB), comm, kErrInput,
               "reduction: K_II is singular or nearly so (constraint modes of norm %g): part of the structure is not held by "
               "the contact nodes or supports; add supports (e.g. -model_support_kn/-model_support_kt)",
               (double)nrm);
  }
  PetscCall(MatAssemblyBegin(W, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(W, MAT_FINAL_ASSEMBLY));
  eps.reset();
  PetscCall(PetscLogStagePop());
  // One solve with nB right-hand sides cannot be polled inside: a signal is obeyed here, before the projection.
  PetscCall(InterruptPoint(comm, "the Craig-Bampton reduction (after its constraint modes)"));
  PetscCall(PetscTime(&t3));
  cpu[3] = (PetscLogDouble)std::clock() / CLOCKS_PER_SEC;
  PetscCall(PetscLogStagePush(stages.project));

  // A_r = T^T A T in the order [B sorted by global index, modes], then permuted to contact order:
  //   P = W^T A_II W,  S = A_BI W,  A_r = P + [A_BB + S_B + S_B^T, S_M; S_M^T, 0].
  std::vector<PetscInt> perm(n2); // reduced position (contact order) of sorted position
  for (PetscInt k = 0; k < nB; ++k) perm[k] = where[Bsorted[k]];
  for (PetscInt k = 0; k < m; ++k) perm[nB + k] = nB + k;
  // For K the projection is known in closed form (Psi^T (K_IB + K_II Psi) = 0, Phi^T K_II Phi =
  // Omega^2): K_r = [K_BB + K_BI Psi, 0; 0, Omega^2], which saves the dense product W^T K_II W.
  auto project = [&](Mat A, bool stiffness, Dense &Ar) -> PetscErrorCode {
    MatH  Aii, Aib, G;
    Dense Sd, Abb;
    PetscFunctionBeginUser;
    PetscCall(MatCreateSubMatrix(A, isI, isB, MAT_INITIAL_MATRIX, Aib.out()));
    PetscCall(InterfaceTransposeProduct(Aib, W, Sd));
    PetscCall(GatherSubmatrix(A, Bsorted, Abb));
    if (stiffness) {
      Ar                       = Dense::Zero(n2, n2);
      Ar.topLeftCorner(nB, nB) = Abb + 0.5 * (Sd.leftCols(nB) + Sd.leftCols(nB).transpose());
      for (PetscInt k = 0; k < m; ++k) Ar(nB + k, nB + k) = lam[keep[k]];
    } else {
      PetscCall(MatCreateSubMatrix(A, isI, isI, MAT_INITIAL_MATRIX, Aii.out()));
      PetscCall(MatMatMult(Aii, W, MAT_INITIAL_MATRIX, PETSC_DEFAULT, G.out()));
      PetscCall(SymmetricTransposeProduct(W, G, Ar));
      Ar.topLeftCorner(nB, nB) += Abb + Sd.leftCols(nB) + Sd.leftCols(nB).transpose();
      Ar.topRightCorner(nB, m) += Sd.rightCols(m);
      Ar.bottomLeftCorner(m, nB) += Sd.rightCols(m).transpose();
    }
    PetscFunctionReturn(0);
  };
  auto permute = [&](const Dense &Ar) {
    Dense Ap(n2, n2);
    for (PetscInt i = 0; i < n2; ++i)
      for (PetscInt j = 0; j < n2; ++j) Ap(perm[i], perm[j]) = Ar(i, j);
    return Ap;
  };
  Dense T; // interface reduction: n2 x (n_c + k + m), CB coordinates from the new ones; empty: none
  auto  finish = [&](const Dense &Ar, Mat *out) -> PetscErrorCode {
    PetscFunctionBeginUser;
    Dense Ap = permute(Ar);
    if (T.size()) {
      Dense AT;
      PetscCallCXX(AT.noalias() = Ap * T);
      PetscCallCXX(Ap.noalias() = T.transpose() * AT);
    }
    PetscCall(CreateReducedMat(comm, Ap, out));
    PetscFunctionReturn(0);
  };
  const PetscInt nc = full.contacts.Size();
  {
    Dense Mr, Kr, Cr;
    PetscCall(project(full.M, false, Mr));
    PetscCall(project(full.K, true, Kr));
    // Rayleigh damping C = a M + b K projects to a M_r + b K_r exactly (the projection is linear),
    // which saves the dense product W^T C_II W; any other C is projected like M.
    PetscReal ray_a = 0, ray_b = 0;
    bool      rayleigh = false;
    if (full.C && rayleigh_) PetscCall(DetectRayleigh(full.M, full.K, full.C, &rayleigh, &ray_a, &ray_b));
    info_.rayleigh = rayleigh;
    if (full.C && rayleigh) Cr = ray_a * Mr + ray_b * Kr;
    else if (full.C) PetscCall(project(full.C, false, Cr));
    if (iface_modes_ >= 0 || iface_fmax_ > 0) {
      const std::string pre = OptionName(prefix_.c_str(), "");
      for (PetscInt c = 0; c < nc; ++c)
        PetscCheck(full.contacts.points[c].nodes.size() == 1, comm, kErrInput,
                   "interface reduction: contact %" PetscInt_FMT " has %zu nodes; %sinterface_modes needs one node per contact point "
                   "(drop the option)", c, full.contacts.points[c].nodes.size(), pre.c_str());
      PetscCheck(iface_modes_ <= 2 * nc, comm, kErrInput,
                 "%sinterface_modes %" PetscInt_FMT " exceeds the %" PetscInt_FMT " in-plane interface DOFs (2 x %" PetscInt_FMT
                 " contact points): give at most %" PetscInt_FMT, pre.c_str(), iface_modes_, 2 * nc, nc, 2 * nc);
      Dense                  Psi;
      std::vector<PetscReal> lam;
      PetscCall(InPlaneModes(comm, full.contacts, permute(Mr), permute(Kr), Psi, lam));
      PetscInt k = 2 * nc;
      if (iface_fmax_ > 0) {
        const PetscReal w2 = std::pow(2 * PETSC_PI * iface_fmax_, 2);
        k = (PetscInt)(std::upper_bound(lam.begin(), lam.end(), w2) - lam.begin());
        PetscCheck(k > 0, comm, kErrInput,
                   "%sinterface_fmax %g Hz keeps no in-plane interface mode (the lowest is at %g Hz): raise it", pre.c_str(),
                   (double)iface_fmax_, std::sqrt(std::max(lam[0], (PetscReal)0)) / (2 * PETSC_PI));
      }
      if (iface_modes_ >= 0) k = std::min(k, iface_modes_);
      PetscCheck(k > 0, comm, kErrInput,
                 "%sinterface_modes 0 keeps no in-plane interface mode: give k >= 1, or -1 (default) for no interface reduction",
                 pre.c_str());
      T = Dense::Zero(n2, nc + k + m);
      for (PetscInt c = 0; c < nc; ++c) {
        const ContactPoint &p = full.contacts.points[c];
        T.block<3, 1>(3 * c, c) = p.n;
        for (PetscInt j = 0; j < k; ++j) T.block<3, 1>(3 * c, nc + j) = p.t * Psi(2 * c, j) + p.b * Psi(2 * c + 1, j);
      }
      for (PetscInt q = 0; q < m; ++q) T(nB + q, nc + k + q) = 1;
      info_.n_normal = nc;
      info_.n_inplane_modes = k;
      info_.inplane_freq.clear();
      for (PetscInt j = 0; j < k; ++j) info_.inplane_freq.push_back(std::sqrt(std::max(lam[j], (PetscReal)0)) / (2 * PETSC_PI));
      red.contacts = full.contacts;
      for (PetscInt c = 0; c < nc; ++c) {
        ContactPoint   &p = red.contacts.points[c];
        const PetscReal w = p.nodes[0].weight;
        p.nodes.clear();
        for (ColumnEntries &col : p.cols) col.clear();
        // h_n selects the normal coordinate: the pivot elimination and the node-wise unilateral
        // law stay exact; h_t, h_b are rows of the in-plane mode matrix, dense over xi.
        p.cols[kN].emplace_back(c, w);
        for (PetscInt j = 0; j < k; ++j) {
          p.cols[kT].emplace_back(nc + j, w * Psi(2 * c, j));
          p.cols[kB].emplace_back(nc + j, w * Psi(2 * c + 1, j));
        }
      }
    }
    PetscCall(finish(Mr, red.M.out()));
    PetscCall(finish(Kr, red.K.out()));
    if (full.C) PetscCall(finish(Cr, red.C.out()));
    else red.C.reset();
  }

  // F_r = T^T F = [F_B + Psi^T F_I; Phi^T F_I].
  {
    Vec                    FI;
    VecH                   t;
    std::vector<PetscReal> Ffull, tw, Fr(n2, 0.0);
    PetscCall(VecGetSubVector(full.F, isI, &FI));
    PetscCall(MatCreateVecs(W, t.out(), nullptr));
    PetscCall(MatMultTranspose(W, FI, t));
    PetscCall(VecRestoreSubVector(full.F, isI, &FI));
    PetscCall(GatherVector(t, true, tw));
    PetscCall(GatherVector(full.F, true, Ffull));
    for (PetscInt k = 0; k < nB; ++k) Fr[perm[k]] = Ffull[Bsorted[k]] + tw[k];
    for (PetscInt k = 0; k < m; ++k) Fr[nB + k] = tw[nB + k];
    if (T.size()) {
      const Eigen::Map<const Eigen::Matrix<PetscReal, Eigen::Dynamic, 1>> f(Fr.data(), n2);
      const Eigen::Matrix<PetscReal, Eigen::Dynamic, 1>                   g = T.transpose() * f;
      Fr.assign(g.data(), g.data() + g.size());
    }
    PetscCall(MatCreateVecs(red.K, nullptr, red.F.out()));
    PetscInt lo, hi;
    PetscCall(VecGetOwnershipRange(red.F, &lo, &hi));
    for (PetscInt i = lo; i < hi; ++i) PetscCall(VecSetValue(red.F, i, Fr[i], INSERT_VALUES));
    PetscCall(VecAssemblyBegin(red.F));
    PetscCall(VecAssemblyEnd(red.F));
  }

  // The contact set follows its DOFs to the first 3 n_c positions; frames and speeds unchanged
  // (with interface reduction it was set above).
  if (!T.size()) {
    red.contacts = full.contacts;
    PetscInt next = 0;
    for (ContactPoint &p : red.contacts.points)
      for (ContactNode &nd : p.nodes)
        for (int k = 0; k < 3; ++k) {
          PetscCheck(where[nd.dofs[k]] == next, comm, PETSC_ERR_PLIB, "reduction: contact DOF %" PetscInt_FMT " missing from the basis",
                     nd.dofs[k]);
          nd.dofs[k] = next++;
        }
  }
  char name[128];
  PetscCall(PetscSNPrintf(name, sizeof(name), " + CB(%" PetscInt_FMT " + %" PetscInt_FMT ")", nB, m));
  red.name = full.name + name;
  if (T.size()) {
    PetscCall(PetscSNPrintf(name, sizeof(name), " + IR(%" PetscInt_FMT " normal + %" PetscInt_FMT " in-plane)", info_.n_normal,
                            info_.n_inplane_modes));
    red.name += name;
  }
  PetscCall(red.Validate());
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&t4));
  cpu[4] = (PetscLogDouble)std::clock() / CLOCKS_PER_SEC;
  info_.time_factor  = t1 - t0;
  info_.time_modes   = t2 - t1;
  info_.time_static  = t3 - t2;
  info_.time_project = t4 - t3;
  info_.time_total   = t4 - t0;
  PetscLogDouble dcpu[4] = {cpu[1] - cpu[0], cpu[2] - cpu[1], cpu[3] - cpu[2], cpu[4] - cpu[3]};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, dcpu, 4, MPI_DOUBLE, MPI_MAX, comm));
  info_.cpu_factor = dcpu[0], info_.cpu_modes = dcpu[1], info_.cpu_static = dcpu[2], info_.cpu_project = dcpu[3];
  PetscLogDouble mem = 0;
  PetscCall(PetscMemoryGetCurrentUsage(&mem));
  PetscCallMPI(MPI_Allreduce(&mem, &info_.mem_peak, 1, MPI_DOUBLE, MPI_SUM, comm));
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::View(PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "Craig-Bampton reduction: %" PetscInt_FMT " DOFs -> %" PetscInt_FMT " (%" PetscInt_FMT
                                   " interface DOFs of the contact nodes + %" PetscInt_FMT " fixed-interface modes",
                                   info_.N, info_.n_interface + info_.n_modes, info_.n_interface, info_.n_modes));
  if (info_.n_modes > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, ", %.1f to %.1f Hz", (double)info_.freq.front(), (double)info_.freq.back()));
  PetscCall(PetscViewerASCIIPrintf(viewer, ")\n"));
  if (info_.n_inplane_modes > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "  interface reduction: %" PetscInt_FMT " interface DOFs -> %" PetscInt_FMT " normal + %" PetscInt_FMT
                                     " in-plane characteristic constraint modes (%.1f to %.1f Hz): %" PetscInt_FMT " DOFs\n",
                                     info_.n_interface, info_.n_normal, info_.n_inplane_modes, (double)info_.inplane_freq.front(),
                                     (double)info_.inplane_freq.back(), info_.n_normal + info_.n_inplane_modes + info_.n_modes));
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "  time %.3f s (factorisation of K_II %.3f s, fixed-interface modes %.3f s, constraint modes %.3f s, "
                                   "projection %.3f s%s), resident memory %.1f MB\n",
                                   (double)info_.time_total, (double)info_.time_factor, (double)info_.time_modes,
                                   (double)info_.time_static, (double)info_.time_project,
                                   info_.rayleigh ? ", C = a M + b K projected as a M_r + b K_r" : "",
                                   (double)(info_.mem_peak / 1048576.0)));
  PetscCall(PetscViewerASCIIPrintf(viewer, "  CPU time of the busiest rank: %.3f s (%.3f, %.3f, %.3f, %.3f)\n",
                                   (double)(info_.cpu_factor + info_.cpu_modes + info_.cpu_static + info_.cpu_project),
                                   (double)info_.cpu_factor, (double)info_.cpu_modes, (double)info_.cpu_static, (double)info_.cpu_project));
  PetscFunctionReturn(0);
}

} // namespace squeal
