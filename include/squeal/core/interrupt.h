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

// InterruptPoint once per step of a loop whose steps cost anything from a microsecond (a 3-DOF
// step) to a second (a block of tangent columns of a reduced brake), at a pace set by the time
// the steps take. Under mpiexec a signal has to be obeyed within about a second: Open MPI passes
// SIGTERM on and sends SIGKILL one second later (odls_base_sigkill_timeout), and a fixed count
// (every 256 steps) let 30 ms steps of a 1594-DOF reduced brake be killed before their poll,
// with every result lost. On one rank a poll is a flag test, made every step; on several ranks
// the ranks agree in each poll (one Allreduce) on how many steps to the next, about kSpacing
// seconds of their slowest rank's work, never more than 4 times the last count.
class InterruptPacer {
public:
  static constexpr double kSpacing = 0.05; // seconds between polls on several ranks

  InterruptPacer(MPI_Comm comm, const char *where);
  // Collective: every rank calls it once per step, before the step.
  PetscErrorCode Step() { return ++count_ < every_ ? PetscErrorCode(0) : Poll(); }
  PetscInt       Polls() const { return polls_; }

private:
  PetscErrorCode Poll();

  MPI_Comm    comm_;
  const char *where_;
  PetscMPIInt size_  = 1;
  PetscInt    count_ = 0, every_ = 1, polls_ = 0;
  double      last_  = 0; // MPI_Wtime of the last poll
};

// The results file a second signal salvages (rank 0's writer, io/h5.cpp): its temporary and the
// name it gets (the target, or the ".failed.h5" sibling of a complete file). nullptr: none.
// Ready: the temporary is consistent on disk now (just flushed, nothing written since). Returns
// false once the file has been salvaged: it must not be written or closed again.
//
// Under Open MPI's mpiexec the salvage also comes without a second signal: mpiexec passes SIGINT
// or SIGTERM on to the ranks as SIGTERM and kills them one second later
// (odls_base_sigkill_timeout), and some steps of a large model take longer than that between two
// polls (a step set-up, a factorisation). Half a second before the kill, if the run has not begun
// its last write, a watchdog thread moves the consistent temporary to its name, as the second
// signal would; a run that reaches its poll in time writes its results as usual.
void InterruptSalvage(const char *part, const char *target);
bool InterruptSalvageReady(bool ready);
bool InterruptSalvaged();

// The signal received on this rank, or learnt from another rank in a collective poll (0 if none),
// and its name ("SIGINT", "SIGTERM").
int         InterruptSignal();
const char *InterruptSignalName();

} // namespace squeal
