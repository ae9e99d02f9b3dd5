// A second signal (issue 20, item 1): the process is stuck (it no longer polls), the user signals
// again half a second later. The results file must then be readable under its name if it was
// consistent on disk (just flushed), and left as the temporary, said so, if a write was in hand.
//
//   interrupt_salvage FILE flushed|writing|complete|stuck
//
// Writes /stability/value = 42 and a checkpoint's status, flushes, then (mode "writing") starts a
// further write without flushing; raises SIGTERM, waits 0.6 s as a stuck run would, raises it again
// and must die by it. Mode "complete" writes a complete file and exits 0 (the one a salvage must
// not replace). Mode "stuck" (run under Open MPI's mpiexec, which kills its ranks a second after
// passing a signal on) says "flushed" on stdout and computes without a poll until the watchdog
// has salvaged the file (at most 10 s), then reaches its poll late, as a long step would: the
// error unwinds through the writer, which must leave the salvaged file as it was. The checker
// (check_interrupt_salvage.py) reads what is left.
#include "squeal/core/interrupt.h"
#include "squeal/io/h5.h"

#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>

int main(int argc, char **argv)
{
  PetscCall(PetscInitialize(&argc, &argv, nullptr, "interrupt_salvage FILE flushed|writing|complete"));
  PetscCheck(argc == 3 && (!std::strcmp(argv[2], "flushed") || !std::strcmp(argv[2], "writing") || !std::strcmp(argv[2], "complete") ||
                           !std::strcmp(argv[2], "stuck")),
             PETSC_COMM_SELF, PETSC_ERR_ARG_WRONG, "usage: interrupt_salvage FILE flushed|writing|complete|stuck");
  PetscCall(squeal::InstallInterruptHandlers());
  {
    squeal::io::H5Writer out;
    PetscCall(out.Open(PETSC_COMM_SELF, argv[1]));
    PetscCall(out.WriteAttribute("/stability", "value", (PetscReal)42));
    PetscCall(out.SetStatus("running (complete up to the stability analysis)"));
    PetscCall(out.Flush());
    if (!std::strcmp(argv[2], "complete")) {
      PetscCall(out.SetStatus("complete"));
      PetscCall(out.Close());
      PetscCall(PetscFinalize());
      return 0;
    }
    if (!std::strcmp(argv[2], "stuck")) {
      std::printf("flushed\n");
      std::fflush(stdout);
      const struct timespec tick = {0, 10000000};
      for (int i = 0; i < 1000 && !squeal::InterruptSalvaged(); ++i) nanosleep(&tick, nullptr);
      PetscCall(squeal::InterruptPoint(PETSC_COMM_SELF, "the test's stuck step")); // late: after the salvage
      PetscCall(out.SetStatus("complete"));
      PetscCall(out.Close());
      PetscCall(PetscFinalize());
      return 0;
    }
    if (!std::strcmp(argv[2], "writing")) PetscCall(out.WriteAttribute("/energy", "value", (PetscReal)1));
    std::raise(SIGTERM);
    const struct timespec stuck = {0, 600000000};
    nanosleep(&stuck, nullptr);
    std::raise(SIGTERM); // does not return
  }
  PetscCall(PetscFinalize());
  return 0; // not reached: the checker fails on a normal exit of the two other modes
}
