// The squeal program:
//   squeal -scene FILE.yaml [-analyses LIST] [-output FILE.h5] [any PETSc/SLEPc option]
// The scene (YAML) fills PETSc's options database; the command line overrides it. Every
// component reads its options before any analysis runs, so a mistyped option stops the run at
// once; only the requested analyses (and what they need) are computed and written.
#pragma once

#include <petscsys.h>

namespace squeal {

extern const char kHelp[];

// Everything between SlepcInitialize and SlepcFinalize; returns non-zero on any error, after
// writing whatever results were complete.
PetscErrorCode RunApp(int argc, char **argv);

} // namespace squeal
