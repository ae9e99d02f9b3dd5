// Fixed-interface modes by block shift-and-invert Lanczos (cb::BlockLanczosModes, internal.h).
//
// Why not SLEPc's Krylov-Schur here: it applies K_II^-1 to one vector at a time, and one MUMPS
// solve of the size-1 brake's K_II (n_I = 16 764) takes 6.7 ms, bound by reading the factor from
// memory, while a solve of 32 right-hand sides takes 7.6 ms (the constraint modes' blocks). Its
// 802 modes took 1 472 single solves, 9.9 of the 16.5 s. A block Krylov space costs a block
// solve per b columns, and its orthogonalisation is matrix-matrix products (BLAS 3) instead of
// one vector at a time.
//
// OP = K^-1 M is self-adjoint in the M inner product; its largest eigenvalues theta = 1/lambda are
// the lowest modes (with a shift sigma, OP = (K - sigma M)^-1 M, and the modes on both sides of
// sigma are both ends of its spectrum). The basis V (M-orthonormal) grows a block at a time, each
// new block orthogonalised against V (classical Gram-Schmidt in blocks: the last two blocks, all
// of V, the last two again) and then within itself (SVQB, twice); T = V^T M OP V is block
// tridiagonal with blocks of b. No restart: V and M V hold every column (16 n_I bytes each), so
// the caller bounds them.
//
// When to stop: the nev modes below the cut-off are counted beforehand (Sylvester's inertia). The
// Ritz values of T are inside the eigenvalues they approach (Cauchy's interlacing), so once nev of
// them lie at the ends that map to [lo, hi], nev eigenvalues do, and those are all the modes there. Then
// their residuals ||R_last s_last|| / theta (the Lanczos estimate) must be below tol; else more
// blocks.
#include "internal.h"

#include "squeal/core/dense_blas.h"
#include "squeal/core/errors.h"
#include "squeal/core/inf.h"
#include "squeal/core/interrupt.h"

#include <petscblaslapack.h>

#include <algorithm>
#include <cmath>
#include <vector>

extern "C" {
void dsbev_(const char *jobz, const char *uplo, const PetscBLASInt *n, const PetscBLASInt *kd, double *ab, const PetscBLASInt *ldab, double *w,
            double *z, const PetscBLASInt *ldz, double *work, PetscBLASInt *info);
void dsyevd_(const char *jobz, const char *uplo, const PetscBLASInt *n, double *a, const PetscBLASInt *lda, double *w, double *work,
             const PetscBLASInt *lwork, PetscBLASInt *iwork, const PetscBLASInt *liwork, PetscBLASInt *info);
}

namespace squeal::cb {

namespace {

using MapM = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

PetscLogEvent ev_solve = 0, ev_orth = 0, ev_ritz = 0;
PetscErrorCode RegisterEvents()
{
  PetscFunctionBeginUser;
  if (!ev_solve) {
    PetscCall(PetscLogEventRegister("CBLanczosSolve", MAT_CLASSID, &ev_solve));
    PetscCall(PetscLogEventRegister("CBLanczosOrth", MAT_CLASSID, &ev_orth));
    PetscCall(PetscLogEventRegister("CBLanczosRitz", MAT_CLASSID, &ev_ritz));
  }
  PetscFunctionReturn(0);
}

// The eigenvalues of the symmetric band matrix T(0:m, 0:m) (bandwidth kd), ascending.
PetscErrorCode BandEigenvalues(const Dense &T, PetscInt m, PetscInt kd, std::vector<PetscReal> &w)
{
  PetscBLASInt           n, k, ld, one = 1, info = 0;
  PetscFunctionBeginUser;
  PetscCall(PetscBLASIntCast(m, &n));
  PetscCall(PetscBLASIntCast(kd, &k));
  ld = k + 1;
  std::vector<double> ab((size_t)ld * (size_t)m, 0.0), work(3 * (size_t)m);
  for (PetscInt j = 0; j < m; ++j)
    for (PetscInt i = j; i <= std::min(m - 1, j + kd); ++i) ab[(size_t)(i - j) + (size_t)ld * (size_t)j] = T(i, j);
  w.resize((size_t)m);
  double z = 0;
  dsbev_("N", "L", &n, &k, ab.data(), &ld, w.data(), &z, &one, work.data(), &info);
  PetscCheck(info == 0, PETSC_COMM_SELF, PETSC_ERR_LIB, "block Lanczos: LAPACK dsbev failed (info %d)", (int)info);
  PetscFunctionReturn(0);
}

// S = the eigenvectors of the symmetric T(0:m, 0:m), w their eigenvalues, ascending.
PetscErrorCode DenseEigen(const Dense &T, PetscInt m, Dense &S, std::vector<PetscReal> &w)
{
  PetscBLASInt n, lwork = -1, liwork = -1, info = 0, iw = 0;
  double       wq = 0;
  PetscFunctionBeginUser;
  PetscCall(PetscBLASIntCast(m, &n));
  S = T.topLeftCorner(m, m);
  w.resize((size_t)m);
  dsyevd_("V", "L", &n, S.data(), &n, w.data(), &wq, &lwork, &iw, &liwork, &info);
  lwork = (PetscBLASInt)wq, liwork = iw;
  std::vector<double>       work((size_t)std::max<PetscBLASInt>(lwork, 1));
  std::vector<PetscBLASInt> iwork((size_t)std::max<PetscBLASInt>(liwork, 1));
  dsyevd_("V", "L", &n, S.data(), &n, w.data(), work.data(), &lwork, iwork.data(), &liwork, &info);
  PetscCheck(info == 0, PETSC_COMM_SELF, PETSC_ERR_LIB, "block Lanczos: LAPACK dsyevd failed (info %d)", (int)info);
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode BlockLanczosModes(Mat F, Mat Mii, PetscReal sigma, PetscReal lo, PetscReal hi, PetscInt nev, PetscInt b, PetscInt max_cols,
                                 PetscReal tol, std::vector<PetscReal> &lam, Mat X, PetscInt x0, LanczosInfo &info)
{
  MPI_Comm    comm;
  PetscMPIInt size;
  PetscInt    n;
  PetscFunctionBeginUser;
  info.converged = false, info.residual = 0;
  PetscCall(RegisterEvents());
  PetscCall(PetscObjectGetComm((PetscObject)Mii, &comm));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCheck(size == 1, comm, PETSC_ERR_SUP, "block Lanczos: one rank only");
  PetscCheck(lo <= sigma && sigma < hi, comm, PETSC_ERR_ARG_OUTOFRANGE, "block Lanczos: the shift %g is not in [%g, %g)", (double)sigma, (double)lo,
             (double)hi);
  PetscCall(MatGetSize(Mii, &n, nullptr));
  b = PetscMax(1, PetscMin(b, n / 4));
  // Whole blocks, and room for the residual block after the last one.
  const PetscInt mmax = PetscMin(max_cols, n - b) / b * b;
  info.block = b;
  if (nev <= 0) {
    info.converged = true;
    PetscFunctionReturn(0);
  }
  if (mmax < nev + b) PetscFunctionReturn(0); // not converged: the caller's other route

  // V and MV = M V: the projections read V^T M W as MV^T W, so that M is applied once a block (to
  // the block being orthonormalised; the solve's right-hand side M V_j is MV's block). Five sparse
  // products a block took 3 of 10 s on the size-1 brake.
  MatH V, MV;
  PetscCall(MatCreateDense(comm, n, PETSC_DECIDE, n, mmax + b, nullptr, V.out()));
  PetscCall(MatCreateDense(comm, n, PETSC_DECIDE, n, mmax + b, nullptr, MV.out()));
  Dense T = Dense::Zero(mmax, mmax);
  Dense R = Dense::Zero(b, b); // the last subdiagonal block: OP V_last = ... + V_next R
  {
    PetscRandom rnd;
    Mat         V0;
    PetscCall(PetscRandomCreate(PETSC_COMM_SELF, &rnd));
    PetscCall(PetscRandomSetInterval(rnd, -1.0, 1.0));
    PetscCall(PetscRandomSetSeed(rnd, 0x5eed));
    PetscCall(PetscRandomSeed(rnd));
    PetscCall(MatDenseGetSubMatrix(V, PETSC_DECIDE, PETSC_DECIDE, 0, b, &V0));
    PetscCall(MatSetRandom(V0, rnd));
    PetscCall(MatDenseRestoreSubMatrix(V, &V0));
    PetscCall(PetscRandomDestroy(&rnd));
  }

  // Columns [c, c + b) of V made M-orthonormal to columns [0, c) and among themselves, and MV's
  // block with them; H (c x b) and Rb (b x b) the coefficients: the block before = V(:, 0:c) H +
  // V(:, c:c+b) Rb. ok false where the block has lost rank (an invariant subspace: not expected at
  // these sizes).
  Dense H, G, Rb;
  auto  orthonormalise = [&](PetscInt c, bool *ok) -> PetscErrorCode {
    PetscScalar *v, *mv;
    Mat          Vb, Zb = nullptr;
    PetscFunctionBeginUser;
    *ok = true;
    H   = Dense::Zero(c, b);
    Rb  = Dense::Identity(b, b);
    PetscCall(PetscLogEventBegin(ev_orth, 0, 0, 0, 0));
    if (c > 0) {
      // Classical Gram-Schmidt: against the last two blocks (the three-term recurrence, where the
      // new block's large components lie), then against the whole basis once, then the last two
      // again. Reading V and MV whole is what costs (the products with a few columns are bound
      // by memory): twice against the whole basis took 6.8 of the size-1 brake's 14.4 s.
      PetscCall(MatDenseGetArray(V, &v));
      PetscCall(MatDenseGetArray(MV, &mv));
      MapM Vall(v, n, c + b, Eigen::OuterStride<>(n)), MVall(mv, n, c, Eigen::OuterStride<>(n));
      const PetscInt lo2 = PetscMax(0, c - 2 * b);
      for (int pass = 0; pass < 3; ++pass) {
        const PetscInt c0 = pass == 1 ? 0 : lo2;
        Dense          Hp(c - c0, b);
        Gemm(MVall.middleCols(c0, c - c0), true, Vall.middleCols(c, b), Hp);
        Gemm(Vall.middleCols(c0, c - c0), false, Hp, Vall.middleCols(c, b), -1.0, 1.0);
        H.bottomRows(c - c0) += Hp;
      }
      PetscCall(MatDenseRestoreArray(MV, &mv));
      PetscCall(MatDenseRestoreArray(V, &v));
    }
    PetscCall(MatDenseGetSubMatrix(V, PETSC_DECIDE, PETSC_DECIDE, c, c + b, &Vb));
    PetscCall(MatMatMult(Mii, Vb, MAT_INITIAL_MATRIX, PETSC_DEFAULT, &Zb));
    PetscCall(MatDenseRestoreSubMatrix(V, &Vb));
    {
      const PetscScalar *z;
      PetscCall(MatDenseGetArrayRead(Zb, &z));
      PetscCall(MatDenseGetArray(V, &v));
      PetscCall(MatDenseGetArray(MV, &mv));
      MapM  W(v + (size_t)n * (size_t)c, n, b, Eigen::OuterStride<>(n)), MW(mv + (size_t)n * (size_t)c, n, b, Eigen::OuterStride<>(n));
      MW = Eigen::Map<const Eigen::MatrixXd>(z, n, b);
      // SVQB, twice: W = W_new D^1/2 Q^T with W_new = W Q D^-1/2 M-orthonormal; M W_new follows
      // from M W by the same product.
      for (int pass = 0; pass < 2 && *ok; ++pass) {
        G.resize(b, b);
        Gemm(W, true, MW, G);
        G = 0.5 * (G + G.transpose());
        Eigen::SelfAdjointEigenSolver<Dense> es(G);
        const Eigen::VectorXd d    = es.eigenvalues();
        const PetscReal       dmax = d.maxCoeff();
        if (!(dmax > 0) || d.minCoeff() <= 1e-12 * dmax) *ok = false;
        else {
          const Dense Q = es.eigenvectors() * d.cwiseSqrt().cwiseInverse().asDiagonal();
          Dense       Wn(n, b);
          Gemm(W, false, Q, Wn);
          W = Wn;
          Gemm(MW, false, Q, Wn);
          MW = Wn;
          Rb = d.cwiseSqrt().asDiagonal() * es.eigenvectors().transpose() * Rb;
        }
      }
      PetscCall(MatDenseRestoreArray(MV, &mv));
      PetscCall(MatDenseRestoreArray(V, &v));
      PetscCall(MatDenseRestoreArrayRead(Zb, &z));
    }
    PetscCall(MatDestroy(&Zb));
    PetscCall(PetscLogEventEnd(ev_orth, 0, 0, 0, 0));
    PetscFunctionReturn(0);
  };

  bool ok = true;
  PetscCall(orthonormalise(0, &ok));
  if (!ok) PetscFunctionReturn(0);
  // lambda in [lo, hi] <=> theta = 1 / (lambda - sigma) >= theta_hi or <= theta_lo: both ends of
  // OP's spectrum, where Cauchy's interlacing bounds the Ritz values' count by the eigenvalues'.
  const PetscReal        theta_hi = 1.0 / (hi - sigma), theta_lo = lo < sigma ? 1.0 / (lo - sigma) : -kInf;
  auto                   inside   = [&](PetscReal t) { return t >= theta_hi || t <= theta_lo; };
  std::vector<PetscReal> w;
  Dense                  S;
  PetscInt               m = 0, next_full = 0, next_band = 0;
  bool                   done = false;
  while (m + b <= mmax) {
    PetscCall(InterruptPoint(comm, "the fixed-interface modes (block Lanczos, between two blocks)"));
    // V(:, m + b : m + 2b) = K^-1 M V(:, m : m + b)
    {
      Mat MVj, Vn;
      PetscCall(PetscLogEventBegin(ev_solve, 0, 0, 0, 0));
      PetscCall(MatDenseGetSubMatrix(MV, PETSC_DECIDE, PETSC_DECIDE, m, m + b, &MVj));
      PetscCall(MatDenseGetSubMatrix(V, PETSC_DECIDE, PETSC_DECIDE, m + b, m + 2 * b, &Vn));
      PetscCall(MatMatSolve(F, MVj, Vn));
      PetscCall(MatDenseRestoreSubMatrix(V, &Vn));
      PetscCall(MatDenseRestoreSubMatrix(MV, &MVj));
      PetscCall(PetscLogEventEnd(ev_solve, 0, 0, 0, 0));
      ++info.block_solves;
    }
    PetscCall(orthonormalise(m + b, &ok));
    if (!ok) PetscFunctionReturn(0);
    // T's block column m: the diagonal block from H (symmetrised), the subdiagonal Rb; the rest of
    // H is round-off of the full reorthogonalisation.
    const Dense A = H.bottomRows(b);
    T.block(m, m, b, b) = 0.5 * (A + A.transpose());
    if (m + b < mmax) {
      T.block(m + b, m, b, b) = Rb;
      T.block(m, m + b, b, b) = Rb.transpose();
    }
    R = Rb;
    m += b;
    info.columns += b;
    if (m < nev || m < next_band) continue;
    next_band = m + PetscMax(b, m / 20 / b * b); // the band's eigenvalues at most once per 5 % more columns
    PetscCall(PetscLogEventBegin(ev_ritz, 0, 0, 0, 0));
    PetscCall(BandEigenvalues(T, m, 2 * b - 1, w) /* R is full (SVQB): T has 2b - 1 subdiagonals */);
    ++info.checks;
    const PetscInt found = (PetscInt)std::count_if(w.begin(), w.end(), inside);
    if (found >= nev && m >= next_full) {
      // The residual estimates need T's eigenvectors (O(m^3)): at most once per 10 % more columns.
      PetscCall(DenseEigen(T, m, S, w));
      ++info.full_checks;
      PetscReal worst = 0;
      for (PetscInt i = 0; i < m; ++i)
        if (inside(w[(size_t)i])) worst = std::max(worst, (R * S.block(m - b, i, b, 1)).norm() / std::abs(w[(size_t)i]));
      info.residual = worst;
      done          = worst <= tol;
      next_full     = m + PetscMax(b, m / 10 / b * b);
    }
    PetscCall(PetscLogEventEnd(ev_ritz, 0, 0, 0, 0));
    if (done) break;
  }
  if (!done) PetscFunctionReturn(0);
  std::vector<PetscInt> keep;
  for (PetscInt i = 0; i < m; ++i)
    if (inside(w[(size_t)i])) keep.push_back(i);
  if ((PetscInt)keep.size() != nev) PetscFunctionReturn(0); // more than counted: round-off at an end; the other route

  // The Ritz vectors X(:, x0 : x0 + nev) = V(:, 0:m) S(:, keep), eigenvalues sigma + 1/theta.
  {
    PetscScalar *v, *x;
    PetscInt     nx;
    Dense        Sk(m, nev);
    PetscCall(MatGetSize(X, nullptr, &nx));
    PetscCheck(x0 + nev <= nx, comm, PETSC_ERR_ARG_SIZ, "block Lanczos: no room for %" PetscInt_FMT " modes in X", nev);
    for (PetscInt k = 0; k < nev; ++k) {
      Sk.col(k) = S.col(keep[(size_t)k]);
      lam.push_back(sigma + 1.0 / w[(size_t)keep[(size_t)k]]);
    }
    PetscCall(MatDenseGetArray(V, &v));
    PetscCall(MatDenseGetArray(X, &x));
    MapM Vm(v, n, m, Eigen::OuterStride<>(n));
    MapM Xm(x + (size_t)n * (size_t)x0, n, nev, Eigen::OuterStride<>(n));
    Gemm(Vm, false, Sk, Xm);
    PetscCall(MatDenseRestoreArray(X, &x));
    PetscCall(MatDenseRestoreArray(V, &v));
  }
  info.converged = true;
  PetscFunctionReturn(0);
}

} // namespace squeal::cb
