#include "squeal/model/model.h"
#include "squeal/core/errors.h"
#include "squeal/io/matrix_io.h"
#include "squeal/model/builders.h"

#include <string>

namespace squeal {

namespace {

// ||A - A^T||_F <= tol ||A||_F; MatIsSymmetric's tolerance is absolute per entry, which does not
// suit matrices whose entries span ten orders of magnitude.
PetscErrorCode CheckSymmetric(Mat A, const char *what, MPI_Comm comm)
{
  Mat       At;
  PetscReal nA, nD;
  PetscFunctionBeginUser;
  PetscCall(MatNorm(A, NORM_FROBENIUS, &nA));
  PetscCall(MatTranspose(A, MAT_INITIAL_MATRIX, &At));
  PetscCall(MatAXPY(At, -1.0, A, DIFFERENT_NONZERO_PATTERN));
  PetscCall(MatNorm(At, NORM_FROBENIUS, &nD));
  PetscCall(MatDestroy(&At));
  PetscCheck(nD <= 1e-10 * nA, comm, kErrInput, "%s is not symmetric: ||A - A^T|| / ||A|| = %g", what, (double)(nD / nA));
  PetscFunctionReturn(0);
}

// Fails naming the first diagonal entry that is not finite or violates the sign requirement.
PetscErrorCode CheckDiagonal(Mat A, const char *what, const char *problem, bool strictly_positive, MPI_Comm comm)
{
  Vec                d;
  const PetscScalar *a;
  PetscInt           rstart, rend, bad = -1;
  PetscReal          badv = 0;
  PetscFunctionBeginUser;
  PetscCall(MatCreateVecs(A, &d, nullptr));
  PetscCall(MatGetDiagonal(A, d));
  PetscCall(VecGetOwnershipRange(d, &rstart, &rend));
  PetscCall(VecGetArrayRead(d, &a));
  for (PetscInt i = rstart; i < rend && bad < 0; ++i) {
    const PetscReal v = PetscRealPart(a[i - rstart]);
    if (PetscIsInfOrNanReal(v) || (strictly_positive ? v <= 0 : v < 0)) bad = i, badv = v;
  }
  PetscCall(VecRestoreArrayRead(d, &a));
  PetscCall(VecDestroy(&d));
  // Report the first offending entry in global order, whichever rank found it.
  PetscInt  first = 0;
  PetscReal value = 0;
  const PetscInt mine = bad < 0 ? PETSC_MAX_INT : bad;
  PetscCallMPI(MPI_Allreduce(&mine, &first, 1, MPIU_INT, MPI_MIN, comm));
  const PetscReal contrib = (mine == first) ? badv : 0.0;
  PetscCallMPI(MPI_Allreduce(&contrib, &value, 1, MPIU_REAL, MPIU_SUM, comm));
  PetscCheck(first == PETSC_MAX_INT, comm, kErrInput, "%s: %s(%" PetscInt_FMT ",%" PetscInt_FMT ") = %g", problem, what,
             first, first, (double)value);
  PetscFunctionReturn(0);
}

// A positive diagonal does not make a symmetric matrix definite ([[1,1],[1,1]] is singular,
// [[1,2],[2,1]] indefinite): count the pivots of an LDL^T factorisation (MUMPS, null-pivot
// detection relative to ||A||) instead. Semi-definite: zero pivots allowed, negative ones not.
PetscErrorCode CheckDefinite(Mat A, const char *what, bool semi, MPI_Comm comm)
{
  Mat            F;
  IS             rperm, cperm;
  MatFactorInfo  info;
  MatFactorError ferr;
  PetscInt       N, nneg = 0, nzero = 0, npos = 0;
  PetscFunctionBeginUser;
  PetscCall(MatGetSize(A, &N, nullptr));
  // A diagonal matrix (a lumped mass) is definite by its diagonal, checked before: MUMPS's PORD
  // ordering of its edgeless graph is quadratic (61 s of a 30000-cell chain's 68 s set-up, deaf to
  // signals).
  {
    PetscInt  rstart, rend;
    PetscBool offdiag = PETSC_FALSE, any;
    PetscCall(MatGetOwnershipRange(A, &rstart, &rend));
    for (PetscInt i = rstart; i < rend && !offdiag; ++i) {
      PetscInt           nc;
      const PetscInt    *cols;
      const PetscScalar *vals;
      PetscCall(MatGetRow(A, i, &nc, &cols, &vals));
      for (PetscInt k = 0; k < nc; ++k)
        if (cols[k] != i && vals[k] != 0.0) offdiag = PETSC_TRUE;
      PetscCall(MatRestoreRow(A, i, &nc, &cols, &vals));
    }
    PetscCallMPI(MPI_Allreduce(&offdiag, &any, 1, MPIU_BOOL, MPI_LOR, comm));
    if (!any && !semi) PetscFunctionReturn(0);
  }
  PetscCall(MatGetFactor(A, MATSOLVERMUMPS, MAT_FACTOR_CHOLESKY, &F));
  PetscCall(MatMumpsSetIcntl(F, 24, 1));      // detect null pivots ...
  PetscCall(MatMumpsSetCntl(F, 3, 1e-10));    // ... below 1e-10 ||A|| (scaled)
  PetscCall(MatMumpsSetIcntl(F, 13, 1));      // inertia that is valid on several ranks too
  PetscCall(MatGetOrdering(A, MATORDERINGNATURAL, &rperm, &cperm));
  PetscCall(MatFactorInfoInitialize(&info));
  PetscCall(MatCholeskyFactorSymbolic(F, A, rperm, &info));
  PetscCall(MatCholeskyFactorNumeric(F, A, &info));
  PetscCall(MatFactorGetError(F, &ferr));
  if (ferr == MAT_FACTOR_NOERROR) PetscCall(MatGetInertia(F, &nneg, &nzero, &npos));
  PetscCall(ISDestroy(&rperm));
  PetscCall(ISDestroy(&cperm));
  PetscCall(MatDestroy(&F));
  PetscCheck(ferr != MAT_FACTOR_OUTMEMORY, comm, PETSC_ERR_MEM,
             "out of memory factorising %s (%" PetscInt_FMT " x %" PetscInt_FMT ") to check that it is positive definite", what, N, N);
  PetscCheck(ferr == MAT_FACTOR_NOERROR, comm, kErrInput,
             "%s is singular: its LDL^T factorisation fails (a positive diagonal is not enough; expected symmetric positive %sdefinite)",
             what, semi ? "semi-" : "");
  PetscCheck(nneg == 0 && (semi || nzero == 0), comm, kErrInput,
             "%s is not positive %sdefinite: its LDL^T factorisation has %" PetscInt_FMT " negative and %" PetscInt_FMT
             " zero pivot(s) of %" PetscInt_FMT " (%s, although a diagonal may be positive)",
             what, semi ? "semi-" : "", nneg, nzero, N, nneg ? "indefinite" : "singular");
  PetscFunctionReturn(0);
}

PetscErrorCode CheckFinite(Mat A, const char *what, MPI_Comm comm)
{
  PetscReal nrm;
  PetscFunctionBeginUser;
  PetscCall(MatNorm(A, NORM_FROBENIUS, &nrm));
  PetscCheck(!PetscIsInfOrNanReal(nrm), comm, kErrInput, "%s has NaN or infinite entries", what);
  PetscFunctionReturn(0);
}

} // namespace

PetscInt Model::Size() const
{
  PetscInt n = 0;
  if (K) PetscCallAbort(comm_, MatGetSize(K, &n, nullptr));
  return n;
}

PetscErrorCode Model::Validate()
{
  PetscInt  m, n, nf;
  PetscReal fn;
  PetscFunctionBeginUser;
  PetscCheck(M && K && F, comm_, kErrInput, "model '%s' is incomplete: M, K and F are required", name.c_str());
  PetscCall(MatGetSize(K, &m, &n));
  PetscCheck(m == n, comm_, kErrInput, "stiffness matrix K is %" PetscInt_FMT " x %" PetscInt_FMT ": expected square", m, n);
  const PetscInt N = m;
  struct Named {
    Mat         A;
    const char *name;
  } mats[] = {{M, "mass matrix M"}, {C, "damping matrix C"}};
  for (const Named &x : mats) {
    if (!x.A) continue;
    PetscCall(MatGetSize(x.A, &m, &n));
    PetscCheck(m == N && n == N, comm_, kErrInput,
               "%s is %" PetscInt_FMT " x %" PetscInt_FMT " but K is %" PetscInt_FMT " x %" PetscInt_FMT, x.name, m, n, N, N);
  }
  PetscCall(VecGetSize(F, &nf));
  PetscCheck(nf == N, comm_, kErrInput, "load vector F has %" PetscInt_FMT " entries but K is %" PetscInt_FMT " x %" PetscInt_FMT,
             nf, N, N);
  PetscCall(VecNorm(F, NORM_2, &fn));
  PetscCheck(!PetscIsInfOrNanReal(fn), comm_, kErrInput, "load vector F has NaN or infinite entries");
  PetscCall(CheckFinite(M, "mass matrix M", comm_));
  PetscCall(CheckFinite(K, "stiffness matrix K", comm_));
  if (C) PetscCall(CheckFinite(C, "damping matrix C", comm_));
  PetscCall(CheckDiagonal(M, "M", "non-positive mass", true, comm_));
  PetscCall(CheckDiagonal(K, "K", "negative stiffness", false, comm_));
  if (C) PetscCall(CheckDiagonal(C, "C", "negative damping", false, comm_));
  PetscCall(CheckSymmetric(M, "mass matrix M", comm_));
  PetscCall(CheckSymmetric(K, "stiffness matrix K", comm_));
  if (C) PetscCall(CheckSymmetric(C, "damping matrix C", comm_));
  PetscCall(CheckDefinite(M, "mass matrix M", false, comm_));
  PetscCall(contacts.Validate(comm_, N));
  PetscFunctionReturn(0);
}

PetscErrorCode Model::View(PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscCall(PetscViewerASCIIPrintf(viewer, "model '%s': %" PetscInt_FMT " DOFs, %s damping\n", name.c_str(), Size(),
                                   HasDamping() ? "viscous" : "no"));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(contacts.View(viewer));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode Model::Export(const char *dir, const char *format) const
{
  const std::string d   = std::string(dir) + "/";
  const std::string ext = std::string(".") + (format ? format : "bin");
  PetscViewer       v;
  PetscMPIInt       rank;
  PetscFunctionBeginUser;
  // One rank creates the folder: on every rank, the second mkdir of a race fails ("Could not create dir").
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  if (rank == 0) PetscCall(PetscMkdir(dir));
  PetscCallMPI(MPI_Barrier(comm_));
  PetscCall(io::MatSaveToFile(M, (d + "M" + ext).c_str()));
  PetscCall(io::MatSaveToFile(K, (d + "K" + ext).c_str()));
  if (C) PetscCall(io::MatSaveToFile(C, (d + "C" + ext).c_str()));
  PetscCall(io::OpenBinaryViewer(comm_, (d + "F.bin").c_str(), FILE_MODE_WRITE, &v));
  PetscCall(VecView(F, v));
  PetscCall(PetscViewerDestroy(&v));
  PetscCall(WriteContactTable(comm_, (d + "contacts.txt").c_str(), contacts));
  PetscFunctionReturn(0);
}

// The whole of src on rank 0 (all_ranks false) or on every rank, as a model on PETSC_COMM_SELF.
static PetscErrorCode ModelGather(const Model &src, Model &dst, bool all_ranks)
{
  PetscMPIInt rank;
  const PetscInt N = src.Size();
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(src.comm(), &rank));
  PetscCheck(dst.comm() == PETSC_COMM_SELF, src.comm(), PETSC_ERR_ARG_WRONG, "ModelGather: the copy must be on PETSC_COMM_SELF");
  const bool mine = all_ranks || rank == 0;
  Handle<IS> all;
  PetscCall(ISCreateStride(PETSC_COMM_SELF, mine ? N : 0, 0, 1, all.out()));
  auto gather = [&](Mat A, MatH &out) -> PetscErrorCode {
    Mat *sub;
    IS   is = all;
    PetscFunctionBeginUser;
    PetscCall(MatCreateSubMatrices(A, 1, &is, &is, MAT_INITIAL_MATRIX, &sub));
    if (mine) {
      PetscCall(PetscObjectReference((PetscObject)sub[0]));
      *out.out() = sub[0];
    }
    PetscCall(MatDestroySubMatrices(1, &sub));
    PetscFunctionReturn(0);
  };
  PetscCall(gather(src.M, dst.M));
  PetscCall(gather(src.K, dst.K));
  if (src.HasDamping()) PetscCall(gather(src.C, dst.C));
  VecScatter sc;
  Vec        f0;
  if (all_ranks) PetscCall(VecScatterCreateToAll(src.F, &sc, &f0));
  else PetscCall(VecScatterCreateToZero(src.F, &sc, &f0));
  PetscCall(VecScatterBegin(sc, src.F, f0, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, src.F, f0, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterDestroy(&sc));
  if (mine) *dst.F.out() = f0;
  else PetscCall(VecDestroy(&f0));
  dst.contacts = src.contacts;
  dst.name     = src.name;
  if (!all_ranks) {
    dst.mesh      = src.mesh;
    dst.expansion = src.expansion; // built on rank 0, where the copy lives
  }
  PetscFunctionReturn(0);
}

PetscErrorCode ModelGatherToRankZero(const Model &src, Model &dst) { return ModelGather(src, dst, false); }

PetscErrorCode ModelReplicate(const Model &src, Model &dst) { return ModelGather(src, dst, true); }

PetscErrorCode ModelShare(const Model &src, Model &dst)
{
  PetscMPIInt same;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_compare(src.comm(), dst.comm(), &same));
  PetscCheck(same == MPI_IDENT || same == MPI_CONGRUENT, src.comm(), PETSC_ERR_ARG_WRONG, "ModelShare: the models must be on one communicator");
  auto share = [](auto obj, auto &h) -> PetscErrorCode {
    PetscFunctionBeginUser;
    if (obj) PetscCall(PetscObjectReference((PetscObject)obj));
    *h.out() = obj;
    PetscFunctionReturn(0);
  };
  PetscCall(share(src.M.get(), dst.M));
  PetscCall(share(src.C.get(), dst.C));
  PetscCall(share(src.K.get(), dst.K));
  PetscCall(share(src.F.get(), dst.F));
  dst.contacts = src.contacts;
  dst.name     = src.name;
  dst.mesh.reset();
  dst.expansion.reset();
  PetscFunctionReturn(0);
}

} // namespace squeal
