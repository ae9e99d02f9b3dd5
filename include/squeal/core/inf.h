// IEEE infinity for quantities that are unbounded (the period of a zero-frequency mode, a
// completeness radius when every eigenvalue is known, an open end of a range). PETSc's
// PETSC_INFINITY is PETSC_MAX_REAL / 4, a finite sentinel (4.49e307): it passes std::isfinite and
// would be printed and written to results files as a number.
#pragma once

#include <petscsys.h>

#include <limits>

namespace squeal {
inline constexpr PetscReal kInf = std::numeric_limits<PetscReal>::infinity();
} // namespace squeal
