#include "squeal/core/errors.h"

#include <cstdio>

namespace squeal {

namespace {

PetscErrorCode OneLineHandler(MPI_Comm comm, int line, const char *fun, const char *file, PetscErrorCode n,
                              PetscErrorType p, const char *mess, void *)
{
  // Only the place where the error was raised has the message; the callers that pass it
  // upwards (PETSC_ERROR_REPEAT) stay silent.
  if (p != PETSC_ERROR_INITIAL) return n;
  PetscMPIInt rank = 0, initialized = 0;
  MPI_Initialized(&initialized);
  if (initialized && comm != MPI_COMM_NULL) MPI_Comm_rank(comm, &rank);
  if (rank == 0) {
    if (mess && mess[0]) {
      std::fprintf(stderr, "squeal: error: %s\n", mess);
    } else {
      const char *text = nullptr;
      PetscErrorMessage(n, &text, nullptr);
      std::fprintf(stderr, "squeal: error: %s (in %s, %s:%d; rerun with -squeal_traceback)\n", text ? text : "unknown",
                   fun, file, line);
    }
    std::fflush(stderr);
  }
  return n;
}

} // namespace

PetscErrorCode PushErrorHandler()
{
  PetscBool traceback = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-squeal_traceback", &traceback, nullptr));
  if (traceback) PetscCall(PetscPushErrorHandler(PetscTraceBackErrorHandler, nullptr));
  else PetscCall(PetscPushErrorHandler(OneLineHandler, nullptr));
  PetscFunctionReturn(0);
}

} // namespace squeal
