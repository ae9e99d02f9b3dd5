// Floquet multipliers of the periodic orbit found by shooting (docs/method.md §6).
//
// The multipliers are the eigenvalues of the monodromy matrix, the Jacobian of the period map
// Z0 -> Z(Z0, T) at the converged orbit. Three routes, chosen by Compute:
//   - dense (2N <= -floquet_dense_max): the whole monodromy, from the exact tangents of the
//     steps (MonodromyExact: statuses held fixed, dense theta back end) or from 2N forward
//     differences (Monodromy: delta = fd_step ||U0|| for displacement columns, fd_step ||dU0|| for
//     velocity columns);
//   - matrix-free (larger models): the -floquet_nev largest multipliers by SLEPc on a
//     MatShell whose product is a forward difference of the flow or an exact tangent integration;
//   - block Arnoldi: the exact-tangent case of the matrix-free route, -floquet_block columns
//     per tangent integration.
// The discrete period map is only piecewise smooth along the orbit (the step that holds an impact
// moves with the phase), so its own trivial multiplier misses 1 by ~1e-3 whatever h. The monodromy
// is therefore averaged over -floquet_phases starting points spread over one step of the
// orbit (Z0 + s (Z1 - Z0), s in [0, 1)): the average is the derivative of the phase-averaged map,
// whose trivial multiplier closes on 1 (docs/numerics.md). The trivial multiplier (closest to 1)
// is reported as an accuracy check, and the verdict carries its error (FloquetVerdict).
//
// FloquetSolver runs on the flow and the tangents of its Shooting (the integrator set up at the
// orbit's period, the stored trajectory of the last residual), which owns it and calls its
// SetFromOptions from its own. Options prefix "floquet_" (-floquet_nev, ..., the eigensolver under
// -floquet_eps_*); the former names -shoot_floquet_* are still read, with a deprecation warning.
#pragma once

#include "squeal/core/handle.h"

#include <Eigen/Dense>
#include <petscsys.h>
#include <petscviewer.h>

#include <complex>
#include <string>
#include <utility>
#include <vector>

namespace squeal {

class Shooting;
struct ShootingResult;

// The Floquet verdict carries its error. The trivial multiplier would be exactly 1 for an exact
// monodromy, so |L_trivial - 1| measures the discretisation's error on the multipliers; where
// the phase average and the Jacobian at Z0 disagree (a status change moving within its step),
// their difference in the largest non-trivial |L| is an error too. The margin is
// 1 - largest non-trivial |L|; the verdict is "undecided" when |margin| <= error.
struct FloquetVerdictResult {
  const char *word;
  PetscReal   margin, error;
};
FloquetVerdictResult FloquetVerdict(PetscReal largest_nontrivial, PetscReal trivial_error, PetscReal phase_spread = 0);
// Block Arnoldi's stopping residual (-floquet_tol, -floquet_tol_error): tol, or tol_error times the
// distance from 1 of the Ritz value nearest it (the trivial multiplier's error, when within 0.1 of
// 1), if larger, at most 1e-4.
PetscReal FloquetArnoldiTolerance(PetscReal tol, PetscReal tol_error, const std::vector<std::complex<PetscReal>> &ritz);
// The block count at which block Arnoldi next computes its Ritz values, after a check at `blocks`
// whose worst residual `worst` missed `stop`: every block up to 8, then every ceil(count / 8)-th,
// or sooner where the residual, falling geometrically from `prev_worst` at the check before
// (`prev_blocks`, 0 for none), reaches `stop` sooner.
Eigen::Index FloquetNextCheck(Eigen::Index blocks, Eigen::Index prev_blocks, PetscReal prev_worst, PetscReal worst, PetscReal stop);
// At -floquet_max_dim's block count `blocks`, with the residual `worst` above `stop`: the block
// count at which the residual, falling geometrically as between the check at `prev_blocks`
// (`prev_worst`) and this one, reaches `stop`; 0 where it does not fall (or no check before).
Eigen::Index FloquetBlocksToReach(Eigen::Index blocks, Eigen::Index prev_blocks, PetscReal prev_worst, PetscReal worst, PetscReal stop);

class FloquetSolver {
public:
  explicit FloquetSolver(Shooting &sh) : sh_(sh) {}
  // The prefix of this object's options and of its eigensolver's (default "floquet_").
  PetscErrorCode SetOptionsPrefix(const char *prefix)
  {
    prefix_ = prefix ? prefix : "";
    return 0;
  }
  const std::string &OptionsPrefix() const { return prefix_; }
  // -floquet_compute, -floquet_dense_max, -floquet_exact, -floquet_phases, -floquet_bisect_interp,
  // -floquet_nev, -floquet_block, -floquet_monitor, -floquet_max_dim, -floquet_max_dim_extend, -floquet_tol, -floquet_tol_error; -shoot_floquet
  // and -shoot_floquet_* are renamed to them first (PetscOptionsDeprecated).
  PetscErrorCode SetFromOptions();
  // The multipliers of res and the verdict (ASCII viewers only), as part of the shooting's report.
  PetscErrorCode View(const ShootingResult &res, PetscViewer viewer) const;

  // The settings, each an option of the same name under the prefix.
  PetscBool compute   = PETSC_TRUE; // -floquet_compute: the multipliers at convergence of shooting
  PetscInt  dense_max = 400;        // largest 2N for the dense monodromy; above: matrix-free
  PetscBool exact     = PETSC_TRUE; // monodromy from the exact step tangents (dense back end)
  PetscInt  phases    = PETSC_DECIDE;
  // Width of phase interval below which the bisection of the phase pieces starts its flows from
  // interpolated states instead of from the start of the period.
  PetscReal bisect_interp = 1.0 / 32;
  PetscInt  nev = 6, block = 16, max_dim = 640; // matrix-free route: multipliers; block Arnoldi's columns and basis
  // -floquet_max_dim_extend: past max_dim, block Arnoldi goes on up to this fraction more columns
  // where the residuals' geometric decay reaches the tolerance within them (0: max_dim is a hard cap).
  // The size-1 brake: 1.67e-3 at 35 blocks, 1.56e-4 at 40 (the cap), converged at 46 (3.2e-6).
  PetscReal max_dim_extend = 0.5;
  PetscReal tol     = 1e-8;                     // block Arnoldi: relative residual of the nev largest
  // ... or this fraction of the trivial multiplier's distance from 1, if larger (at most 1e-4): that
  // distance is the step's own error on the multipliers, the verdict's error bar (0: tol only).
  PetscReal tol_error = 1e-2;
  PetscBool monitor = PETSC_FALSE;

  // The multipliers of the orbit from (U0, dU0) with period T into res (floquet, floquet_at_z0,
  // the trivial one, the verdict); the route as above. The orbit's flow is the shooting's last.
  PetscErrorCode Compute(Vec U0, Vec dU0, PetscReal T, ShootingResult &res);
  // The dense monodromy averaged over `phases` starting points (as -floquet_phases;
  // PETSC_DECIDE: adaptive), by forward differences of the flow.
  PetscErrorCode Monodromy(Vec U0, Vec dU0, PetscReal T, PetscInt phases, Eigen::MatrixXd &Mono);
  // The same matrix as the product of the exact step tangents along one flow (docs/method.md §6),
  // statuses held fixed: no finite-difference error, one flow instead of 2N + 1. Dense back end.
  PetscErrorCode MonodromyExact(Vec U0, Vec dU0, PetscReal T, PetscInt phases, Eigen::MatrixXd &Mono);
  // The nev largest multipliers by SLEPc (Krylov-Schur, largest magnitude) on a MatShell
  // whose product is a forward difference of the flow: for models too large for 2N integrations.
  PetscErrorCode MatrixFree(Vec U0, Vec dU0, PetscReal T, std::vector<std::complex<PetscReal>> &mult);
  // The exact-tangent case of it (one phase, dense back end) by block Arnoldi: each tangent
  // integration carries -floquet_block columns, so the step matrices are read once for all
  // of them (matrix-matrix instead of matrix-vector products); no restart, the basis grows until
  // the nev largest Ritz values have relative residuals below tol (or tol_error |L_trivial - 1|).
  PetscErrorCode BlockArnoldi(std::vector<std::complex<PetscReal>> &mult);
  // A new model may have another size: the one-step shift is rebuilt on first use.
  void Reset() { shiftU_.reset(), shiftdU_.reset(); }

private:
  class PhaseBisection; // the search for PhaseBreaks
  Shooting   &sh_;
  std::string prefix_ = "floquet_";
  // Nodes s and weights of the average over one step of the orbit: K phases (-floquet_phases;
  // PETSC_DECIDE: adaptive when adaptive_default, else one).
  PetscErrorCode SetUpPhases(Vec U0, Vec dU0, PetscReal T, PetscInt K, bool adaptive_default);
  // K = 0: the values of s in [0, 1] where a status change of the flow moves to another step.
  PetscErrorCode PhaseBreaks(Vec U0, Vec dU0, PetscReal T, std::vector<PetscReal> &breaks);
  PetscErrorCode ShiftAlongOrbit(Vec U0, Vec dU0, PetscReal T);            // shift{U,dU}_ = one step from Z0, minus Z0
  PetscErrorCode PhaseStart(Vec U0, Vec dU0, PetscReal s, Vec U, Vec dU); // Z0 + s (shift)
  // y = M v, the MatShell product of the matrix-free route.
  static PetscErrorCode MonodromyMult(Mat A, Vec v, Vec y);

  std::vector<PetscReal> phase_s_, phase_w_;
  VecH                   shiftU_, shiftdU_;
  VecH                   mono_U0_, mono_dU0_;                  // Z0 of the matrix-free monodromy
  std::vector<std::pair<VecH, VecH>> mono_start_, mono_base_; // per phase: start and its flow
  PetscReal              mono_T_     = 0;
  bool                   mono_exact_ = false; // matrix-free products from exact tangents along the flow from mono_x_
  VecH                   mono_x_;
  PetscInt               products_ = 0; // block tangent integrations of the last block Arnoldi
};

} // namespace squeal
