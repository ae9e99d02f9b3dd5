#include "squeal/reduction/craig_bampton.h"
#include "internal.h"

#include "squeal/core/interrupt.h"
#include "squeal/core/inf.h"
#include "squeal/core/dense_blas.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/options.h"
#include "squeal/core/sparse.h"
#include "squeal/stability/stability.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <ctime>
#include <memory>
#include <numeric>

#include <sys/resource.h>

namespace squeal {

namespace {

using cb::Dense;

// S = A_IB^T W (nB x n) on every rank, for a sparse A_IB with the row layout of W: each rank adds
// a_ij W(i, :) to row j of S for the nonzeros of its rows (a few per row, near the interface),
// then the shares are summed. PETSc's MatTransposeMatMult took 1.3 s per call on the 31119-DOF
// pad for 1e8 flops (symbolic transpose and sparse-dense product). A row of the column-major W is
// strided by its leading dimension: read whole, each of its entries is on another page (3.5 s a
// call on the 126 861-DOF brake). So the rows A_IB touches are copied, a block of columns at a
// time, into a small transposed block whose columns are those rows' contiguous pieces.
PetscErrorCode InterfaceTransposeProduct(Mat Aib, Mat W, Dense &S)
{
  MPI_Comm               comm;
  PetscInt               nB, n, rstart, rend, lda;
  const PetscScalar     *w;
  std::vector<PetscInt>  rows, ptr{0}, cols; // the local rows with entries (local index), CSR
  std::vector<PetscReal> vals;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)W, &comm));
  PetscCall(MatGetSize(Aib, nullptr, &nB));
  PetscCall(MatGetSize(W, nullptr, &n));
  PetscCall(MatGetOwnershipRange(Aib, &rstart, &rend));
  PetscCall(MatDenseGetLDA(W, &lda));
  for (PetscInt i = rstart; i < rend; ++i) {
    PetscInt           nc;
    const PetscInt    *c;
    const PetscScalar *v;
    PetscCall(MatGetRow(Aib, i, &nc, &c, &v));
    if (nc > 0) {
      rows.push_back(i - rstart);
      for (PetscInt k = 0; k < nc; ++k) cols.push_back(c[k]), vals.push_back(PetscRealPart(v[k]));
      ptr.push_back((PetscInt)cols.size());
    }
    PetscCall(MatRestoreRow(Aib, i, &nc, &c, &v));
  }
  const PetscInt nr = (PetscInt)rows.size();
  constexpr PetscInt bs = 32, rchunk = 512; // a chunk of the block: 128 kB
  Dense St = Dense::Zero(n, nB);            // S^T: the updates go down contiguous columns
  Dense Tb(bs, nr);                         // Tb(jj, r) = W(rows[r], j0 + jj)
  PetscCall(MatDenseGetArrayRead(W, &w));
  for (PetscInt j0 = 0; j0 < n; j0 += bs) {
    const PetscInt jb = PetscMin(bs, n - j0);
    for (PetscInt r0 = 0; r0 < nr; r0 += rchunk)
      for (PetscInt jj = 0; jj < jb; ++jj) {
        const PetscScalar *wc = w + (size_t)(j0 + jj) * lda;
        for (PetscInt r = r0; r < PetscMin(nr, r0 + rchunk); ++r) Tb(jj, r) = PetscRealPart(wc[rows[r]]);
      }
    for (PetscInt r = 0; r < nr; ++r)
      for (PetscInt k = ptr[r]; k < ptr[r + 1]; ++k) St.col(cols[k]).segment(j0, jb) += vals[k] * Tb.col(r).head(jb);
  }
  PetscCall(MatDenseRestoreArrayRead(W, &w));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, St.data(), (int)(n * nB), MPIU_REAL, MPI_SUM, comm));
  S = St.transpose();
  PetscFunctionReturn(0);
}

// Every rank receives A(rows, rows) for a (small) list of global rows, as a dense matrix.
PetscErrorCode GatherSubmatrix(Mat A, const std::vector<PetscInt> &rows, Dense &out)
{
  Handle<IS> is;
  PetscFunctionBeginUser;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, (PetscInt)rows.size(), rows.data(), PETSC_COPY_VALUES, is.out()));
  PetscCall(squeal::GatherSubmatrix(A, is, is, out));
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

// P = W^T A W for a symmetric A (same row layout as W) and W's first nc columns, on every rank, a
// block of columns of W at a time: the whole A W would be a second N x n dense block (4.1 GB for
// the 126 861-DOF brake at n = 4019), beside W at the peak of the reduction. Each rank forms its
// rows' share of the block column's lower part (half the flops of a full product; through OpenBLAS
// where it stands behind the system BLAS, 51 against Eigen's 42 GF/s on this shape, else Eigen),
// the shares are summed, and the triangle mirrored: no N x n block leaves its rank.
PetscErrorCode SymmetricProjection(Mat A, Mat W, PetscInt nc, Dense &P)
{
  MPI_Comm       comm;
  PetscInt       nloc, n;
  const PetscInt block = 256; // columns: 2 MB per 1000 local rows
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)W, &comm));
  PetscCall(MatGetLocalSize(W, &nloc, nullptr));
  PetscCall(MatGetSize(W, nullptr, &n));
  n = PetscMin(n, nc);
  P = Dense::Zero(n, n);
  // A matrix with entries on a few rows (a part damped on its own: the lining's 9 765 of the
  // 126 861-DOF brake's rows) needs W^T G over those rows only, G = A W being zero elsewhere.
  std::vector<PetscInt> rows;
  {
    PetscInt rstart, rend;
    PetscCall(MatGetOwnershipRange(A, &rstart, &rend));
    PetscCheck(rend - rstart == nloc, PETSC_COMM_SELF, PETSC_ERR_PLIB, "projection: A's rows are not laid out as W's");
    for (PetscInt i = rstart; i < rend; ++i) {
      PetscInt ncols;
      PetscCall(MatGetRow(A, i, &ncols, nullptr, nullptr));
      if (ncols > 0) rows.push_back(i - rstart);
      PetscCall(MatRestoreRow(A, i, &ncols, nullptr, nullptr));
    }
  }
  const bool compact = 2 * (PetscInt)rows.size() < nloc;
  Dense      Wc, Gc;
  for (PetscInt c0 = 0; c0 < n; c0 += block) {
    // Seconds a block on the 126 861-DOF brake (122 s for the projections there, polled nowhere
    // before: under mpiexec the ranks were killed a second after the signal, without a word).
    PetscCall(InterruptPoint(comm, "the Craig-Bampton projection"));
    const PetscInt     c1 = PetscMin(n, c0 + block);
    Mat                Wb;
    MatH               Gb;
    PetscInt           ldw, ldg;
    const PetscScalar *w, *g;
    PetscCall(MatDenseGetSubMatrix(W, PETSC_DECIDE, PETSC_DECIDE, c0, c1, &Wb));
    PetscCall(MatMatMult(A, Wb, MAT_INITIAL_MATRIX, PETSC_DEFAULT, Gb.out()));
    PetscCall(MatDenseRestoreSubMatrix(W, &Wb));
    PetscCall(MatDenseGetLDA(W, &ldw));
    PetscCall(MatDenseGetLDA(Gb, &ldg));
    PetscCall(MatDenseGetArrayRead(W, &w));
    PetscCall(MatDenseGetArrayRead(Gb, &g));
    if (nloc > 0) {
      using CMap = Eigen::Map<const Dense, 0, Eigen::OuterStride<>>;
      const CMap Wl(w + (size_t)c0 * ldw, nloc, n - c0, Eigen::OuterStride<>(ldw)), Gl(g, nloc, c1 - c0, Eigen::OuterStride<>(ldg));
      auto       Pb = P.block(c0, c0, n - c0, c1 - c0);
      if (compact) {
        const PetscInt nr = (PetscInt)rows.size();
        Wc.resize(nr, n - c0), Gc.resize(nr, c1 - c0);
        for (PetscInt r = 0; r < nr; ++r) Wc.row(r) = Wl.row(rows[r]), Gc.row(r) = Gl.row(rows[r]);
        if (nr > 0) Gemm(Wc, true, Gc, Pb, 1.0, 1.0);
      } else Gemm(Wl, true, Gl, Pb, 1.0, 1.0);
    }
    PetscCall(MatDenseRestoreArrayRead(Gb, &g));
    PetscCall(MatDenseRestoreArrayRead(W, &w));
  }
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

// CPU time of the process, all threads (PetscGetCPUTime read ~0 here).
PetscLogDouble CpuNow() { return (PetscLogDouble)std::clock() / CLOCKS_PER_SEC; }

// The interface in contact order (point c, its nodes, their x, y, z DOFs) and the interior.
PetscErrorCode PartitionDofs(const Model &full, cb::Partition &p)
{
  MPI_Comm comm = full.comm();
  PetscInt rstart, rend;
  PetscFunctionBeginUser;
  PetscCall(MatGetSize(full.K, &p.N, nullptr));
  PetscCall(MatGetOwnershipRange(full.K, &rstart, &rend));
  PetscCheck(!full.contacts.HasExplicitColumns(), comm, kErrInput,
             "reduction: the contact set has explicit column entries (an already reduced model?); Craig-Bampton needs "
             "node-based contact points, reduce the full model instead");
  std::vector<PetscInt> iface;
  for (const ContactPoint &c : full.contacts.points)
    for (const ContactNode &nd : c.nodes)
      for (int k = 0; k < 3; ++k) iface.push_back(nd.dofs[k]);
  p.nB = (PetscInt)iface.size();
  p.where.assign(p.N, -1);
  for (PetscInt k = 0; k < p.nB; ++k) {
    PetscCheck(iface[k] >= 0 && iface[k] < p.N, comm, kErrInput,
               "reduction: contact DOF %" PetscInt_FMT " is outside the model's %" PetscInt_FMT " DOFs", iface[k], p.N);
    PetscCheck(p.where[iface[k]] < 0, comm, kErrInput,
               "reduction: DOF %" PetscInt_FMT " belongs to two contact nodes; the interface must list each DOF once", iface[k]);
    p.where[iface[k]] = k;
  }
  p.nI = p.N - p.nB;
  PetscCheck(p.nI > 0, comm, kErrInput, "reduction: every DOF is a contact DOF, nothing to reduce (drop -reduce_type)");
  std::vector<PetscInt> Iloc, Bloc;
  p.Bsorted = iface;
  std::sort(p.Bsorted.begin(), p.Bsorted.end());
  for (PetscInt i = rstart; i < rend; ++i) (p.where[i] < 0 ? Iloc : Bloc).push_back(i);
  PetscCall(ISCreateGeneral(comm, (PetscInt)Iloc.size(), Iloc.data(), PETSC_COPY_VALUES, p.isI.out()));
  PetscCall(ISCreateGeneral(comm, (PetscInt)Bloc.size(), Bloc.data(), PETSC_COPY_VALUES, p.isB.out()));
  PetscFunctionReturn(0);
}

// W = [Psi Phi] (Psi's first nB columns left for the constraint modes), Phi M_II-normalised, and
// the orders the projection needs.
PetscErrorCode CreateBasis(MPI_Comm comm, const cb::Partition &p, const cb::Interior &in, const std::vector<PetscReal> &lam,
                           const std::vector<PetscInt> &keep, cb::Basis &b)
{
  PetscInt nIloc;
  VecH     x, y;
  PetscFunctionBeginUser;
  b.nB = p.nB, b.m = (PetscInt)keep.size(), b.n2 = b.nB + b.m;
  b.omega2.clear();
  for (PetscInt k : keep) b.omega2.push_back(lam[k]);
  b.perm.resize(b.n2);
  for (PetscInt k = 0; k < b.nB; ++k) b.perm[k] = p.where[p.Bsorted[k]];
  for (PetscInt k = 0; k < b.m; ++k) b.perm[b.nB + k] = b.nB + k;
  PetscCall(MatGetLocalSize(in.Kii, &nIloc, nullptr));
  PetscCall(MatCreateDense(comm, nIloc, PETSC_DECIDE, p.nI, b.n2, nullptr, b.W.out()));
  PetscCall(MatCreateVecs(in.Kii, x.out(), y.out()));
  for (PetscInt k = 0; k < b.m; ++k) {
    Vec       col;
    PetscReal nrm2;
    if (in.modes) {
      Vec xk;
      PetscCall(MatDenseGetColumnVecRead(in.modes, keep[k], &xk));
      PetscCall(VecCopy(xk, x));
      PetscCall(MatDenseRestoreColumnVecRead(in.modes, keep[k], &xk));
    } else PetscCall(EPSGetEigenvector(in.slice ? in.slice : in.eps, keep[k], x, nullptr));
    PetscCall(MatMult(in.Mii, x, y));
    PetscCall(VecDot(x, y, &nrm2));
    // Sign fixed by the entry of largest modulus, so that any rank count gives the same basis.
    PetscReal xmax, xmin;
    PetscCall(VecMax(x, nullptr, &xmax));
    PetscCall(VecMin(x, nullptr, &xmin));
    PetscCall(VecScale(x, (-xmin > xmax ? -1.0 : 1.0) / std::sqrt(PetscRealPart(nrm2))));
    PetscCall(MatDenseGetColumnVecWrite(b.W, b.nB + k, &col));
    PetscCall(VecCopy(x, col));
    PetscCall(MatDenseRestoreColumnVecWrite(b.W, b.nB + k, &col));
  }
  PetscFunctionReturn(0);
}

// A_r = T^T A T in the order [B sorted by global index, modes]:
//   P = W^T A_II W,  S = A_BI W,  A_r = P + [A_BB + S_B + S_B^T, S_M; S_M^T, 0].
// For K the projection is known in closed form (Psi^T (K_IB + K_II Psi) = 0, Phi^T K_II Phi =
// Omega^2): K_r = [K_BB + K_BI Psi, 0; 0, Omega^2], which saves the dense product W^T K_II W.
// For M the blocks with a mode are too: Phi^T M_II Phi = I (the modes are M_II-normalised) and
// Psi^T M_II Phi = Psi^T K_II Phi Omega^-2 = -K_BI Phi Omega^-2 (K_II Phi = M_II Phi Omega^2), so
// only Psi^T M_II Psi is a dense product: (nB / n2)^2 of W^T M_II W's flops. Both closed forms are
// exact up to the eigensolver's residual, as K_r's already were. kbi_phi = K_BI Phi (nB x m),
// from K's projection. Any other matrix (a damping that is not Rayleigh) is projected whole.
enum class Projected { stiffness, mass, general };

PetscErrorCode ProjectMatrix(const cb::Partition &p, const cb::Basis &b, Mat A, Projected kind, Dense &Ar, Dense *kbi_phi)
{
  MatH           Aii, Aib;
  Dense          Sd, Abb;
  const PetscInt nB = b.nB, m = b.m;
  PetscFunctionBeginUser;
  PetscCall(MatCreateSubMatrix(A, p.isI, p.isB, MAT_INITIAL_MATRIX, Aib.out()));
  PetscCall(InterfaceTransposeProduct(Aib, b.W, Sd));
  PetscCall(GatherSubmatrix(A, p.Bsorted, Abb));
  if (kind == Projected::stiffness) {
    Ar                       = Dense::Zero(b.n2, b.n2);
    Ar.topLeftCorner(nB, nB) = Abb + 0.5 * (Sd.leftCols(nB) + Sd.leftCols(nB).transpose());
    for (PetscInt k = 0; k < m; ++k) Ar(nB + k, nB + k) = b.omega2[k];
    if (kbi_phi) *kbi_phi = Sd.rightCols(m);
    PetscFunctionReturn(0);
  }
  PetscCall(MatCreateSubMatrix(A, p.isI, p.isI, MAT_INITIAL_MATRIX, Aii.out()));
  if (kind == Projected::mass) {
    Dense Ppsi;
    PetscCheck(kbi_phi && kbi_phi->rows() == nB && kbi_phi->cols() == m, PETSC_COMM_SELF, PETSC_ERR_PLIB,
               "the mass projection needs K_BI Phi from the stiffness's");
    PetscCall(SymmetricProjection(Aii, b.W, nB, Ppsi));
    Ar                        = Dense::Zero(b.n2, b.n2);
    Ar.topLeftCorner(nB, nB)  = Ppsi + Abb + Sd.leftCols(nB) + Sd.leftCols(nB).transpose();
    Dense coupling            = Sd.rightCols(m);
    for (PetscInt k = 0; k < m; ++k) coupling.col(k) -= kbi_phi->col(k) / b.omega2[k];
    Ar.topRightCorner(nB, m)   = coupling;
    Ar.bottomLeftCorner(m, nB) = coupling.transpose();
    Ar.bottomRightCorner(m, m).setIdentity();
  } else {
    PetscCall(SymmetricProjection(Aii, b.W, b.n2, Ar));
    Ar.topLeftCorner(nB, nB) += Abb + Sd.leftCols(nB) + Sd.leftCols(nB).transpose();
    Ar.topRightCorner(nB, m) += Sd.rightCols(m);
    Ar.bottomLeftCorner(m, nB) += Sd.rightCols(m).transpose();
  }
  PetscFunctionReturn(0);
}

// A reduced matrix from the sorted order to contact order.
Dense Permuted(const cb::Basis &b, const Dense &Ar)
{
  Dense Ap(b.n2, b.n2);
  for (PetscInt i = 0; i < b.n2; ++i)
    for (PetscInt j = 0; j < b.n2; ++j) Ap(b.perm[i], b.perm[j]) = Ar(i, j);
  return Ap;
}

// The reduced matrix in contact order, through the interface reduction T if any (T empty: none).
PetscErrorCode AssembleReduced(MPI_Comm comm, const cb::Basis &b, const Dense &T, const Dense &Ar, Mat *out)
{
  PetscFunctionBeginUser;
  Dense Ap = Permuted(b, Ar);
  if (T.size()) {
    Dense AT;
    PetscCallCXX(AT.noalias() = Ap * T);
    PetscCallCXX(Ap.noalias() = T.transpose() * AT);
  }
  PetscCall(CreateReducedMat(comm, Ap, out));
  PetscFunctionReturn(0);
}

// F_r = T^T F = [F_B + Psi^T F_I; Phi^T F_I] (then through the interface reduction T, if any), with
// the layout of K_r.
PetscErrorCode ReducedLoad(const cb::Partition &p, const cb::Basis &b, const Dense &T, Vec F, Mat Kr, Vec *Fr_out)
{
  Vec                    FI;
  VecH                   t;
  std::vector<PetscReal> Ffull, tw, Fr(b.n2, 0.0);
  PetscInt               lo, hi;
  PetscFunctionBeginUser;
  PetscCall(VecGetSubVector(F, p.isI, &FI));
  PetscCall(MatCreateVecs(b.W, t.out(), nullptr));
  PetscCall(MatMultTranspose(b.W, FI, t));
  PetscCall(VecRestoreSubVector(F, p.isI, &FI));
  PetscCall(GatherVector(t, true, tw));
  PetscCall(GatherVector(F, true, Ffull));
  for (PetscInt k = 0; k < b.nB; ++k) Fr[b.perm[k]] = Ffull[p.Bsorted[k]] + tw[k];
  for (PetscInt k = 0; k < b.m; ++k) Fr[b.nB + k] = tw[b.nB + k];
  if (T.size()) {
    const Eigen::Map<const Eigen::Matrix<PetscReal, Eigen::Dynamic, 1>> f(Fr.data(), b.n2);
    const Eigen::Matrix<PetscReal, Eigen::Dynamic, 1>                   g = T.transpose() * f;
    Fr.assign(g.data(), g.data() + g.size());
  }
  PetscCall(MatCreateVecs(Kr, nullptr, Fr_out));
  PetscCall(VecGetOwnershipRange(*Fr_out, &lo, &hi));
  for (PetscInt i = lo; i < hi; ++i) PetscCall(VecSetValue(*Fr_out, i, Fr[i], INSERT_VALUES));
  PetscCall(VecAssemblyBegin(*Fr_out));
  PetscCall(VecAssemblyEnd(*Fr_out));
  PetscFunctionReturn(0);
}

// The contact set follows its DOFs to the first 3 n_c positions; frames and speeds unchanged.
PetscErrorCode RenumberContacts(MPI_Comm comm, const cb::Partition &p, ContactSet &contacts)
{
  PetscInt next = 0;
  PetscFunctionBeginUser;
  for (ContactPoint &c : contacts.points)
    for (ContactNode &nd : c.nodes)
      for (int k = 0; k < 3; ++k) {
        PetscCheck(p.where[nd.dofs[k]] == next, comm, PETSC_ERR_PLIB, "reduction: contact DOF %" PetscInt_FMT " missing from the basis",
                   nd.dofs[k]);
        nd.dofs[k] = next++;
      }
  PetscFunctionReturn(0);
}

// E = P [I 0; Psi Phi] T on rank 0 (Model::expansion): the interface rows are unit rows of the CB
// coordinates in contact order, the interior rows those of W with its columns put in contact
// order, all through the interface reduction T if any. The other ranks send their rows of W one
// rank at a time, so rank 0 holds E, its own rows of W and one other rank's rows at most.
PetscErrorCode BuildExpansion(MPI_Comm comm, const cb::Partition &p, const cb::Basis &b, const Dense &T, Expansion &x)
{
  PetscMPIInt        rank, size;
  PetscInt           nloc, nis, lda;
  const PetscScalar *a;
  const PetscInt    *idx;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCall(MatGetLocalSize(b.W, &nloc, nullptr));
  PetscCall(ISGetLocalSize(p.isI, &nis));
  PetscCheck(nis == nloc, PETSC_COMM_SELF, PETSC_ERR_PLIB, "expansion: %" PetscInt_FMT " interior rows of W against %" PetscInt_FMT " indices", nloc, nis);
  x.full_size = p.N;
  x.n         = T.size() ? (PetscInt)T.cols() : b.n2;
  x.E.clear();
  // Rank 0 fills E (N x n, column-major). Without interface reduction E is the CB basis itself:
  // unit rows on the interface, W's rows (columns in contact order) inside. With it, E = E_cb T row
  // by row: interface row d is T's row where[d], an interior row is W's row times Tp (T's rows in
  // W's column order), a block of rows at a time, so the N x n2 CB expansion (4 GB for the
  // 126 861-DOF brake) is never held beside W.
  Dense Tp;
  if (rank == 0) {
    PetscCallCXX(x.E.assign((size_t)p.N * x.n, 0.0));
    if (T.size()) {
      Tp.resize(b.n2, x.n);
      for (PetscInt j = 0; j < b.n2; ++j) Tp.row(j) = T.row(b.perm[j]);
      for (PetscInt d = 0; d < p.N; ++d)
        if (p.where[d] >= 0)
          for (PetscInt j = 0; j < x.n; ++j) x.E[(size_t)j * p.N + d] = T(p.where[d], j);
    } else
      for (PetscInt d = 0; d < p.N; ++d)
        if (p.where[d] >= 0) x.E[(size_t)p.where[d] * p.N + d] = 1;
  }
  auto place = [&](const PetscInt *rows, PetscInt nr, const PetscScalar *blk, PetscInt ld) {
    if (!T.size()) {
      for (PetscInt j = 0; j < b.n2; ++j) {
        PetscReal *col = x.E.data() + (size_t)b.perm[j] * p.N;
        for (PetscInt i = 0; i < nr; ++i) col[rows[i]] = blk[(size_t)j * ld + i];
      }
      return;
    }
    const PetscInt chunk = 4096;
    Dense          Eb;
    for (PetscInt i0 = 0; i0 < nr; i0 += chunk) {
      const PetscInt m = std::min(chunk, nr - i0);
      Eigen::Map<const Dense, 0, Eigen::OuterStride<>> Wb(blk + i0, m, b.n2, Eigen::OuterStride<>(ld));
      Eb.noalias() = Wb * Tp;
      for (PetscInt j = 0; j < x.n; ++j) {
        PetscReal *col = x.E.data() + (size_t)j * p.N;
        for (PetscInt i = 0; i < m; ++i) col[rows[i0 + i]] = Eb(i, j);
      }
    }
  };
  PetscCall(MatDenseGetArrayRead(b.W, &a));
  PetscCall(MatDenseGetLDA(b.W, &lda));
  PetscCall(ISGetIndices(p.isI, &idx));
  if (rank == 0) place(idx, nloc, a, lda);
  for (PetscMPIInt r = 1; r < size; ++r) {
    if (rank == r) {
      std::vector<PetscScalar> blk((size_t)nloc * b.n2);
      for (PetscInt j = 0; j < b.n2; ++j) std::copy(a + (size_t)j * lda, a + (size_t)j * lda + nloc, blk.begin() + (size_t)j * nloc);
      PetscMPIInt cnt;
      PetscCall(PetscMPIIntCast((PetscInt)blk.size(), &cnt));
      PetscCallMPI(MPI_Send(&nloc, 1, MPIU_INT, 0, 0, comm));
      PetscCallMPI(MPI_Send(idx, (PetscMPIInt)nloc, MPIU_INT, 0, 1, comm));
      PetscCallMPI(MPI_Send(blk.data(), cnt, MPIU_SCALAR, 0, 2, comm));
    } else if (rank == 0) {
      PetscInt nr;
      PetscCallMPI(MPI_Recv(&nr, 1, MPIU_INT, r, 0, comm, MPI_STATUS_IGNORE));
      std::vector<PetscInt>    rows(nr);
      std::vector<PetscScalar> blk((size_t)nr * b.n2);
      PetscMPIInt              cnt;
      PetscCall(PetscMPIIntCast((PetscInt)blk.size(), &cnt));
      PetscCallMPI(MPI_Recv(rows.data(), (PetscMPIInt)nr, MPIU_INT, r, 1, comm, MPI_STATUS_IGNORE));
      PetscCallMPI(MPI_Recv(blk.data(), cnt, MPIU_SCALAR, r, 2, comm, MPI_STATUS_IGNORE));
      place(rows.data(), nr, blk.data(), nr);
    }
  }
  PetscCall(ISRestoreIndices(p.isI, &idx));
  PetscCall(MatDenseRestoreArrayRead(b.W, &a));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode CraigBampton::SetFromOptions(bool *enabled)
{
  const char *const types[] = {"none", "craig_bampton"};
  PetscInt          type    = 0;
  OptionChecks      checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, prefix_.c_str(), "Craig-Bampton model reduction", "CraigBampton");
  // A switch whose default the code decides: out becomes 1 or 0 when the option is given, else stays.
  auto tristate = [&](const char *name, const char *help, PetscInt &out) -> PetscErrorCode {
    PetscBool v = PETSC_FALSE, set = PETSC_FALSE;
    PetscFunctionBeginUser;
    PetscCall(PetscOptionsBool(name, help, "CraigBampton", out > 0 ? PETSC_TRUE : PETSC_FALSE, &v, &set));
    if (set) out = (PetscInt)v;
    PetscFunctionReturn(0);
  };
  PetscCall(PetscOptionsEList("-type", "Model reduction: none or craig_bampton (contact DOFs + fixed-interface modes)",
                              "CraigBampton", types, 2, types[type], &type, nullptr));
  SquealOptionsReal("-fmax", "Cut-off frequency of the fixed-interface modes (Hz); 0: use -reduce_nmodes only; default: -reduce_fmax_factor x the band", "CraigBampton",
                    &fmax_, Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-nmodes", "Number of fixed-interface modes (-1: all below -reduce_fmax)", "CraigBampton", nmodes_,
                            &nmodes_, nullptr));
  SquealOptionsReal("-fband", "Top of the frequency band of interest (Hz); a cut-off below it is refused (default: -stab_fmax)",
                    "CraigBampton", &fband_, Range::NonNegative(), checks);
  SquealOptionsReal("-fmax_factor",
                    "Without -reduce_fmax and -reduce_nmodes: the cut-off is this many times the band's top (-reduce_fband, "
                    "else -stab_fmax)",
                    "CraigBampton", &fmax_factor_, Range::Closed(1.0, kInf), checks);
  PetscCall(PetscOptionsInt("-max_modes", "Upper bound on the fixed-interface modes kept for -reduce_fmax", "CraigBampton", max_modes_,
                            &max_modes_, nullptr));
  PetscCall(PetscOptionsBool("-sparse_rhs", "Constraint modes from the sparse right-hand sides -K_IB (MUMPS ICNTL(20) = 1) instead of a dense block",
                             "CraigBampton", sparse_rhs_, &sparse_rhs_, nullptr));
  PetscCall(PetscOptionsInt("-rhs_block",
                            "Constraint modes solved in blocks of this many right-hand sides, a signal obeyed between blocks "
                            "(0: all in one solve)",
                            "CraigBampton", rhs_block_, &rhs_block_, nullptr));
  PetscCall(tristate("-slice",
                     "Fixed-interface modes by spectrum slicing of [0, (2 pi fmax)^2] (SLEPc Krylov-Schur, one part of the "
                     "interval per rank, its options under -reduce_slice_); default: where its factorisations cost less "
                     "than orthogonalising against every mode at one shift",
                     slice_));
  PetscCall(PetscOptionsBool("-slice_balance",
                             "Spectrum slicing on several ranks: the parts' boundaries where each holds as many modes (inertia "
                             "counts seek the median, at most 3 factorisations), not at equal widths of the interval",
                             "CraigBampton", slice_balance_, &slice_balance_, nullptr));
  PetscCall(PetscOptionsInt("-lanczos_block",
                            "Fixed-interface modes by block shift-and-invert Lanczos with this many columns a block (modes counted by "
                            "-reduce_count_modes; on several ranks with -reduce_redundant, the slices dealt out); 0: SLEPc's "
                            "Krylov-Schur (-reduce_eps_*) or spectrum slicing (-reduce_slice)",
                            "CraigBampton", lanczos_block_, &lanczos_block_, nullptr));
  PetscCall(PetscOptionsInt("-lanczos_slice_modes", "Block Lanczos: the modes' interval is cut into slices of about this many modes, each at its own shift",
                            "CraigBampton", lanczos_slice_modes_, &lanczos_slice_modes_, nullptr));
  PetscCall(PetscOptionsBool("-lanczos_monitor", "Block Lanczos: print each slice's interval, shift, columns and residual", "CraigBampton",
                             lanczos_monitor_, &lanczos_monitor_, nullptr));
  SquealOptionsReal("-lanczos_tol", "Block Lanczos: the modes' relative residual estimates ||K^-1 M x - x / lambda|| lambda", "CraigBampton",
                    &lanczos_tol_, Range::Positive(), checks);
  SquealOptionsReal("-lanczos_max_mb", "Largest block Lanczos basis (MB, 16 n_I bytes a column: V and M V); beyond it the modes go to SLEPc",
                    "CraigBampton", &lanczos_max_mb_, Range::Positive(), checks);
  PetscCall(PetscOptionsBool("-count_modes", "Count the modes below -reduce_fmax by the inertia of K_II - (2 pi fmax)^2 M_II (one more factorisation) and solve once",
                             "CraigBampton", count_modes_, &count_modes_, nullptr));
  PetscCall(PetscOptionsBool("-rayleigh", "Project Rayleigh damping C = a M + b K (detected to round-off) as a M_r + b K_r",
                             "CraigBampton", rayleigh_, &rayleigh_, nullptr));
  PetscCall(PetscOptionsBool("-redundant", "On several ranks, every rank factorises the whole K_II and solves its share of the constraint modes alone (false: one distributed MUMPS factorisation and solve)",
                             "CraigBampton", redundant_, &redundant_, nullptr));
  PetscCall(PetscOptionsInt("-interface_modes",
                            "Interface reduction: keep this many characteristic constraint modes of the contact interface "
                            "(one normal coordinate per point stays physical; -1: no interface reduction, or all below -reduce_interface_fmax)",
                            "CraigBampton", iface_modes_, &iface_modes_, nullptr));
  expand_opt_ = -1;
  PetscCall(tristate("-expand",
                     "Keep the expansion of reduced vectors to the full model (dense, N x n on rank 0) and write the "
                     "unstable modes, the cycle and the transient's last records on the full mesh (/expanded); "
                     "default: on for a model with a mesh (-model_type calculix)",
                     expand_opt_));
  PetscCall(PetscOptionsInt("-expand_records", "With -reduce_expand: how many of the transient's last records are expanded (0: none)",
                            "CraigBampton", expand_records_, &expand_records_, nullptr));
  SquealOptionsReal("-expand_max_mb",
                    "Without -reduce_expand: keep the expansion only while E (8 N n bytes on rank 0) is at most this many MB "
                    "(beside the reduction's own N x n basis at its peak)",
                    "CraigBampton", &expand_max_mb_, Range::NonNegative(), checks);
  PetscCall(tristate("-interface_statics",
                     "Interface reduction: add the interface's static response to each contact normal (n_c more DOFs), so "
                     "that an opening point takes a condensed shape; default: for two-body points (pad against disc) only",
                     iface_statics_));
  SquealOptionsReal("-interface_fmax", "Interface reduction: keep the interface's characteristic constraint modes below this frequency (Hz); 0: by count only",
                    "CraigBampton", &iface_fmax_, Range::NonNegative(), checks);
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(lanczos_slice_modes_ >= 1, comm_, kErrInput, "option -%slanczos_slice_modes = %" PetscInt_FMT ": expected >= 1", prefix_.c_str(),
             lanczos_slice_modes_);
  PetscCheck(lanczos_block_ >= 0, comm_, kErrInput, "option -%slanczos_block = %" PetscInt_FMT ": expected >= 0 (0: SLEPc)", prefix_.c_str(),
             lanczos_block_);
  const std::string pre = OptionName(prefix_.c_str(), "");
  if (type == 1) {
    if (fmax_ <= 0 && nmodes_ < 0) {
      // The user gave the band, not the cut-off. Fixed-interface modes up to 6 x the band put
      // the unstable eigenvalues of both gmsh + CalculiX brakes within 1e-3 of the full model's
      // (8.4e-4 and 5.7e-4 in a 15 kHz band; 4 x: 1.5e-3; docs/fe-workflow.md).
      PetscReal band = fband_;
      if (band <= 0) {
        PetscBool set = PETSC_FALSE;
        band          = kDefaultBandHz;
        PetscCall(PetscOptionsGetReal(nullptr, nullptr, "-stab_fmax", &band, &set));
      }
      PetscCheck(band > 0, comm_, kErrInput,
                 "%stype craig_bampton needs a cut-off: give %sfmax (Hz) or %snmodes (with -stab_fmax 0 there is no band to "
                 "take it from)",
                 pre.c_str(), pre.c_str(), pre.c_str());
      fmax_ = fmax_factor_ * band;
      // Said when the reduction runs (this may be a dry run of the options).
      char line[256];
      std::snprintf(line, sizeof line, "reduction: cut-off %g Hz = %g x the band's top, %g Hz (%s); %sfmax sets it\n", (double)fmax_,
                    (double)fmax_factor_, (double)band, fband_ > 0 ? (pre + "fband").c_str() : "-stab_fmax", pre.c_str());
      fmax_note_ = line;
    }
    PetscCheck(fband_ <= 0 || fmax_ <= 0 || fmax_ >= fband_, comm_, kErrInput,
               "cut-off %sfmax = %g Hz is below the band of interest (%sfband = %g Hz): raise %sfmax to %.0f Hz "
               "(%.1f x the band, what it is when not given)",
               pre.c_str(), (double)fmax_, pre.c_str(), (double)fband_, pre.c_str(), (double)(fmax_factor_ * fband_), (double)fmax_factor_);
    PetscCheck(expand_records_ >= 0, comm_, kErrInput, "option %sexpand_records = %" PetscInt_FMT ": expected >= 0", pre.c_str(), expand_records_);
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

namespace {

// A signal is obeyed at the fixed-interface eigensolver's next monitor call.
PetscErrorCode PollInterrupt(EPS eps)
{
  PetscFunctionBeginUser;
  PetscCall(EPSMonitorSet(
    eps,
    [](EPS e, PetscInt, PetscInt, PetscScalar *, PetscScalar *, PetscReal *, PetscInt, void *) -> PetscErrorCode {
      return InterruptPoint(PetscObjectComm((PetscObject)e), "the Craig-Bampton fixed-interface modes");
    },
    nullptr, nullptr));
  PetscFunctionReturn(0);
}

// The converged eigenvalues (real: a symmetric pencil), in the solver's order.
PetscErrorCode Eigenvalues(EPS eps, std::vector<PetscReal> &lam)
{
  PetscInt nconv = 0;
  PetscFunctionBeginUser;
  PetscCall(EPSGetConverged(eps, &nconv));
  lam.resize(nconv);
  for (PetscInt i = 0; i < nconv; ++i) {
    PetscScalar kr, ki;
    PetscCall(EPSGetEigenvalue(eps, i, &kr, &ki));
    lam[i] = PetscRealPart(kr);
  }
  PetscFunctionReturn(0);
}

} // namespace

// The interior blocks, the eigensolver and the one MUMPS Cholesky factorisation of K_II that it
// shares with the constraint modes: the shift-and-invert shift is 0, so the spectral
// transformation's operator is K_II itself and its KSP, set up here, is not factorised again
// inside EPSSolve.
PetscErrorCode CraigBampton::FactorInterior(const Model &full, const cb::Partition &p, cb::Interior &in)
{
  MPI_Comm    comm = full.comm();
  PetscMPIInt size;
  ST          st;
  KSP         ksp;
  PC          pc, fpc = nullptr; // fpc: the PC that holds the factor (pc itself, or the redundant PC's inner one)
  PetscBool   isfactor, isredundant;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCall(MatCreateSubMatrix(full.K, p.isI, p.isI, MAT_INITIAL_MATRIX, in.Kii.out()));
  PetscCall(MatCreateSubMatrix(full.K, p.isI, p.isB, MAT_INITIAL_MATRIX, in.Kib.out()));
  PetscCall(MatCreateSubMatrix(full.M, p.isI, p.isI, MAT_INITIAL_MATRIX, in.Mii.out()));
  PetscCall(EPSCreate(comm, in.eps.out()));
  PetscCall(EPSSetOptionsPrefix(in.eps, prefix_.c_str()));
  PetscCall(EPSSetOperators(in.eps, in.Kii, in.Mii));
  PetscCall(EPSSetProblemType(in.eps, EPS_GHEP));
  PetscCall(EPSSetType(in.eps, EPSKRYLOVSCHUR));
  PetscCall(EPSSetTarget(in.eps, 0.0));
  PetscCall(EPSSetWhichEigenpairs(in.eps, EPS_TARGET_MAGNITUDE));
  PetscCall(EPSSetTolerances(in.eps, 1e-10, PETSC_DEFAULT));
  // No purification: it guards against a singular B, and M_II is a principal block of the model's
  // M, checked positive definite. It would cost one more solve per mode (81 of 348 on the 31119-DOF
  // pad, 2.3 s) to move the eigenvalues by 4e-9 relative. -<prefix>eps_purify 1 restores it.
  PetscCall(EPSSetPurify(in.eps, PETSC_FALSE));
  PetscCall(EPSGetST(in.eps, &st));
  PetscCall(STSetType(st, STSINVERT));
  PetscCall(STGetKSP(st, &ksp));
  PetscCall(KSPSetType(ksp, KSPPREONLY));
  PetscCall(KSPGetPC(ksp, &pc));
  if (size > 1 && redundant_) { // the final choice follows -<prefix>st_pc_type
    PetscCall(PCSetType(pc, PCREDUNDANT));
    PetscCall(PCRedundantSetNumber(pc, size));
  } else {
    PetscCall(PCSetType(pc, PCCHOLESKY));
    PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  }
  in.nev = nmodes_ > 0 ? nmodes_ : 24;
  in.nev = PetscMax(1, PetscMin(in.nev, PetscMin(max_modes_, p.nI)));
  PetscCall(EPSSetDimensions(in.eps, in.nev, PETSC_DEFAULT, PETSC_DEFAULT));
  PetscCall(EPSSetFromOptions(in.eps));
  {
    PetscInt nev, ncv, mpd;
    PetscCall(EPSGetDimensions(in.eps, &nev, &ncv, &mpd));
    if (ncv > 0) in.ncv = ncv;
    if (mpd > 0) in.mpd = mpd;
  }
  PetscCall(PollInterrupt(in.eps));
  PetscCall(KSPSetOperators(ksp, in.Kii, in.Kii));
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
    MPI_Comm    fcomm;
    PetscMPIInt fsize;
    PetscCall(PetscObjectGetComm((PetscObject)fpc, &fcomm));
    PetscCallMPI(MPI_Comm_size(fcomm, &fsize));
    PetscCheck(fsize == 1, comm, kErrInput,
               "reduction: -%sst_pc_redundant_number must be the number of ranks (%d): each rank solves its constraint modes alone",
               prefix_.c_str(), (int)size);
  }
  in.redundant = isredundant;
  PetscCall(PCFactorGetMatrix(fpc, &in.Fct));
  MatFactorError ferr;
  PetscCall(MatFactorGetError(in.Fct, &ferr));
  PetscCheck(ferr == MAT_FACTOR_NOERROR, comm, kErrInput,
             "reduction: K_II (stiffness with every contact DOF held) cannot be factorised (MUMPS error %d): part of the "
             "structure is not held by the contact nodes or supports; add supports (e.g. -model_support_kn/-model_support_kt) "
             "or contact nodes there",
             (int)ferr);
  PetscFunctionReturn(0);
}

// The lambda below which t modes lie, from counts (lambda, n) sorted by lambda: interpolated in
// log-log between the counts around t, or a power law below the lowest (the exponent of the two
// lowest counts; a solid's Weyl law, N ~ lambda^1.5, from one count).
static PetscReal LambdaAtCount(const std::vector<std::pair<PetscReal, PetscInt>> &counts, PetscReal t)
{
  const auto &lo = counts.front();
  if (t <= lo.second) {
    PetscReal p = 1.5;
    if (counts.size() > 1 && counts[1].second > lo.second)
      p = std::log((PetscReal)counts[1].second / lo.second) / std::log(counts[1].first / lo.first);
    p = PetscMax(0.25, PetscMin(4.0, p));
    return lo.first * std::pow(t / lo.second, 1.0 / p);
  }
  for (size_t i = 0; i + 1 < counts.size(); ++i) {
    const auto &a = counts[i], &b = counts[i + 1];
    if (t > b.second) continue;
    if (b.second == a.second) return a.first;
    const PetscReal x = std::log(t / a.second) / std::log((PetscReal)b.second / a.second);
    return a.first * std::pow(b.first / a.first, x);
  }
  return counts.back().first;
}

// Parts of the sliced interval: one per rank, so that each part's factorisations are sequential.
static PetscInt SliceParts(MPI_Comm comm)
{
  PetscMPIInt size = 1;
  MPI_Comm_size(comm, &size);
  return (PetscInt)size;
}

// The modes of (K_II, M_II) in [0, w2max] by spectrum slicing. One Krylov-Schur run at a
// single shift with hundreds of modes spends its time orthogonalising against them (802 modes of the
// size-1 brake: 31 of 47 s); slicing moves the shift along the interval (a factorisation each) and
// splits the interval over the ranks, each part on one rank with its own whole copy of the matrices.
// On several parts (-reduce_slice_balance) the parts' boundaries are put where each holds as many of
// the nev modes, found by inertia counts (else SLEPc's equal widths).
PetscErrorCode CraigBampton::SliceModes(MPI_Comm comm, cb::Interior &in, PetscReal w2max, PetscInt nev, const ModeCount &count,
                                        std::vector<PetscReal> &lam)
{
  ST          st;
  KSP         ksp;
  PC          pc;
  PetscFunctionBeginUser;
  PetscCall(EPSCreate(comm, in.slice.out()));
  PetscCall(EPSSetOptionsPrefix(in.slice, (prefix_ + "slice_").c_str()));
  PetscCall(EPSSetOperators(in.slice, in.Kii, in.Mii));
  PetscCall(EPSSetProblemType(in.slice, EPS_GHEP));
  PetscCall(EPSSetType(in.slice, EPSKRYLOVSCHUR));
  // From 0: K_II is positive definite (held by the contact DOFs and supports, checked by its
  // factorisation), so no mode is lost below the interval.
  PetscCall(EPSSetInterval(in.slice, 0.0, w2max));
  PetscCall(EPSSetWhichEigenpairs(in.slice, EPS_ALL));
  PetscCall(EPSSetTolerances(in.slice, 1e-10, PETSC_DEFAULT));
  PetscCall(EPSSetPurify(in.slice, PETSC_FALSE)); // as the one shift's solve (FixedInterfaceModes)
  // Modes a shift: more shifts cost more factorisations, more modes a shift more orthogonalisation
  // against the shift's basis, and a factorisation grows faster with n_I than a vector. SLEPc's 40
  // is best for neither brake; 60 (n_I / 16764)^0.2, fitted to both (fixed-interface modes):
  //   size 1 (n_I = 16 764, 802 modes, 1 rank): 20: 29.8 s, 40: 24.0-25.2, 60: 21.7, 80: 22.3, 120: 25.0;
  //   size 2 (n_I = 122 955, 933 modes, 2 ranks): 40: 256.1 s, 60: 235.2, 90: 214.7, 130: 241.4.
  // SLEPc 3.18 goes back to its 40 when only -reduce_slice_eps_krylovschur_ncv or _mpd is given:
  // give _nev with them.
  PetscInt nI;
  PetscCall(MatGetSize(in.Kii, &nI, nullptr));
  info_.slice_per_shift = (PetscInt)std::lround(PetscMax(40.0, PetscMin(120.0, 60.0 * std::pow((PetscReal)nI / 16764.0, 0.2))));
  if (nI >= 4 * info_.slice_per_shift) PetscCall(EPSKrylovSchurSetDimensions(in.slice, info_.slice_per_shift, PETSC_DEFAULT, PETSC_DEFAULT));
  // One rank per part: each part's factorisations are sequential MUMPS ones, whose inertia is exact.
  PetscCall(EPSKrylovSchurSetPartitions(in.slice, SliceParts(comm)));
  PetscCall(EPSGetST(in.slice, &st));
  PetscCall(STSetType(st, STSINVERT));
  PetscCall(STGetKSP(st, &ksp));
  PetscCall(KSPSetType(ksp, KSPPREONLY));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCSetType(pc, PCCHOLESKY));
  PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  // The parts' eigensolvers are made inside EPSSetUp and read their KSP from the options (SLEPc
  // 3.18 does not copy the solver type set above): the same choice, as defaults the user can override.
  // A part on several ranks (-reduce_slice_eps_krylovschur_partitions) factorises with distributed
  // MUMPS, whose inertia needs ICNTL(13) = 1; ICNTL(14) as for the count below.
  const std::pair<const char *, const char *> defaults[] = {{"slice_st_pc_type", "cholesky"},
                                                           {"slice_st_pc_factor_mat_solver_type", "mumps"},
                                                           {"slice_st_mat_mumps_icntl_13", "1"},
                                                           {"slice_st_mat_mumps_icntl_14", "100"}};
  for (const auto &d : defaults) {
    const std::string name = OptionName(prefix_.c_str(), d.first);
    PetscBool         has  = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, nullptr, name.c_str(), &has));
    if (!has) PetscCall(PetscOptionsSetValue(nullptr, name.c_str(), d.second));
  }
  PetscCall(EPSSetFromOptions(in.slice));
  PetscCall(EPSKrylovSchurGetDimensions(in.slice, &info_.slice_per_shift, nullptr, nullptr));
  PetscInt  npart = 1;
  PetscReal inta, intb;
  PetscCall(EPSKrylovSchurGetPartitions(in.slice, &npart));
  PetscCall(EPSGetInterval(in.slice, &inta, &intb));
  std::vector<std::pair<PetscReal, PetscInt>> counts{{w2max, nev}}; // (lambda, modes below it), sorted
  if (npart > 1 && slice_balance_ && inta == 0.0 && intb == w2max) {
    // Equal widths of [0, w2max] hold unequal counts (the size-2 brake's two parts 764 and 1146
    // solves; the unit tests' small pad at 150 kHz 164 and 77 modes): the median is sought by counts
    // (a factorisation each, at most 3, within 5 % of it), the other boundaries interpolated
    // between them. Every rank takes the same steps: the counts are the same on all.
    const PetscReal half = 0.5 * (PetscReal)nev;
    for (int tries = 0; tries < 3; ++tries) {
      const PetscReal w2c = LambdaAtCount(counts, half);
      PetscInt        nc  = 0;
      bool            okc = false;
      PetscCall(count(w2c, &nc, &okc));
      if (!okc || nc <= 0 || nc >= nev) break;
      counts.insert(std::upper_bound(counts.begin(), counts.end(), std::make_pair(w2c, nc)), std::make_pair(w2c, nc));
      if (std::abs((PetscReal)nc - half) <= 0.05 * (PetscReal)nev) break;
    }
  }
  if (counts.size() > 1) {
    std::vector<PetscReal> sub(npart + 1);
    sub[0] = 0.0, sub[npart] = w2max;
    for (PetscInt k = 1; k < npart; ++k)
      sub[k] = PetscMin(w2max, PetscMax(sub[k - 1], LambdaAtCount(counts, (PetscReal)nev * k / npart)));
    PetscCall(EPSKrylovSchurSetSubintervals(in.slice, sub.data()));
  }
  PetscCall(PollInterrupt(in.slice));
  PetscCall(EPSSolve(in.slice));
  info_.slice_parts = npart;
  PetscCall(Eigenvalues(in.slice, lam));
  info_.slice_counts.assign(1, (PetscInt)lam.size());
  if (npart > 1) { // (SLEPc 3.18 keeps no boundaries for one part)
    PetscReal *sub = nullptr;
    PetscCall(EPSKrylovSchurGetSubintervals(in.slice, &sub));
    info_.slice_counts.assign(npart, 0);
    for (PetscReal l : lam)
      for (PetscInt k = 0; k < npart; ++k)
        if (l < sub[k + 1] || k == npart - 1) {
          ++info_.slice_counts[k];
          break;
        }
    PetscCall(PetscFree(sub));
  }
  PetscFunctionReturn(0);
}

// F = the MUMPS Cholesky (LDL^T) factor of A = K - w2 M, for an inertia count (inertia: the root
// node without ScaLAPACK, so that its pivots count too) or a shift-and-invert solve; *ferr its error.
static PetscErrorCode FactorShifted(Mat K, Mat M, PetscReal w2, bool inertia, MatH &A, MatH &F, MatFactorError *ferr)
{
  MatFactorInfo finfo;
  PetscFunctionBeginUser;
  PetscCall(MatDuplicate(K, MAT_COPY_VALUES, A.out()));
  PetscCall(MatAXPY(A, -w2, M, UNKNOWN_NONZERO_PATTERN));
  PetscCall(MatSetOption(A, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatFactorInfoInitialize(&finfo));
  PetscCall(MatGetFactor(A, MATSOLVERMUMPS, MAT_FACTOR_CHOLESKY, F.out()));
  if (inertia) PetscCall(MatMumpsSetIcntl(F, 13, 1));
  // An indefinite matrix delays pivots beyond the analysis' estimate (MUMPS's default 20 % more
  // workspace): room for them, or the factorisation fails (a count lost, a slice left to SLEPc).
  PetscCall(MatMumpsSetIcntl(F, 14, 100));
  PetscCall(MatCholeskyFactorSymbolic(F, A, nullptr, &finfo));
  PetscCall(MatCholeskyFactorNumeric(F, A, &finfo));
  PetscCall(MatFactorGetError(F, ferr));
  PetscFunctionReturn(0);
}

// Fixed-interface modes of (K_II, M_II) up to the cut-off: lam holds every converged eigenvalue,
// keep the ones kept (ascending).
PetscErrorCode CraigBampton::FixedInterfaceModes(MPI_Comm comm, const cb::Partition &p, cb::Interior &in,
                                                 std::vector<PetscReal> &lam, std::vector<PetscInt> &keep)
{
  const PetscReal w2max = fmax_ > 0 ? std::pow(2 * PETSC_PI * fmax_, 2) : kInf;
  const PetscInt  nI    = p.nI;
  PetscInt        nconv = 0, nev = in.nev;
  PetscFunctionBeginUser;
  lam.clear();
  // With a cut-off alone, the count of modes below it is the number of negative pivots of
  // K_II - (2 pi fmax)^2 M_II (Sylvester's inertia; one more factorisation): one solve then asks
  // for exactly those, instead of solving again and again with a growing request.
  bool           counted      = false;
  PetscLogDouble t_count      = 0; // s, the counting factorisation: the price of a slicing shift
  // The number of eigenvalues of (K_II, M_II) below w2: the negative pivots of K_II - w2 M_II
  // (ok false if the factorisation failed: a mode at w2 itself, or out of memory); t its time.
  auto count = [&](PetscReal w2, PetscInt *nneg, bool *ok, PetscLogDouble *t) -> PetscErrorCode {
    MatH           A, F;
    MatFactorError ferr;
    PetscLogDouble t1;
    PetscFunctionBeginUser;
    *nneg = 0, *ok = false;
    PetscCall(PetscTime(t));
    PetscCall(FactorShifted(in.Kii, in.Mii, w2, true, A, F, &ferr));
    PetscCall(PetscTime(&t1));
    *t = t1 - *t;
    // The slicing decision below is collective: every rank takes it from the same time.
    PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, t, 1, MPI_DOUBLE, MPI_MAX, comm));
    if (ferr == MAT_FACTOR_NOERROR) {
      PetscCall(MatGetInertia(F, nneg, nullptr, nullptr));
      *ok = true;
    } else {
      PetscInt infog1 = 0, infog2 = 0;
      PetscCall(MatMumpsGetInfog(F, 1, &infog1));
      PetscCall(MatMumpsGetInfog(F, 2, &infog2));
      PetscCall(PetscPrintf(comm,
                            "reduction: note: the count of the modes below %g Hz failed (factorisation of K_II - (2 pi f)^2 "
                            "M_II: MUMPS INFOG(1) = %" PetscInt_FMT ", INFOG(2) = %" PetscInt_FMT ")\n",
                            (double)(std::sqrt(w2) / (2 * PETSC_PI)), infog1, infog2));
    }
    PetscFunctionReturn(0);
  };
  PetscReal w2slice = w2max; // the interval that slicing solves, [0, w2slice]
  PetscInt  nneg    = 0;
  const PetscInt cap = PetscMin(max_modes_, nI);
  if (fmax_ > 0 && nmodes_ < 0 && count_modes_) {
    bool ok = false;
    PetscCall(count(w2max, &nneg, &ok, &t_count));
    if (ok) {
      counted = true;
      nev     = PetscMin(nneg, cap);
    } else PetscCall(PetscPrintf(comm, "reduction: note: the modes below the cut-off by growing requests\n"));
  }
  // Many modes: spectrum slicing of [0, w2max] (its own eigensolver and factorisations, so the
  // factor of K_II above stays for the constraint modes), one part of the interval per rank.
  bool slice = counted && nev > 0 && slice_ != 0;
  if (slice && slice_ < 0) {
    // Time model, from the 17820-DOF brake (802 modes, 1 rank; K_II factor 0.2 s, a solve 7 ms):
    // at one shift ~3.5 solves per mode and ~4 n_I k^2 flops of orthogonalisation at ~1.4 GFlop/s
    // (31 of 47 s), none of it shared by the ranks (each solves the whole system); slicing ~3.2
    // solves per mode and k/60 + 2 more factorisations (60-90 modes a shift), split over its parts. A solve ~0.04 of a
    // factorisation, timed on the counting one. Few modes of a large model stay at one shift.
    const double parts     = (double)SliceParts(comm);
    const double t_solve   = 0.04 * t_count;
    const double one_shift = 4.0 * (double)nI * (double)nev * (double)nev / 1.4e9 + 3.5 * nev * t_solve;
    const double slicing   = (3.2 * nev * t_solve + ((double)nev / 60.0 + 2.0) * t_count) / parts;
    slice                  = one_shift > slicing && nev >= 50 * SliceParts(comm); // 50 modes a part at least
  }
  if (slice && nneg > cap) {
    // More modes below the cut-off than are kept: slicing the whole interval would solve them all
    // and drop the rest (1370 below 90 kHz on the size-2 brake, for 1000 kept). The lowest cap lie
    // below some lower cut-off, found by the count too (a factorisation each): guess N ~ lambda,
    // then the exponent of the last two counts, until 85-100 % of cap lie below it.
    PetscReal w2b = w2max, expo = 1.0;
    PetscInt  nb = nneg;
    for (int tries = 0; tries < 4 && !(nb <= cap && nb >= (PetscInt)(0.85 * cap)); ++tries) {
      const PetscReal w2c = w2b * std::pow(0.95 * (PetscReal)cap / (PetscReal)nb, 1.0 / expo);
      PetscInt        nc  = 0;
      bool            okc = false;
      PetscLogDouble  tc  = 0;
      PetscCall(count(w2c, &nc, &okc, &tc));
      if (!okc) break;
      if (nc != nb && nc > 0 && nb > 0) expo = PetscMax(0.25, PetscMin(4.0, std::log((PetscReal)nb / nc) / std::log(w2b / w2c)));
      w2b = w2c, nb = nc;
    }
    if (nb <= cap && nb > 0) w2slice = w2b, nev = nb;
    else slice = false; // no such cut-off found in a few counts: the cap's modes at one shift
  }
  if (counted && nneg > cap) {
    char f[64] = "";
    if (w2slice < w2max) std::snprintf(f, sizeof f, ", those below %g Hz", (double)(std::sqrt(w2slice) / (2 * PETSC_PI)));
    PetscCall(PetscPrintf(comm,
                          "reduction: warning: %" PetscInt_FMT " fixed-interface modes lie below %g Hz, more than -%smax_modes = %" PetscInt_FMT
                          "; only the lowest %" PetscInt_FMT " are kept%s: raise -%smax_modes or lower -%sfmax\n",
                          nneg, (double)fmax_, prefix_.c_str(), max_modes_, nev, f, prefix_.c_str(), prefix_.c_str()));
  }
  // Counted: block shift-and-invert Lanczos (src/reduction/block_lanczos.cpp), a block solve for
  // each -reduce_lanczos_block columns, where SLEPc solves for one vector at a time (the size-1
  // brake's 802 modes: 1 472 single solves of 6.7 ms, 16.5 s). The interval is cut into slices of
  // about -reduce_lanczos_slice_modes modes (a count at each cut, a factorisation of
  // K_II - sigma M_II at each slice's middle): one basis for all 802 modes needed 2 176 columns and
  // its orthogonalisation, O(n_I m^2), took 8 of 22.6 s. On several ranks (with the redundant
  // factor: a whole K_II on every rank) the slices are dealt out, as many to each rank, each
  // solved by its rank alone on whole copies of K_II and M_II, and every mode then sent to all.
  // A slice whose basis would pass -reduce_lanczos_max_mb unconverged leaves all the modes to
  // SLEPc below.
  PetscMPIInt size = 1, rank = 0;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  // Not where the modes are a large part of the interior's (a small model): the basis would fill
  // the space before it converges them, and SLEPc's dense-ish run is cheap there.
  if (counted && nev > 0 && lanczos_block_ > 0 && (size == 1 || in.redundant) && 8 * nev <= nI && !(nneg > nev && !(w2slice < w2max))) {
    const PetscReal w2l     = w2slice < w2max ? w2slice : w2max; // nev modes below it
    const PetscInt  by_mem  = (PetscInt)PetscMin((PetscReal)PETSC_MAX_INT, lanczos_max_mb_ * 1048576.0 / (16.0 * (PetscReal)nI)); // V and M V
    const PetscInt  per     = PetscMax(1, (PetscInt)std::lround((PetscReal)nev / ((PetscReal)lanczos_slice_modes_ * size)));
    const PetscInt  nslices = per * size;
    std::vector<PetscReal> cut{0.0};  // the slices' ends
    std::vector<PetscInt>  below{0};  // the modes below each
    std::vector<std::pair<PetscReal, PetscInt>> counts{{w2l, nev}};
    bool ok = true;
    for (PetscInt k = 1; k < nslices && ok; ++k) {
      const PetscReal w2c = LambdaAtCount(counts, (PetscReal)nev * k / nslices);
      PetscInt        nc  = 0;
      PetscLogDouble  tc  = 0;
      if (!(w2c > cut.back() && w2c < w2l)) continue;
      PetscCall(count(w2c, &nc, &ok, &tc));
      if (ok && nc > below.back() && nc < nev) {
        cut.push_back(w2c), below.push_back(nc);
        counts.insert(std::upper_bound(counts.begin(), counts.end(), std::make_pair(w2c, nc)), std::make_pair(w2c, nc));
      }
    }
    cut.push_back(w2l), below.push_back(nev);
    const size_t ns_all = cut.size() - 1;
    // Whole sequential copies of K_II and M_II on every rank (one rank: the matrices themselves).
    MatH Kseq, Mseq;
    Mat  Ks = in.Kii, Ms = in.Mii;
    if (size > 1 && ok) {
      PetscCall(MatCreateRedundantMatrix(in.Kii, size, PETSC_COMM_SELF, MAT_INITIAL_MATRIX, Kseq.out()));
      PetscCall(MatCreateRedundantMatrix(in.Mii, size, PETSC_COMM_SELF, MAT_INITIAL_MATRIX, Mseq.out()));
      Ks = Kseq, Ms = Mseq;
    }
    cb::LanczosInfo                     li;
    PetscReal                           worst = 0;
    std::vector<MatH>                   X(ns_all);   // this rank's slices' modes, every row
    std::vector<std::vector<PetscReal>> lams(ns_all); // and their eigenvalues
    for (size_t s = 0; ok && s < ns_all; ++s) {
      if ((PetscMPIInt)(s % (size_t)size) != rank) continue;
      const PetscInt  ns    = below[s + 1] - below[s];
      const PetscReal sigma = s == 0 ? 0.0 : 0.5 * (cut[s] + cut[s + 1]);
      MatH            A, Fs;
      Mat             F = in.Fct; // the slice at 0: K_II's own factor (sequential and whole on every rank when redundant)
      if (s > 0) {
        MatFactorError ferr;
        PetscCall(FactorShifted(Ks, Ms, sigma, false, A, Fs, &ferr));
        if (ferr != MAT_FACTOR_NOERROR) {
          ok = false;
          break;
        }
        F = Fs;
      }
      // A slice of the size-1 brake converged in 3-5 columns a mode; a few modes of a small pad
      // needed more than 160 columns for 17 (their spectrum's gaps, not their count, set it).
      const PetscInt max_cols = PetscMin(by_mem, PetscMin(nI / 2, PetscMax(10 * ns + 16 * lanczos_block_, 400)));
      PetscCall(MatCreateDense(PETSC_COMM_SELF, nI, PETSC_DECIDE, nI, ns, nullptr, X[s].out()));
      PetscCall(cb::BlockLanczosModes(F, Ms, sigma, cut[s], cut[s + 1], ns, lanczos_block_, max_cols, lanczos_tol_, lams[s], X[s], 0, li));
      ok    = li.converged;
      worst = PetscMax(worst, li.residual);
      if (lanczos_monitor_) {
        char who[32] = "";
        if (size > 1) std::snprintf(who, sizeof who, "[rank %d] ", (int)rank);
        PetscCall(PetscPrintf(PETSC_COMM_SELF,
                              "  %sblock Lanczos slice %d: %" PetscInt_FMT " modes in [%.1f, %.1f] Hz at shift %.1f Hz: %s, %" PetscInt_FMT
                              " columns so far, residual %.2e\n",
                              who, (int)s, ns, (double)(std::sqrt(cut[s]) / (2 * PETSC_PI)), (double)(std::sqrt(cut[s + 1]) / (2 * PETSC_PI)),
                              (double)(std::sqrt(sigma) / (2 * PETSC_PI)), ok ? "converged" : "NOT converged", li.columns, (double)li.residual));
      }
    }
    {
      PetscInt okl = ok ? 1 : 0, sums[2] = {li.columns, li.block_solves};
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &okl, 1, MPIU_INT, MPI_MIN, comm));
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPIU_INT, MPI_SUM, comm));
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &worst, 1, MPIU_REAL, MPI_MAX, comm));
      ok = okl == 1, li.columns = sums[0], li.block_solves = sums[1];
    }
    if (ok) {
      // Every slice's modes from its rank to all: each rank keeps its rows of in.modes.
      PetscInt     nIloc, r0;
      PetscScalar *dst;
      PetscCall(MatGetLocalSize(in.Kii, &nIloc, nullptr));
      PetscCall(MatGetOwnershipRange(in.Kii, &r0, nullptr));
      PetscCall(MatCreateDense(comm, nIloc, PETSC_DECIDE, nI, nev, nullptr, in.modes.out()));
      PetscCall(MatDenseGetArray(in.modes, &dst));
      std::vector<PetscScalar> col(size > 1 ? (size_t)nI : 0);
      PetscMPIInt              nImpi;
      PetscCall(PetscMPIIntCast(nI, &nImpi));
      for (size_t s = 0; s < ns_all; ++s) {
        const PetscMPIInt owner = (PetscMPIInt)(s % (size_t)size);
        const PetscInt    ns    = below[s + 1] - below[s];
        const PetscScalar *x    = nullptr;
        if (owner == rank) PetscCall(MatDenseGetArrayRead(X[s], &x));
        lams[s].resize((size_t)ns);
        PetscCallMPI(MPI_Bcast(lams[s].data(), (PetscMPIInt)ns, MPIU_REAL, owner, comm));
        lam.insert(lam.end(), lams[s].begin(), lams[s].end());
        for (PetscInt k = 0; k < ns; ++k) {
          const PetscScalar *c = x ? x + (size_t)nI * (size_t)k : nullptr;
          if (size > 1) {
            if (owner == rank) std::copy(c, c + nI, col.begin());
            PetscCallMPI(MPI_Bcast(col.data(), nImpi, MPIU_SCALAR, owner, comm));
            c = col.data();
          }
          std::copy(c + r0, c + r0 + nIloc, dst + (size_t)nIloc * (size_t)(below[s] + k));
        }
        if (owner == rank) PetscCall(MatDenseRestoreArrayRead(X[s], &x));
        X[s].reset();
      }
      PetscCall(MatDenseRestoreArray(in.modes, &dst));
      nconv = nev, slice = false;
      info_.lanczos_block = li.block > 0 ? li.block : lanczos_block_, info_.lanczos_columns = li.columns, info_.lanczos_solves = li.block_solves;
      info_.lanczos_slices = (PetscInt)ns_all;
    } else {
      PetscCall(PetscPrintf(comm,
                            "reduction: note: block Lanczos did not converge the %" PetscInt_FMT " modes (%" PetscInt_FMT
                            " columns, residual %.1e; -%slanczos_max_mb %g): solved by SLEPc instead\n",
                            nev, li.columns, (double)worst, prefix_.c_str(), (double)lanczos_max_mb_));
      lam.clear();
    }
  }
  if (counted && nev > 0 && !slice && !in.modes) PetscCall(EPSSetDimensions(in.eps, nev, in.ncv > nev ? in.ncv : PETSC_DEFAULT, in.mpd));
  if (slice && !in.modes) {
    auto count_only = [&](PetscReal w2, PetscInt *n, bool *ok) -> PetscErrorCode {
      PetscLogDouble t;
      return count(w2, n, ok, &t);
    };
    PetscCall(SliceModes(comm, in, w2slice, nev, count_only, lam));
    nconv = (PetscInt)lam.size();
    PetscCheck(nconv == nev || slice_ < 0, comm, PETSC_ERR_NOT_CONVERGED,
               "reduction: spectrum slicing found %" PetscInt_FMT " fixed-interface modes below %g Hz where the inertia counts %" PetscInt_FMT
               " (-%sslice 0 solves them at one shift)",
               nconv, (double)(std::sqrt(w2slice) / (2 * PETSC_PI)), nev, prefix_.c_str());
    if (nconv != nev) { // chosen for speed only: the one shift's solve instead
      PetscCall(PetscPrintf(comm,
                            "reduction: note: spectrum slicing found %" PetscInt_FMT " fixed-interface modes where the inertia counts %" PetscInt_FMT
                            "; solved again at one shift\n",
                            nconv, nev));
      in.slice.reset();
      lam.clear(), nconv = 0, slice = false, info_.slice_parts = 0;
      info_.slice_counts.clear();
      nev = PetscMin(nneg, cap); // the one shift asks for the cap's modes below the cut-off itself
      PetscCall(EPSSetDimensions(in.eps, nev, in.ncv > nev ? in.ncv : PETSC_DEFAULT, in.mpd));
    }
  }
  if (nmodes_ != 0 && !(counted && nev == 0) && !slice && !in.modes) {
    for (;;) {
      PetscCall(EPSSolve(in.eps));
      PetscCall(Eigenvalues(in.eps, lam));
      nconv = (PetscInt)lam.size();
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
      PetscCall(EPSSetDimensions(in.eps, nev, in.ncv > nev ? in.ncv : PETSC_DEFAULT, in.mpd));
    }
  }
  in.nev = nev;
  keep.resize(nconv);
  std::iota(keep.begin(), keep.end(), 0);
  std::sort(keep.begin(), keep.end(), [&](PetscInt a, PetscInt b) { return lam[a] < lam[b]; });
  while (!keep.empty() && lam[keep.back()] > w2max) keep.pop_back();
  if (nmodes_ > 0 && (PetscInt)keep.size() > nmodes_) keep.resize(nmodes_);
  // SLEPc may converge more than it was asked for (458 below 90 kHz on the half brake for a request
  // of 400): the bound holds on what is kept, as the warning above says.
  if ((PetscInt)keep.size() > max_modes_) keep.resize(max_modes_);
  if (!counted && fmax_ > 0 && nmodes_ < 0 && nconv > 0 && *std::max_element(lam.begin(), lam.end()) <= w2max)
    PetscCall(PetscPrintf(comm,
                          "reduction: warning: %" PetscInt_FMT " modes (-%smax_modes) do not reach the cut-off %g Hz; raise "
                          "-%smax_modes\n",
                          (PetscInt)keep.size(), prefix_.c_str(), (double)fmax_, prefix_.c_str()));
  if (keep.empty() && nmodes_ < 0 && nI > 0) {
    char f[32]; // PETSc's %g would print "10."
    std::snprintf(f, sizeof f, "%g", (double)fmax_);
    PetscCall(PetscPrintf(comm,
                          "reduction: warning: no fixed-interface mode lies below -%sfmax = %s Hz: the reduction is static (Guyan, "
                          "interface DOFs only) and misses every interior resonance; raise -%sfmax, or give -%snmodes 0 to ask for "
                          "a static reduction\n",
                          prefix_.c_str(), f, prefix_.c_str(), prefix_.c_str()));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode CraigBampton::Reduce(const Model &full, Model &red)
{
  MPI_Comm               comm = full.comm();
  PetscLogDouble         t[5], cpu[5];
  Stages                 stages{};
  cb::Partition          part;
  cb::Interior           in;
  cb::Basis              basis;
  std::vector<PetscReal> lam;
  std::vector<PetscInt>  keep;
  PetscFunctionBeginUser;
  PetscCall(GetStages(&stages));
  PetscCall(PetscTime(&t[0]));
  cpu[0] = CpuNow();
  info_ = ReductionInfo();
  if (!fmax_note_.empty()) PetscCall(PetscPrintf(comm_, "%s", fmax_note_.c_str()));
  PetscCall(PartitionDofs(full, part));
  info_.N           = part.N;
  info_.n_interface = part.nB;

  PetscCall(PetscLogStagePush(stages.factor));
  PetscCall(FactorInterior(full, part, in));
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&t[1]));
  cpu[1] = CpuNow();

  PetscCall(PetscLogStagePush(stages.modes));
  PetscCall(FixedInterfaceModes(comm, part, in, lam, keep));
  info_.n_modes = (PetscInt)keep.size();
  for (PetscInt k : keep) info_.freq.push_back(std::sqrt(PetscMax(lam[k], 0.0)) / (2 * PETSC_PI));
  PetscCall(CreateBasis(comm, part, in, lam, keep, basis));
  in.modes.reset();
  in.slice.reset(); // the slicing's copies of K_II, M_II and its factors, before the constraint modes
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&t[2]));
  cpu[2] = CpuNow();

  // Constraint modes Psi = -K_II^{-1} K_IB: nB right-hand sides in blocks of -reduce_rhs_block
  // (a signal is obeyed between blocks), written straight into the first nB columns of W (no
  // second N x nB copy).
  PetscCall(PetscLogStagePush(stages.constraint));
  PetscCall(cb::ConstraintModes(comm, in.Fct, in.Kib, in.redundant, sparse_rhs_, rhs_block_, basis.W));
  PetscCall(MatAssemblyBegin(basis.W, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(basis.W, MAT_FINAL_ASSEMBLY));
  in.eps.reset(); // and the factor with it, before the dense products
  PetscCall(PetscLogStagePop());
  // After the last block: a signal is obeyed before the projection.
  PetscCall(InterruptPoint(comm, "the Craig-Bampton reduction (after its constraint modes)"));
  PetscCall(PetscTime(&t[3]));
  cpu[3] = CpuNow();

  PetscCall(PetscLogStagePush(stages.project));
  Dense T; // interface reduction: n2 x (n_c + k + m), CB coordinates from the new ones; empty: none
  {
    Dense Mr, Kr, Cr, kbi_phi;
    PetscCall(ProjectMatrix(part, basis, full.K, Projected::stiffness, Kr, &kbi_phi));
    PetscCall(ProjectMatrix(part, basis, full.M, Projected::mass, Mr, &kbi_phi));
    // Rayleigh damping C = a M + b K projects to a M_r + b K_r exactly (the projection is linear),
    // which saves the dense product W^T C_II W; any other C is projected like M.
    PetscReal ray_a = 0, ray_b = 0;
    bool      rayleigh = false;
    if (full.C && rayleigh_) PetscCall(DetectRayleigh(full.M, full.K, full.C, &rayleigh, &ray_a, &ray_b));
    info_.rayleigh = rayleigh;
    // A C whose builder knows it is a M + b K + a few rows' extra (parts damped on their own):
    // only the extra is projected, at the cost of its rows (SymmetricProjection skips empty rows).
    info_.damping_split = !rayleigh && rayleigh_ && full.C && full.damping_a >= 0 && full.damping_extra;
    if (full.C && rayleigh) Cr = ray_a * Mr + ray_b * Kr;
    else if (info_.damping_split) {
      PetscCall(ProjectMatrix(part, basis, full.damping_extra, Projected::general, Cr, nullptr));
      Cr += full.damping_a * Mr + full.damping_b * Kr;
    } else if (full.C) PetscCall(ProjectMatrix(part, basis, full.C, Projected::general, Cr, nullptr));
    if (iface_modes_ >= 0 || iface_fmax_ > 0)
      PetscCall(cb::InterfaceReduction(comm, full.contacts, Permuted(basis, Mr), Permuted(basis, Kr), iface_modes_, iface_fmax_,
                                       iface_statics_, prefix_.c_str(), basis.m, T, red.contacts, info_));
    PetscCall(AssembleReduced(comm, basis, T, Mr, red.M.out()));
    PetscCall(AssembleReduced(comm, basis, T, Kr, red.K.out()));
    if (full.C) PetscCall(AssembleReduced(comm, basis, T, Cr, red.C.out()));
    else red.C.reset();
  }
  PetscCall(ReducedLoad(part, basis, T, full.F, red.K, red.F.out()));
  red.expansion.reset();
  const std::string pre   = OptionName(prefix_.c_str(), "");
  const PetscInt  n_red     = T.size() ? (PetscInt)T.cols() : basis.n2;
  const PetscReal expand_mb = 8.0 * (PetscReal)part.N * (PetscReal)n_red / 1048576.0;
  if (keep_expansion_ && expand_opt_ < 0 && expand_mb > expand_max_mb_) {
    // The default gives way to memory: with E beside W the 126 861-DOF brake's reduction peaked
    // at 9.5 GB; without it the results stay on the contact faces.
    PetscCall(PetscPrintf(comm,
                          "reduction: the expansion to the full mesh would take %.0f MB on rank 0, over %sexpand_max_mb %.0f: not kept, "
                          "results on the contact faces only (%sexpand 1 keeps it)\n",
                          (double)expand_mb, pre.c_str(), (double)expand_max_mb_, pre.c_str()));
  } else if (keep_expansion_) {
    PetscLogDouble t0, t1;
    auto           x = std::make_shared<Expansion>();
    x->records       = expand_records_;
    PetscCall(PetscTime(&t0));
    PetscCall(BuildExpansion(comm, part, basis, T, *x));
    PetscCall(PetscTime(&t1));
    info_.time_expansion  = t1 - t0;
    info_.expansion_bytes = x->Bytes();
    red.expansion         = std::move(x);
  }
  if (!T.size()) { // with interface reduction the contact set was made above
    red.contacts = full.contacts;
    PetscCall(RenumberContacts(comm, part, red.contacts));
  }
  char name[128];
  PetscCall(PetscSNPrintf(name, sizeof(name), " + CB(%" PetscInt_FMT " + %" PetscInt_FMT ")", basis.nB, basis.m));
  red.name = full.name + name;
  if (T.size()) {
    PetscCall(PetscSNPrintf(name, sizeof(name), " + IR(%" PetscInt_FMT " normal + %" PetscInt_FMT " interface modes)", info_.n_normal,
                            info_.n_inplane_modes));
    red.name += name;
  }
  PetscCall(red.Validate());
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&t[4]));
  cpu[4] = CpuNow();
  info_.time_factor  = t[1] - t[0];
  info_.time_modes   = t[2] - t[1];
  info_.time_static  = t[3] - t[2];
  info_.time_project = t[4] - t[3];
  info_.time_total   = t[4] - t[0];
  PetscLogDouble dcpu[4] = {cpu[1] - cpu[0], cpu[2] - cpu[1], cpu[3] - cpu[2], cpu[4] - cpu[3]};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, dcpu, 4, MPI_DOUBLE, MPI_MAX, comm));
  info_.cpu_factor = dcpu[0], info_.cpu_modes = dcpu[1], info_.cpu_static = dcpu[2], info_.cpu_project = dcpu[3];
  PetscLogDouble mem = 0;
  PetscCall(PetscMemoryGetCurrentUsage(&mem));
  PetscCallMPI(MPI_Allreduce(&mem, &info_.mem_peak, 1, MPI_DOUBLE, MPI_SUM, comm));
  // What a job must be given per node: the largest rank's high-water mark (the sum above read as
  // "13.4 GB" on the size-2 brake, whose rank 0 peaked at 8.2 GB and rank 1 at 5.5 GB).
  struct rusage ru{};
  double        hwm = getrusage(RUSAGE_SELF, &ru) == 0 ? 1024.0 * (double)ru.ru_maxrss : 0.0;
  PetscCallMPI(MPI_Allreduce(&hwm, &info_.mem_rank_hwm, 1, MPI_DOUBLE, MPI_MAX, comm));
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
  char statics[96] = "", sliced[160] = "";
  if (info_.slice_parts > 0) {
    std::string counts;
    for (size_t k = 0; k < info_.slice_counts.size(); ++k) counts += (k ? " + " : "") + std::to_string(info_.slice_counts[k]);
    PetscCall(PetscSNPrintf(sliced, sizeof sliced, " by spectrum slicing in %" PetscInt_FMT " part(s) (%s%s%" PetscInt_FMT " a shift)",
                            info_.slice_parts, info_.slice_parts > 1 ? counts.c_str() : "", info_.slice_parts > 1 ? " modes, " : "",
                            info_.slice_per_shift));
  }
  if (info_.lanczos_block > 0)
    PetscCall(PetscSNPrintf(sliced, sizeof sliced, " by block Lanczos in %" PetscInt_FMT " slice(s) (%" PetscInt_FMT " columns in %" PetscInt_FMT " block solves of %" PetscInt_FMT ")",
                            info_.lanczos_slices, info_.lanczos_columns, info_.lanczos_solves, info_.lanczos_block));
  if (info_.n_interface_statics > 0)
    PetscCall(PetscSNPrintf(statics, sizeof statics, " (%" PetscInt_FMT " of them the statics of the contact normals)", info_.n_interface_statics));
  if (info_.n_inplane_modes > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "  interface reduction: %" PetscInt_FMT " interface DOFs -> %" PetscInt_FMT " normal + %" PetscInt_FMT
                                     " characteristic constraint modes of the interface%s (%.1f to %.1f Hz): %" PetscInt_FMT " DOFs\n",
                                     info_.n_interface, info_.n_normal, info_.n_inplane_modes, statics, (double)info_.inplane_freq.front(),
                                     (double)info_.inplane_freq.back(), info_.n_normal + info_.n_inplane_modes + info_.n_modes));
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "  time %.3f s (factorisation of K_II %.3f s, fixed-interface modes %.3f s%s, constraint modes %.3f s, "
                                   "projection %.3f s%s), resident memory %.1f MB (all ranks; peak of the largest rank so far %.1f MB)\n",
                                   (double)info_.time_total, (double)info_.time_factor, (double)info_.time_modes, sliced,
                                   (double)info_.time_static, (double)info_.time_project,
                                   info_.rayleigh         ? ", C = a M + b K projected as a M_r + b K_r"
                                   : info_.damping_split ? ", C = a M + b K + the damped parts: the parts projected alone"
                                                         : "",
                                   (double)(info_.mem_peak / 1048576.0), (double)(info_.mem_rank_hwm / 1048576.0)));
  PetscCall(PetscViewerASCIIPrintf(viewer, "  CPU time of the busiest rank: %.3f s (%.3f, %.3f, %.3f, %.3f)\n",
                                   (double)(info_.cpu_factor + info_.cpu_modes + info_.cpu_static + info_.cpu_project),
                                   (double)info_.cpu_factor, (double)info_.cpu_modes, (double)info_.cpu_static, (double)info_.cpu_project));
  if (info_.expansion_bytes)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  expansion to the full model kept for the results on the mesh: %" PetscInt_FMT " x %" PetscInt_FMT
                                             " on rank 0, %.1f MB, built in %.3f s (-reduce_expand 0 frees it)\n",
                                     info_.N, info_.n_normal ? info_.n_normal + info_.n_inplane_modes + info_.n_modes : info_.n_interface + info_.n_modes,
                                     (double)(info_.expansion_bytes / 1048576.0), (double)info_.time_expansion));
  PetscFunctionReturn(0);
}

} // namespace squeal
