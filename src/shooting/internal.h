// Shared by the shooting sources (shooting.cpp, pre_periods.cpp, newton.cpp, tangent.cpp); not installed.
#pragma once

#include "squeal/shooting/shooting.h"

namespace squeal {

// -log_view events: the parts of a shooting run (SNESSolve is PETSc's own), registered by
// Shooting::SetFromOptions.
namespace shoot_ev {
extern PetscLogEvent pre, floquet, tangent, flow, linear_pc;
} // namespace shoot_ev

// SNES callbacks: C functions that reach the Shooting object through their context (newton.cpp).
struct ShootingCallbacks {
  static PetscErrorCode Function(SNES, Vec x, Vec f, void *ctx);
  static PetscErrorCode Jacobian(SNES snes, Vec x, Mat, Mat, void *ctx);
  static PetscErrorCode DenseSolve(PC pc, Vec v, Vec y);
  static PetscErrorCode Mult(Mat J, Vec v, Vec y);
  static PetscErrorCode KrylovConverged(KSP ksp, PetscInt it, PetscReal rnorm, KSPConvergedReason *reason, void *ctx);
  static PetscErrorCode Update(SNES snes, PetscInt);
  static PetscErrorCode Converged(SNES snes, PetscInt it, PetscReal, PetscReal, PetscReal fnorm, SNESConvergedReason *reason, void *ctx);
};

} // namespace squeal
