#include "squeal/core/interrupt.h"

#include <csignal>
#include <ctime>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace squeal {

namespace {

volatile std::sig_atomic_t g_signal = 0;
struct timespec            g_first{}; // when g_signal arrived

extern "C" void OnSignal(int sig)
{
  struct timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now); // async-signal-safe
  if (g_signal == sig) {
    // A duplicate within half a second (a scheduler signalling both a process and its process
    // group; Open MPI 4.1.4's mpiexec was measured to send one SIGTERM per rank) must not cut the
    // clean stop short; a user's second signal, later than that, gives up on it.
    const double since = (double)(now.tv_sec - g_first.tv_sec) + 1e-9 * (double)(now.tv_nsec - g_first.tv_nsec);
    if (since < 0.5) return;
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  g_first  = now;
  g_signal = sig;
  // Open MPI's mpiexec, told to stop, no longer reads its ranks' output (a pty): rank 0 then
  // blocks writing a progress line and never reaches the results file before the SIGKILL. From
  // here on standard output, unless it is a regular file, goes to /dev/null (the interrupted
  // write, restarted, lands there); the final message is on stderr.
  struct stat st;
  if (fstat(STDOUT_FILENO, &st) == 0 && !S_ISREG(st.st_mode)) {
    const int fd = open("/dev/null", O_WRONLY);
    if (fd >= 0) {
      dup2(fd, STDOUT_FILENO);
      close(fd);
    }
  }
}

} // namespace

PetscErrorCode InstallInterruptHandlers()
{
  PetscFunctionBeginUser;
  // Replaces PETSc's handler (installed at initialisation, it aborts on SIGTERM) and the default
  // action (SIGINT terminates): both would lose every result not yet written.
  struct sigaction sa{};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  PetscCheck(sigaction(SIGINT, &sa, nullptr) == 0 && sigaction(SIGTERM, &sa, nullptr) == 0, PETSC_COMM_SELF, PETSC_ERR_SYS,
             "cannot install the SIGINT/SIGTERM handlers");
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

PetscErrorCode InterruptPoint(MPI_Comm comm, const char *where)
{
  bool stop;
  PetscFunctionBeginUser;
  PetscCall(InterruptRequested(comm, &stop));
  PetscCheck(!stop, comm, PETSC_ERR_SIG, "interrupted by %s during %s", InterruptSignalName(), where);
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
