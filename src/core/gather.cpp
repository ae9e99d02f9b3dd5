#include "squeal/core/gather.h"

namespace squeal {

PetscErrorCode GatherVector(Vec v, bool to_all, std::vector<PetscReal> &out)
{
  VecScatter         sc;
  Vec                w;
  const PetscScalar *a;
  PetscInt           n;
  PetscFunctionBeginUser;
  if (to_all) PetscCall(VecScatterCreateToAll(v, &sc, &w));
  else PetscCall(VecScatterCreateToZero(v, &sc, &w));
  PetscCall(VecScatterBegin(sc, v, w, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, v, w, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetLocalSize(w, &n));
  PetscCall(VecGetArrayRead(w, &a));
  out.assign(n, 0.0);
  for (PetscInt i = 0; i < n; ++i) out[i] = PetscRealPart(a[i]);
  PetscCall(VecRestoreArrayRead(w, &a));
  PetscCall(VecDestroy(&w));
  PetscCall(VecScatterDestroy(&sc));
  PetscFunctionReturn(0);
}

PetscErrorCode SetOwnedRows(const PetscReal *full, Vec v)
{
  PetscInt     lo, hi;
  PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(VecGetOwnershipRange(v, &lo, &hi));
  PetscCall(VecGetArray(v, &a));
  for (PetscInt i = lo; i < hi; ++i) a[i - lo] = full[i];
  PetscCall(VecRestoreArray(v, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode GatherSubmatrix(Mat A, IS rows, IS cols, Eigen::MatrixXd &out)
{
  PetscInt m, n;
  Mat     *sub = nullptr;
  PetscFunctionBeginUser;
  PetscCall(ISGetLocalSize(rows, &m));
  PetscCall(ISGetLocalSize(cols, &n));
  PetscCall(MatCreateSubMatrices(A, 1, &rows, &cols, MAT_INITIAL_MATRIX, &sub));
  out.setZero(m, n);
  for (PetscInt i = 0; i < m; ++i) {
    PetscInt           nc;
    const PetscInt    *cj;
    const PetscScalar *v;
    PetscCall(MatGetRow(sub[0], i, &nc, &cj, &v));
    for (PetscInt k = 0; k < nc; ++k) out(i, cj[k]) = PetscRealPart(v[k]);
    PetscCall(MatRestoreRow(sub[0], i, &nc, &cj, &v));
  }
  PetscCall(MatDestroySubMatrices(1, &sub));
  PetscFunctionReturn(0);
}

PetscErrorCode GatherMatrix(Mat A, bool to_all, Eigen::MatrixXd &out)
{
  PetscInt    m, n;
  PetscMPIInt rank;
  Handle<IS>  rows, cols;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(PetscObjectComm((PetscObject)A), &rank));
  PetscCall(MatGetSize(A, &m, &n));
  const bool here = to_all || rank == 0;
  PetscCall(ISCreateStride(PETSC_COMM_SELF, here ? m : 0, 0, 1, rows.out()));
  PetscCall(ISCreateStride(PETSC_COMM_SELF, here ? n : 0, 0, 1, cols.out()));
  PetscCall(GatherSubmatrix(A, rows, cols, out));
  PetscFunctionReturn(0);
}

PetscErrorCode AllGather::SetUp(Vec like)
{
  PetscFunctionBeginUser;
  full_.reset();
  PetscCall(VecScatterCreateToAll(like, scatter_.out(), full_.out()));
  PetscFunctionReturn(0);
}

PetscErrorCode AllGather::operator()(Vec x, Eigen::Ref<Eigen::VectorXd> out)
{
  const PetscScalar *a;
  PetscInt           n;
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(scatter_, x, full_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(scatter_, x, full_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetLocalSize(full_, &n));
  PetscCall(VecGetArrayRead(full_, &a));
  for (PetscInt i = 0; i < n; ++i) out[i] = PetscRealPart(a[i]);
  PetscCall(VecRestoreArrayRead(full_, &a));
  PetscFunctionReturn(0);
}

} // namespace squeal
