// Validated options. Every real number a user gives (scene or command line) goes through
// CheckReal, so NaN, infinities and out-of-range values are rejected by name, once, at the
// place they are read.
#pragma once

#include "squeal/core/inf.h"

#include <petscsys.h>

#include <string>
#include <vector>

namespace squeal {

struct Range {
  PetscReal lo        = -kInf;
  PetscReal hi        = kInf;
  bool      lo_strict = false; // true: value must be > lo
  static Range Any() { return {}; }
  static Range Positive() { return {0.0, kInf, true}; }
  static Range NonNegative() { return {0.0, kInf, false}; }
  static Range Closed(PetscReal a, PetscReal b) { return {a, b, false}; }
  static Range OpenBelow(PetscReal a, PetscReal b) { return {a, b, true}; }
};

// "-model_m" style name of an option with the given prefix ("model_") and name ("-m" or "m").
std::string OptionName(const char *prefix, const char *name);

// Fails with a one-line message naming the option if v is not finite or outside r.
PetscErrorCode CheckReal(MPI_Comm comm, const char *prefix, const char *name, PetscReal v, const Range &r);

// Names the options nobody read (mistyped or unknown), listing up to five. Call after every
// component has read its options; with skip_views, options ending in "_view" (which PETSc reads
// only after a solve) are left for a final call, and the check fails. Without it (the final call,
// after every result is written) it warns on stderr instead: a viewer or monitor of an analysis
// the run did not do must not turn a complete run into a failed one.
PetscErrorCode CheckUnusedOptions(MPI_Comm comm, bool skip_views);

// The same check in the first second of a run, before any model is built: only squeal's own
// options (-model_, -contact_, -reduce_, -stab_, -eq_, -sweep_, -theta_, -transient_, -energy_,
// -shoot_, -cont_ prefixes) that are not options of a PETSc/SLEPc object under them (_ksp_, _pc_,
// _eps_, ...: read when that object is set up, after the model is built) are judged here; the
// rest waits for CheckUnusedOptions.
PetscErrorCode CheckUnknownSquealOptions(MPI_Comm comm);

// Parses a YAML file (rank 0) and fails naming the file, line and column of a syntax error;
// PETSc's own loader says only "YAML parser loading error". Collective.
PetscErrorCode CheckYAMLFile(MPI_Comm comm, const char *path);

// Checks collected while an options block is open and run after PetscOptionsEnd(): returning
// from inside the block would leak what PETSc allocated for it.
class OptionChecks {
public:
  void Add(const char *prefix, const char *name, const PetscReal *v, const Range &r)
  {
    items_.push_back({prefix ? prefix : "", name, v, r});
  }
  PetscErrorCode Run(MPI_Comm comm) const;

private:
  struct Item {
    std::string      prefix, name;
    const PetscReal *v;
    Range            r;
  };
  std::vector<Item> items_;
};

} // namespace squeal

// Inside a PetscOptionsBegin()/PetscOptionsEnd() block: read, and queue the validation in
// `checks` (an OptionChecks), to be run after PetscOptionsEnd().
#define SquealOptionsReal(opt, text, man, ptr, range, checks)                   \
  do {                                                                           \
    PetscCall(PetscOptionsReal(opt, text, man, *(ptr), ptr, NULL));              \
    (checks).Add(PetscOptionsObject->prefix, opt, ptr, range);                   \
  } while (0)
