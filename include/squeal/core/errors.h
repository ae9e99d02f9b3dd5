// How squeal reports errors to a user running a batch job.
//
// PETSc's default handler prints a multi-line traceback for every error. For problems with the
// user's input that buries the one line that matters, so the application installs a handler
// that prints "squeal: error: <message>" once (from rank 0 of the communicator the error was
// raised on) and lets the error code travel up to main(), which exits non-zero.
// -squeal_traceback restores PETSc's traceback for debugging.
#pragma once

#include <petscsys.h>

namespace squeal {

// Installs the one-line handler (or PETSc's traceback handler if -squeal_traceback is set).
PetscErrorCode PushErrorHandler();

// For a solve that a signal may stop (InterruptPoint raises PETSC_ERR_SIG) where the caller keeps
// what was computed: PETSC_ERR_SIG passes silently to the caller, every other error is reported
// as PushErrorHandler's handler does. Pop with PetscPopErrorHandler.
PetscErrorCode PushErrorHandlerQuietOnSignal();

// Errors whose message is meant for the user (bad input); they are never internal failures.
constexpr PetscErrorCode kErrInput = PETSC_ERR_USER_INPUT;

} // namespace squeal
