// Stopping a long run cleanly on SIGINT / SIGTERM (and SIGPIPE: the reader of standard output has
// gone, as after `squeal ... | head`).
//
// The application installs handlers once; a signal only sets a flag. Long loops (time steps,
// Newton iterations, sweep points) poll the flag between steps, stop after the step in hand, and
// the application writes and closes the results file with what was computed, says so, and exits
// non-zero. A second signal of the same kind, half a second or more after the first, kills the
// process the default way (for a run stuck inside one step); if the results file was consistent on
// disk at that moment (flushed, nothing written since), it first moves it to its final name, so
// that the results of the analyses already finished stay readable.
#pragma once

#include <petscsys.h>

namespace squeal {

// Installs the SIGINT, SIGTERM and SIGPIPE handlers (call once, after PetscInitialize).
PetscErrorCode InstallInterruptHandlers();

// Collective on comm: true on every rank if a signal reached any rank, so that all ranks leave
// their loop at the same step. Cheap (no MPI call on one rank).
PetscErrorCode InterruptRequested(MPI_Comm comm, bool *stop);

// Collective: on every rank, fails with PETSC_ERR_SIG "interrupted by SIGTERM during <where>"
// once a signal has reached any rank. For loops inside PETSc/SLEPc solvers (called from their
// monitors), which cannot stop "after the step in hand": the error unwinds to the application,
// whose results file keeps what earlier analyses wrote (status "interrupted ...").
PetscErrorCode InterruptPoint(MPI_Comm comm, const char *where);

// The results file a second signal salvages (rank 0's writer, io/h5.cpp): its temporary and the
// name it gets (the target, or the ".failed.h5" sibling of a complete file). nullptr: none.
// Ready: the temporary is consistent on disk now (just flushed, nothing written since).
void InterruptSalvage(const char *part, const char *target);
void InterruptSalvageReady(bool ready);

// The signal received on this rank (0 if none), and its name ("SIGINT", "SIGTERM").
int         InterruptSignal();
const char *InterruptSignalName();

} // namespace squeal
