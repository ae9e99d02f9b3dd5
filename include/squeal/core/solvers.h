// Small helpers shared by the components that own PETSc solvers.
#pragma once

#include <petscksp.h>

#include <string>

namespace squeal {

enum class Factorisation {
  General, // non-symmetric or indefinite (saddle point): MUMPS LU, which pivots, on any ranks
  SPD      // symmetric positive definite: PETSc's Cholesky on one rank, MUMPS LU distributed
};

// KSPPREONLY with a direct factorisation chosen for the operator's kind and the communicator's
// size; set before KSPSetFromOptions, so that -prefix_pc_* still overrides it.
PetscErrorCode UseDirectSolver(KSP ksp, Factorisation kind);

// -prefix_view [viewer]: calls view(viewer) if the option is set.
template <class ViewFn>
PetscErrorCode ViewFromOptions(MPI_Comm comm, const std::string &prefix, ViewFn &&view)
{
  PetscViewer       viewer;
  PetscViewerFormat format;
  PetscBool         flg;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsGetViewer(comm, nullptr, prefix.c_str(), "-view", &viewer, &format, &flg));
  if (flg) {
    PetscCall(PetscViewerPushFormat(viewer, format));
    PetscCall(view(viewer));
    PetscCall(PetscViewerPopFormat(viewer));
    PetscCall(PetscViewerDestroy(&viewer));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
