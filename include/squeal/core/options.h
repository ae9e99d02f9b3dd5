// Validated options. Every real number a user gives (scene or command line) goes through
// CheckReal, so NaN, infinities and out-of-range values are rejected by name, once, at the
// place they are read.
#pragma once

#include <petscsys.h>

#include <string>

namespace squeal {

struct Range {
  PetscReal lo        = PETSC_NINFINITY;
  PetscReal hi        = PETSC_INFINITY;
  bool      lo_strict = false; // true: value must be > lo
  static Range Any() { return {}; }
  static Range Positive() { return {0.0, PETSC_INFINITY, true}; }
  static Range NonNegative() { return {0.0, PETSC_INFINITY, false}; }
  static Range Closed(PetscReal a, PetscReal b) { return {a, b, false}; }
  static Range OpenBelow(PetscReal a, PetscReal b) { return {a, b, true}; }
};

// "-model_m" style name of an option with the given prefix ("model_") and name ("-m" or "m").
std::string OptionName(const char *prefix, const char *name);

// Fails with a one-line message naming the option if v is not finite or outside r.
PetscErrorCode CheckReal(MPI_Comm comm, const char *prefix, const char *name, PetscReal v, const Range &r);

// Fails naming the options nobody read (mistyped or unknown), listing up to five. Call after every
// component has read its options; with skip_views, options ending in "_view" (which PETSc reads
// only after a solve) are left for a final call.
PetscErrorCode CheckUnusedOptions(MPI_Comm comm, bool skip_views);

} // namespace squeal

// Inside a PetscOptionsBegin()/PetscOptionsEnd() block: read, then validate.
#define SquealOptionsReal(opt, text, man, ptr, range)                                                      \
  do {                                                                                                     \
    PetscCall(PetscOptionsReal(opt, text, man, *(ptr), ptr, NULL));                                        \
    PetscCall(squeal::CheckReal(PetscOptionsObject->comm, PetscOptionsObject->prefix, opt, *(ptr), range)); \
  } while (0)
