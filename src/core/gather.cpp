#include "squeal/core/gather.h"

namespace squeal {

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
