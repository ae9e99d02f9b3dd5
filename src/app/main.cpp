#include "squeal/app/app.h"
#include "squeal/core/blas_core.h"
#include "squeal/core/errors.h"
#include "squeal/core/interrupt.h"

#include <slepcsys.h>

#include <cstdlib>

int main(int argc, char **argv)
{
  // First, before MPI or PETSc start: OpenBLAS's generic kernels on a CPU it does not know
  // (core/blas_core.cpp) cost 1.7x on the reduction and the eigensolvers.
  squeal::RestartWithMatchingBlasKernels(argv);
  // Started without mpiexec, Open MPI's MPI_Init launches a helper daemon (orted) for dynamic
  // process support that squeal never uses; the wait for it was 0.2-0.3 s of a 0.6 s 3-DOF run.
  // An isolated singleton skips it. Only when not under a launcher, and never over the user's own
  // setting; other MPI implementations ignore the variable.
  if (!std::getenv("OMPI_COMM_WORLD_SIZE") && !std::getenv("PMIX_RANK")) setenv("OMPI_MCA_ess_singleton_isolated", "1", 0);
  PetscCall(SlepcInitialize(&argc, &argv, nullptr, squeal::kHelp));
  PetscErrorCode ierr = squeal::PushErrorHandler();
  if (!ierr) ierr = squeal::InstallInterruptHandlers();
  if (!ierr) {
    ierr = squeal::RunApp(argc, argv);
    PetscCall(PetscPopErrorHandler());
  }
  PetscCall(SlepcFinalize());
  return ierr ? 1 : 0;
}
