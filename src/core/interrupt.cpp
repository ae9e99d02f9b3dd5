#include "squeal/core/interrupt.h"

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <thread>

#include <fcntl.h>
#include <semaphore.h>
#include <sys/stat.h>
#include <unistd.h>

namespace squeal {

namespace {

volatile std::sig_atomic_t g_signal = 0;
// The signal another rank received, learnt in a collective poll (a batch system or a user may
// signal one rank only): for the message and the results file's status on every rank. Not the
// handler's g_signal, whose "second signal" logic is about this process's own signals.
int g_remote = 0;
struct timespec            g_first{}; // when g_signal arrived
// The salvage: g_part and g_target set only in state kBusy, read by the handler or the watchdog
// only after they moved the state from kReady to kSalvaged (lock-free, so async-signal-safe).
enum : int { kBusy = 0, kReady = 1, kSalvaged = 2 };
char             g_part[4096], g_target[4096];
std::atomic<int> g_state{kBusy};
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs a lock-free state");
// The watchdog under Open MPI's mpiexec (InterruptSalvage in the header): woken by the handler.
sem_t  g_wake;
bool   g_watch = false;
double g_grace = 0.5; // seconds from the signal to the salvage

// write(2) of a C string (async-signal-safe, unlike stdio).
void SafeWrite(const char *s) { (void)!write(STDERR_FILENO, s, std::strlen(s)); }

// Claims the consistent temporary for a salvage (kReady -> kSalvaged) and renames it.
bool ClaimAndRename()
{
  int ready = kReady;
  return g_state.compare_exchange_strong(ready, kSalvaged) && std::rename(g_part, g_target) == 0;
}

void Salvage(int sig)
{
  const char *name = sig == SIGINT ? "SIGINT" : sig == SIGPIPE ? "SIGPIPE" : "SIGTERM";
  if (g_state.load() == kSalvaged) return; // the watchdog did it
  if (g_part[0] == 0) return;
  SafeWrite("squeal: second ");
  SafeWrite(name);
  if (ClaimAndRename()) {
    // The file says "running (... written after X)": the analyses up to X are complete in it.
    SafeWrite(": stopped at once; the results written so far are in ");
    SafeWrite(g_target);
    SafeWrite("\n");
  } else {
    SafeWrite(": stopped at once, in the middle of a write to the results file; what it holds is left in ");
    SafeWrite(g_part);
    SafeWrite(" (it may not be readable)\n");
  }
}

extern "C" void OnSignal(int sig)
{
  struct timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now); // async-signal-safe
  // The reader of standard output has gone (`squeal ... | head`): stop like SIGTERM, keeping the
  // results (PETSc's handler aborted with a traceback and left the hidden temporary). Later
  // writes to a broken pipe (stderr under `2>&1 | head`) just fail instead of signalling again.
  if (sig == SIGPIPE) std::signal(SIGPIPE, SIG_IGN);
  if (g_signal == sig) {
    // A duplicate within half a second (a scheduler signalling both a process and its process
    // group; Open MPI 4.1.4's mpiexec was measured to send one SIGTERM per rank) must not cut the
    // clean stop short; a user's second signal, later than that, gives up on it.
    const double since = (double)(now.tv_sec - g_first.tv_sec) + 1e-9 * (double)(now.tv_nsec - g_first.tv_nsec);
    if (since < 0.5) return;
    Salvage(sig);
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  g_first  = now;
  g_signal = sig;
  if (g_watch) sem_post(&g_wake); // async-signal-safe
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

// Waits for the first signal, then salvages the results file g_grace seconds later unless the run
// has begun writing meanwhile (its clean stop) or has gone. No MPI, no allocation, no stdio.
void Watchdog()
{
  while (sem_wait(&g_wake) != 0) {} // EINTR
  struct timespec d{(time_t)g_grace, (long)((g_grace - (double)(time_t)g_grace) * 1e9)};
  while (nanosleep(&d, &d) != 0) {}
  if (g_part[0] == 0 || g_state.load() != kReady) return;
  if (ClaimAndRename()) {
    SafeWrite("squeal: mpiexec stops the ranks one second after passing the signal on, before this step's next poll: the results written so far are in ");
    SafeWrite(g_target);
    SafeWrite("\n");
  }
}

} // namespace

PetscErrorCode InstallInterruptHandlers()
{
  PetscFunctionBeginUser;
  // Only under Open MPI's mpiexec, whose kill follows its signal (a terminal's Ctrl-C on one
  // process, or a batch system's SIGTERM with its own grace, waits for the clean stop). A
  // longer kill timeout set by the user (the MCA variable) leaves more time for the clean stop.
  if (std::getenv("OMPI_COMM_WORLD_SIZE") && sem_init(&g_wake, 0, 0) == 0) {
    if (const char *t = std::getenv("OMPI_MCA_odls_base_sigkill_timeout")) {
      char        *end = nullptr;
      const double v   = std::strtod(t, &end);
      if (end != t && v > 1) g_grace = v - 0.5;
    }
    try {
      std::thread(Watchdog).detach();
      g_watch = true;
    } catch (...) { // no thread: the polls alone, as without mpiexec
    }
  }
  // Replaces PETSc's handler (installed at initialisation, it aborts on SIGTERM) and the default
  // action (SIGINT terminates): both would lose every result not yet written.
  struct sigaction sa{};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  PetscCheck(sigaction(SIGINT, &sa, nullptr) == 0 && sigaction(SIGTERM, &sa, nullptr) == 0 && sigaction(SIGPIPE, &sa, nullptr) == 0,
             PETSC_COMM_SELF, PETSC_ERR_SYS, "cannot install the SIGINT/SIGTERM/SIGPIPE handlers");
  PetscFunctionReturn(0);
}

PetscErrorCode InterruptRequested(MPI_Comm comm, bool *stop)
{
  PetscMPIInt size, here, any;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  here = (PetscMPIInt)g_signal;
  if (size > 1) PetscCallMPI(MPI_Allreduce(&here, &any, 1, MPI_INT, MPI_MAX, comm));
  else any = here;
  if (any && !here) g_remote = any;
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

InterruptPacer::InterruptPacer(MPI_Comm comm, const char *where) : comm_(comm), where_(where)
{
  // A constructor cannot return an error code; MPI_Comm_size only fails on an invalid comm,
  // which the first poll's Allreduce would report.
  if (MPI_Comm_size(comm, &size_) != MPI_SUCCESS) size_ = 2;
  last_ = MPI_Wtime();
}

PetscErrorCode InterruptPacer::Poll()
{
  PetscFunctionBeginUser;
  count_ = 0;
  ++polls_;
  if (size_ == 1) {
    PetscCheck(g_signal == 0, comm_, PETSC_ERR_SIG, "interrupted by %s during %s", InterruptSignalName(), where_);
    PetscFunctionReturn(0);
  }
  const double now = MPI_Wtime(), dt = now - last_;
  // This rank's proposal for the next count, negated so that one MPI_MAX gives both the signal
  // and the smallest proposal (the slowest rank's pace).
  // The first poll comes before the first step (Step is called before it): its dt measures no
  // step, and growing on it (x4, capped) left the next poll 4 steps away, 0.6 s on the 400-cell
  // chain's first tangent slices, past mpiexec's second. The pace is set from the second poll on.
  const double grow = polls_ == 1 ? 1.0 : dt > 0 ? kSpacing / dt : 4.0;
  const double next = std::clamp((double)every_ * std::min(grow, 4.0), 1.0, 1e6);
  int          mine[2] = {(int)g_signal, -(int)next}, all[2];
  PetscCallMPI(MPI_Allreduce(mine, all, 2, MPI_INT, MPI_MAX, comm_));
  if (all[0] && !g_signal) g_remote = all[0];
  every_ = -all[1];
  last_  = MPI_Wtime();
  PetscCheck(all[0] == 0, comm_, PETSC_ERR_SIG, "interrupted by %s during %s", InterruptSignalName(), where_);
  PetscFunctionReturn(0);
}

void InterruptSalvage(const char *part, const char *target)
{
  // Busy first (the watchdog claims only a ready file); a salvaged one is gone to its name, and
  // no other is offered.
  for (int now = g_state.load();;) {
    if (now == kSalvaged) return;
    if (g_state.compare_exchange_weak(now, kBusy)) break;
  }
  g_part[0] = g_target[0] = 0;
  if (!part || !target || std::strlen(part) >= sizeof g_part || std::strlen(target) >= sizeof g_target) return;
  std::memcpy(g_target, target, std::strlen(target) + 1);
  std::memcpy(g_part, part, std::strlen(part) + 1);
}

bool InterruptSalvageReady(bool ready)
{
  int from = ready ? kBusy : kReady;
  g_state.compare_exchange_strong(from, ready ? kReady : kBusy);
  return g_state.load() != kSalvaged;
}

bool InterruptSalvaged() { return g_state.load() == kSalvaged; }

int InterruptSignal() { return g_signal ? (int)g_signal : g_remote; }

const char *InterruptSignalName()
{
  switch (InterruptSignal()) {
  case SIGINT: return "SIGINT";
  case SIGTERM: return "SIGTERM";
  case SIGPIPE: return "SIGPIPE";
  case 0: return "";
  default: return "a signal";
  }
}

} // namespace squeal
