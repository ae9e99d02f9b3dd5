// Version differences between the PETSc/SLEPc we build against (Debian: 3.18) and newer
// releases live here and nowhere else.
#pragma once

#include <petscversion.h>
#include <slepcversion.h>

#if PETSC_VERSION_LT(3, 18, 0)
  #error "squeal needs PETSc >= 3.18"
#endif

// 3.18 functions end with PetscFunctionReturn(0); PETSC_SUCCESS arrived in 3.19.
#if PETSC_VERSION_LT(3, 19, 0)
  #define SQUEAL_SUCCESS 0
#else
  #define SQUEAL_SUCCESS PETSC_SUCCESS
#endif
