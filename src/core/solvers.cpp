#include "squeal/core/solvers.h"

namespace squeal {

PetscErrorCode UseDirectSolver(KSP ksp, Factorisation kind)
{
  PC          pc;
  MPI_Comm    comm;
  PetscMPIInt size;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)ksp, &comm));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCall(KSPSetType(ksp, KSPPREONLY));
  PetscCall(KSPGetPC(ksp, &pc));
  // PETSc's own Cholesky avoids MUMPS's fixed cost per solve (~60 us at small N), which matters
  // in the time stepper; MUMPS serves everything that needs pivoting or distribution.
  if (kind == Factorisation::SPD && size == 1) {
    PetscCall(PCSetType(pc, PCCHOLESKY));
    PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERPETSC));
  } else {
    PetscCall(PCSetType(pc, PCLU));
    PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
