// A state to start from, read back from a squeal results file: -transient_start and -shoot_start.
//
// The sources, in the order `auto` tries them (where the file's run ended first), each taken only if
// it holds the model's N DOFs:
//   transient     the last record of /transient (U, V; its reactions R as the contact's warm start;
//                 the settled period, if the run settled)
//   steady        /steady_state/Z_end (the statistical steady state's end state; the period 1 / f1
//                 when its spectrum has one base, f1)
//   shooting      /shooting/Z0 (a cycle's start; its period)
//   expanded_end  /expanded/Z_end (a reduced steady state's end on the full model's DOFs; as steady)
//   expanded      /expanded/Z0 (a reduced cycle's start on the full model's DOFs; its period)
//   energy        /energy/Z0 (the energy estimate's start; its period T0)
// A file without any of them for this N is an error naming what the file has.
#pragma once

#include <petscsys.h>
#include <petscviewer.h>

#include <string>
#include <vector>

namespace squeal::io {

struct StartState {
  std::vector<PetscReal> U, dU; // N values each, on every rank
  std::vector<PetscReal> R;     // 3 n_c reactions (local t, b, n) when the source has them for n_c points; else empty
  PetscReal              period = 0; // the source's period (s), 0 if it has none
  std::string            what;       // "/shooting/Z0 of FILE", said on stdout and kept in the results
};

// The names `from` accepts, for an options list: auto and the sources above.
constexpr int            kNumStartSources = 7;
extern const char *const kStartSources[kNumStartSources];

// Reads `file` (named by `option` in messages) for a model of N DOFs and nc contact points.
// Collective; every rank gets the whole state.
PetscErrorCode ReadStartState(MPI_Comm comm, const std::string &file, const std::string &from, PetscInt N, PetscInt nc,
                              const char *option, StartState &out);
// Inside an options block (PetscOptionsBegin): -start FILE (help `help`) and -start_from under the
// block's prefix, for `owner` (the manual page).
PetscErrorCode StartOptions(PetscOptionItems *PetscOptionsObject, const char *owner, const char *help, std::string &file, std::string &from);
// Opens `file` only: a missing or foreign file fails at option time, before any model work.
PetscErrorCode CheckStartFile(MPI_Comm comm, const std::string &file, const char *option);

} // namespace squeal::io
