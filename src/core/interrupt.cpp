#include "squeal/core/interrupt.h"

#include <csignal>

namespace squeal {

namespace {

volatile std::sig_atomic_t g_signal = 0;

extern "C" void OnSignal(int sig)
{
  if (g_signal == sig) { // asked twice: give up on a clean stop
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  g_signal = sig;
}

} // namespace

PetscErrorCode InstallInterruptHandlers()
{
  PetscFunctionBeginUser;
  // Replaces PETSc's handler (installed at initialisation, it aborts on SIGTERM) and the default
  // action (SIGINT terminates): both would lose every result not yet written.
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  PetscFunctionReturn(0);
}

PetscErrorCode InterruptRequested(MPI_Comm comm, bool *stop)
{
  PetscMPIInt size, here, any;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  here = g_signal != 0;
  if (size > 1) PetscCallMPI(MPI_Allreduce(&here, &any, 1, MPI_INT, MPI_MAX, comm));
  else any = here;
  *stop = any != 0;
  PetscFunctionReturn(0);
}

int InterruptSignal() { return (int)g_signal; }

const char *InterruptSignalName()
{
  switch (g_signal) {
  case SIGINT: return "SIGINT";
  case SIGTERM: return "SIGTERM";
  case 0: return "";
  default: return "a signal";
  }
}

} // namespace squeal
