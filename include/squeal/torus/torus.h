// The invariant torus of a quasi-periodic motion: an invariant circle of the stroboscopic map
// (quasi-periodic shooting; Schilder, Osinga & Vogt, SIAM J. Appl. Dyn. Syst. 4 (2005) 459).
//
// A motion on a 2-torus with frequencies f1, f2 is, sampled every T = 1/f1, a circle u(theta) of
// states that the period map Phi_T rotates by rho = f2/f1 - 1 (mod 1, the modulation f2 - f1 over f1):
//     Phi_T(u(theta_j)) = u(theta_j + 2 pi rho),   theta_j = 2 pi j / M,  j = 0..M-1 (M odd),      (T.1)
// with u(theta) the trigonometric interpolant of the M unknown states u_j = u(theta_j), so
// u(theta_j + 2 pi rho) = sum_l D(theta_j + 2 pi rho - theta_l) u_l, D the Dirichlet kernel of
// order (M - 1)/2. The unknowns are (u_0..u_{M-1}, T, rho); the two more equations fix the two
// symmetries of a solution (any shift in theta, any time shift along the flow) against the start
// circle u^0:
//     sum_j <u_j - u^0_j, d u^0 / d theta (theta_j)> = 0,   sum_j <u_j - u^0_j, G(u^0_j)> = 0   (T.2)
// G the vector field, from a short flow (Phi_tau(u) - u) / tau. The states are scaled by s (a
// weight per component, so that displacements and velocities count alike) before the norms.
// SNES (prefix torus_) solves (T.1)-(T.2) by Newton with matrix-free Jacobian products (MFFD,
// M period flows each) and GMRES without preconditioner; every residual costs M period flows.
//
// The start circle comes from a stroboscopic sequence z_k = Phi_T^k(z_0) of the settled motion:
// each z_k sits at angle 2 pi rho k on the circle, and a least-squares Fourier fit of order
// (M - 1)/2 in that angle gives u^0 (FitCircle). rho itself is the strongest frequency of that
// sequence (EstimateRotation).
// In squeal (Run): a transient (its -transient_* options) from the mode runs the start-up, then
// the period map is the theta-method (integration/theta.h) with -torus_steps steps of h = T/steps.
#pragma once

#include "squeal/integration/theta.h"
#include "squeal/integration/transient.h"
#include "squeal/io/h5.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/stability.h"

#include <petscsnes.h>

#include <Eigen/Dense>

#include <functional>
#include <string>
#include <vector>

namespace squeal {

struct TorusResult {
  bool                   converged = false;
  std::string            reason;
  PetscInt               M = 0, n = 0;                  // points on the circle, state size
  PetscInt               iterations = 0, flows = 0;     // Newton iterations, period flows in all
  PetscInt               krylov_iterations = 0;
  bool                   preconditioned = false;
  PetscReal              T = 0, rho = 0;                // stroboscopic period and rotation number
  PetscReal              f1 = 0, f2 = 0;                // 1/T and (1 + rho)/T (Hz)
  PetscReal              T0 = 0, rho0 = 0;              // the start's
  PetscReal              residual0 = 0, residual = 0;   // ||(T.1)|| / ||u|| (scaled) at the start and at the end
  std::vector<PetscReal> residual_history;              // per Newton iterate
  PetscReal              seconds = 0, seconds_per_residual = 0;
  PetscInt               snapshots = 0, startup_periods = 0;
  std::vector<PetscReal> circle;                        // M x n, row j = u_j (natural order), rank 0
  std::vector<PetscReal> snapshot_signal;               // the signal DOF along the stroboscopic sequence, rank 0
  PetscInt               signal_dof = -1;
  // An estimated start refined once (Run, -torus_refine_its): the first pass's start, its Newton
  // iterates and time; T0, rho0, residual_history and the counts above are then the second pass's.
  PetscInt               contact_unconverged = 0;    // flow steps whose contact solve did not converge (noise for MFFD)
  PetscReal              contact_residual_max = 0;
  PetscInt               retries = 0;                // new starts after Newton did not converge (-torus_retries)
  std::vector<PetscReal> retry_history;              // ||F||/||u|| where each earlier start ended
  bool                   refined = false;
  PetscReal              refine_T0 = 0, refine_rho0 = 0, refine_seconds = 0;
  PetscInt               refine_iterations = 0, refine_krylov = 0;
  std::vector<PetscReal> refine_history;
};

class TorusSolver {
public:
  // z1 = Phi_T(z0), states in full on every rank (collective).
  using FlowFn = std::function<PetscErrorCode(const Eigen::VectorXd &z0, PetscReal T, Eigen::VectorXd &z1)>;

  explicit TorusSolver(MPI_Comm comm) : comm_(comm) {}
  ~TorusSolver();
  // -torus_points, -torus_f1, -torus_f2, -torus_startup_periods, -torus_snapshots, -torus_steps,
  // -torus_refine_its, -torus_rtol, -torus_monitor; the SNES and KSP under -torus_ (-torus_snes_max_it, -torus_ksp_*).
  PetscErrorCode SetFromOptions();

  // Newton on (T.1)-(T.2) from the circle (n x M, column j = u_j), T0 and rho0; s: the scale of
  // each state component. Not converging is reported in res (and is no error).
  // mono (optional, n x n, unscaled): an approximate monodromy for the preconditioner. With it GMRES
  // is preconditioned (right) by the block-circulant P = I (x) mono - R(rho) (x) I, which the DFT over
  // the M points splits into M solves with mono - e^{i 2 pi k rho} (k = -(M-1)/2..(M-1)/2): the
  // weakly damped modes, whose multipliers lie on the unit circle, are then no longer GMRES's to find.
  PetscErrorCode Solve(const FlowFn &flow, const Eigen::VectorXd &s, const Eigen::MatrixXd &circle, PetscReal T0, PetscReal rho0,
                       TorusResult &res, const Eigen::MatrixXd *mono = nullptr);
  // In squeal: start-up transient, stroboscopic sequence, fit, Solve.
  PetscErrorCode Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, ThetaIntegrator &ti,
                     TransientAnalysis &transient, TorusResult &res);
  PetscErrorCode View(const TorusResult &res, PetscViewer viewer) const;
  PetscErrorCode ViewFromOptions(const TorusResult &res) const;
  PetscErrorCode Write(const TorusResult &res, io::H5Writer &out) const;

  // The pieces, public for tests.
  // u(theta_j + 2 pi rho) = sum_l R_jl u_l (the trigonometric interpolant, M odd), and d/d theta at theta_j.
  static Eigen::MatrixXd ShiftMatrix(PetscInt M, PetscReal rho);
  static Eigen::MatrixXd DerivativeMatrix(PetscInt M);
  // Least-squares Fourier fit of order (M - 1)/2 of the sequence z_k (columns) placed at 2 pi rho k.
  static Eigen::MatrixXd FitCircle(const Eigen::MatrixXd &z, PetscReal rho, PetscInt M);
  // The rotation number in (0, 1/2] ... (0, 1): the strongest frequency (cycles per sample) of the
  // sequence's first principal component, refined between DFT bins.
  static PetscReal EstimateRotation(const Eigen::MatrixXd &z);

  PetscInt  points = 15, startup_periods = 300, snapshots = PETSC_DECIDE, steps = 200;
  // -torus_refine_its: without -torus_f2 (an estimated start), Newton iterations after which the
  // stroboscopic sequence and the start circle are made again at Newton's T and rho (0: never).
  PetscInt  refine_its = 0;
  // -torus_retries: Newton not converged, new starts further on the motion (Run).
  PetscInt  retries = 1;
  // -torus_auto: -analyses auto goes on to the torus when the statistical steady state calls the
  // motion quasi-periodic with two bases (started from those lines and the steady state's end state).
  PetscBool in_auto = PETSC_TRUE;
  PetscReal f1 = 0, f2 = 0, rtol = 1e-6;
  PetscBool monitor = PETSC_FALSE;
  // -torus_linear_pc: in Run, precondition with the monodromy of the steady sliding linearisation
  // (the step tangent at the equilibrium reactions, raised to -torus_steps; dense back end).
  PetscBool linear_pc = PETSC_TRUE;

private:
  struct Ctx;
  friend struct TorusCallbacks;
  MPI_Comm comm_;
  SNES     snes_ = nullptr;
};

} // namespace squeal
