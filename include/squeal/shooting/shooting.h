// Shooting for the periodic orbit with the period as unknown (docs/method.md §6).
//
// Unknowns x = (Z0, T), Z = (U, dU) in R^{2N}. The discrete flow Z(Z0, T) runs N_s steps of the
// theta-method (integration/theta.h) with h = T / N_s, every evaluation starting the contact
// fixed point from the steady-sliding reactions, so the flow is a function of (Z0, T) alone.
// Residual (SNES, options prefix "shoot_"):
//     H = Z(Z0, T) - Z0,     p = G_a^T (Z0 - Z_a)                                         (6.1)
// with the anchor (Z_a, G_a = G(Z(Z_a, T))) reset to the current iterate at the start of every
// Newton iteration (SNESSetUpdate), so the last row linearises to the talk's phase row of (6.2).
// The Jacobian is a MatShell of matrix-free products (6.4): one period integration each, forward
// differences with step -shoot_fd_step * ||Z0|| / ||v|| (-shoot_fd_motion: relative to the motion's
// size, EquilibriumDistance), which include d Z / d T consistently; the bordered system is solved
// by GMRES (-shoot_ksp_*), preconditioned on the dense back end as the exact products are. With
// -shoot_deflate_power p > 0, SNES solves m(Z0) (H, p) = 0 instead, m = (d / d_0)^-p + shift
// (Farrell, Birkisson & Funke, SIAM J. Sci. Comput. 37 (2015) A2026), whose Jacobian is
// m J + F grad m^T: the sliding equilibrium, where H = 0 for any T, is no longer a root. Newton stops
// when ||H|| / ||Z0|| < eps1 and |dT| / T < eps2 at the same iterate x_k, dT being the Newton
// correction computed at x_k (-shoot_eps1, -shoot_eps2); that last correction is applied.
// At convergence, the Floquet multipliers of the orbit (-floquet_compute): FloquetSolver
// (floquet/floquet.h, options -floquet_*), on this object's flow and tangents.
// Sources: src/shooting/shooting.cpp (options, set-up, Solve and its steps, orbit, report), pre_periods.cpp
// (pre-periods, their period measurement), newton.cpp (residual, Jacobian products, anchor, deflation,
// SNES callbacks), tangent.cpp (flows, tangent flows, the dense bordered Jacobian, the linearised preconditioner).
#pragma once

#include "squeal/core/bordered_lu.h"
#include "squeal/core/inf.h"
#include "squeal/core/gather.h"
#include "squeal/floquet/floquet.h"
#include "squeal/integration/theta.h"
#include "squeal/io/h5.h"
#include "squeal/stability/equilibrium.h"

#include <petscsnes.h>
#include <slepceps.h>

#include <complex>
#include <functional>
#include <string>
#include <vector>

namespace squeal {

struct ShootingResult {
  bool                                 converged = false;
  std::string                          reason;
  // iterations: index k of the iterate at which (6.3) holds, ||H(x_k)|| / ||Z0|| < eps1 and the
  // correction computed at x_k has |dT| / T < eps2; that correction is applied (corrections = k + 1).
  PetscInt                             iterations = 0, corrections = 0, flow_evaluations = 0;
  // flow_evaluations counts partial flows pro rata (steps / N_s, rounded up). Of them: linear integrations of the step tangents (Jacobian products and exact
  // monodromies); set-ups of the step matrices (one per new period).
  PetscInt                             tangent_evaluations = 0, setups = 0;
  // Columns propagated by those tangent integrations (a block integration of k columns counts k),
  // and of them the recycled subspace's (-shoot_recycle), one block per Newton iteration.
  PetscInt                             tangent_columns = 0, recycled_columns = 0;
  // ... and how they split: Newton (residuals and Jacobians up to convergence) and Floquet
  // (phase pieces, their tangents, the Jacobian at Z0), each rounded up.
  PetscInt                             newton_evaluations = 0, floquet_evaluations = 0;
  // -shoot_pre_periods: periods of flow run before Newton, and the period-corrected T they ended with.
  PetscInt                             pre_periods = 0;
  PetscReal                            pre_period  = 0;
  PetscInt                             pre_coarse_periods = 0; // ... of them at -shoot_pre_steps
  PetscReal                            pre_contact_iterations = 0; // ... their contact iterations a step (-shoot_pre_fp_tol)
  // -shoot_pre_retries taken: Newton restarted after more pre-periods to a tighter return distance.
  PetscInt                             pre_retries = 0;
  // The period of the pre-periods' motion, from its returns to a Poincare section (0: no two
  // successive returns agreed), and the centre T_c of the period bracket (T_c/2, 2 T_c) Newton ran
  // in: the start period, or that measured period when it lay beyond the first-order correction.
  PetscReal                            pre_measured_period = 0, bracket_centre = 0;
  bool                                 bracket_recentred   = false;
  PetscReal                            period = 0, residual = 0; // ||H|| / ||Z0|| at the returned iterate
  std::vector<PetscReal>               residual_history, period_history;
  std::vector<PetscReal>               Z0;                 // (U, dU) on rank 0
  std::vector<std::complex<PetscReal>> floquet;            // by decreasing modulus
  std::string                          floquet_method;     // how the monodromy was obtained
  PetscInt                             floquet_phases = 0; // starting points averaged over
  // With the phase average: the multipliers of the discrete map's own Jacobian at Z0.
  std::vector<std::complex<PetscReal>> floquet_at_z0;
  PetscInt                             trivial_at_z0 = -1;
  PetscReal                            largest_at_z0 = 0;  // largest non-trivial |L| at Z0
  PetscInt                             trivial = -1;       // index of the multiplier closest to 1
  bool                                 stable_cycle = false; // largest non-trivial |L| < 1 (see the verdict)
  // The verdict with its error (FloquetVerdict, floquet/floquet.h): "stable", "unstable" or "undecided".
  std::string                          floquet_verdict;
  PetscReal                            floquet_margin = 0, floquet_error = 0;
  std::vector<PetscReal>               orbit_t, orbit_U;   // one period, rank 0
  std::vector<PetscInt>                orbit_status;       // per step and point
  std::vector<PetscReal>               peak_to_peak;       // per DOF over the orbit
  PetscReal                            frac_separated = 0, frac_stuck = 0;
};

class Shooting {
public:
  explicit Shooting(MPI_Comm comm) : comm_(comm) {}
  ~Shooting();
  // -shoot_steps, -shoot_eps1, -shoot_eps2, -shoot_fd_step, -shoot_q_scale (start from q_scale * q0 of the energy estimate),
  // and the SNES/KSP under -shoot_ (-shoot_snes_max_it, -shoot_snes_monitor, -shoot_ksp_*); then the
  // Floquet solver's (-floquet_*, FloquetSolver::SetFromOptions).
  PetscErrorCode SetFromOptions();
  // The defaults that follow from the model (N DOFs), for the options left at PETSC_DECIDE:
  // steps per period, and the pre-periods with their tolerance (shooting.cpp says why).
  static PetscInt DefaultSteps(PetscInt N);
  static void     DefaultPrePeriods(PetscInt N, PetscInt *pre_periods, PetscReal *pre_tol);
  static PetscInt DefaultPreSteps(PetscInt N, PetscInt steps);
  // Solves from (U0, dU0, T0). Not converging is reported in res (reason, best iterate), and
  // returned as an error after res is complete, so that the caller can write it first.
  PetscErrorCode Solve(const Model &model, const SlidingEquilibrium &eq, ThetaIntegrator &ti, Vec U0, Vec dU0, PetscReal T0,
                       ShootingResult &res);
  PetscErrorCode View(const ShootingResult &res, PetscViewer viewer) const;
  // After the -shoot_pre_periods, when set: their outcome and end state (Z, T); *newton = false
  // ends Solve there (res.converged false, no error). The pipeline's choice between shooting and
  // the statistical steady state (app/pipeline.h) reads it.
  struct PrePeriodsOutcome {
    PetscInt  periods  = 0;
    PetscReal distance = 0, period = 0, measured_period = 0; // last return distance; T they ended with; 0: none measured
    bool      returned = false; // the return criterion held: distance < -shoot_pre_tol with the measured period
    bool      stagnated = false; // stopped by -shoot_pre_stagnation: no progress towards a return
    PetscReal best_recent = 0, best_before = 0; // ... the best return distances of the last window and before it
  };
  std::function<PetscErrorCode(const PrePeriodsOutcome &, Vec U, Vec dU, bool *newton)> after_pre_periods;
  PetscErrorCode Write(const ShootingResult &res, io::H5Writer &out) const;

  // The pieces, public for tests: the flow over one period and the bordered residual/Jacobian.
  // transitions: (step, point, new status) of every status change along the flow.
  PetscErrorCode Flow(Vec U, Vec dU, PetscReal T, Vec U1, Vec dU1, Eigen::VectorXd *r_end = nullptr,
                      std::vector<PetscInt> *transitions = nullptr);
  PetscErrorCode Residual(Vec x, Vec f);
  PetscErrorCode JacobianProduct(Vec x, Vec v, Vec y); // J(x) v: exact tangent (dense back end) or finite difference
  // Exact tangent of the period map along the flow from x (stored once per x, reused): columns
  // (dZ0; dT) -> dZ(T) = d Z / d Z0 dZ0 + d Z / d T dT, one linear integration for all k columns,
  // without a new factorisation (the derivative in h is exact, ThetaIntegrator::StepTangent).
  // Vectors in the natural order (U, dU) of the whole model, on every rank. Dense back end.
  PetscErrorCode TangentFlow(Vec x, const Eigen::MatrixXd &dZ0, const Eigen::RowVectorXd &dT, Eigen::MatrixXd &dZ1);
  PetscErrorCode ExchangeColumns(Eigen::MatrixXd &Z) const; // TangentFlow's column shares, to every rank
  // TangentFlow's integration of columns [c0, c0 + kc) along the stored flow into dZ1 (sized),
  // polling for interrupts on `poll`.
  PetscErrorCode TangentColumns(MPI_Comm poll, Eigen::Index c0, Eigen::Index kc, const Eigen::MatrixXd &dZ0, const Eigen::RowVectorXd &dT,
                                bool modal, Eigen::MatrixXd &dZ1);
  bool           ExactJacobian() const { return exact_jacobian && ti_ && ti_->Dense(); }
  // Newton's preconditioner for a caller's own Krylov solve on the bordered Jacobian at x
  // (continuation's arclength corrector): the LU of the dense Jacobian (2N + 1 <=
  // -shoot_jacobian_dense_max) or of the sliding linearisation's (-shoot_linear_pc), built as Newton
  // builds them, on the flow at x (integrated if it is not the one stored: the caller's last
  // Residual at x must be at the model's present parameters). After a Solve on this model.
  // *have = false where Newton has none: difference products, the sparse back end, deflation on.
  PetscErrorCode PreparePreconditioner(Vec x, bool *have);
  bool           HasPreconditioner() const // whether PreparePreconditioner will have one (after a Solve)
  {
    return ExactJacobian() && !(deflate_power > 0) && (2 * N_ + 1 <= jacobian_dense_max || (linear_pc && 2 * N_ <= linear_pc_max));
  }
  PetscErrorCode ApplyPreconditioner(Vec v, Vec y); // y = P^-1 v, P PreparePreconditioner's
  PetscErrorCode CreateState(Vec *x) const;
  PetscErrorCode Pack(Vec U, Vec dU, PetscReal T, Vec x) const;
  PetscErrorCode Unpack(Vec x, Vec U, Vec dU, PetscReal *T) const;
  PetscErrorCode SetAnchor(Vec x); // Z_a = Z0(x), G_a = G(Z(x))
  // The monodromy averaged over -floquet_phases starting points, by finite differences of
  // the flow or from the exact step tangents (FloquetSolver::Monodromy, MonodromyExact).
  PetscErrorCode Monodromy(Vec U0, Vec dU0, PetscReal T, Eigen::MatrixXd &Mono)
  {
    return floquet_.Monodromy(U0, dU0, T, floquet_.phases, Mono);
  }
  PetscErrorCode MonodromyExact(Vec U0, Vec dU0, PetscReal T, Eigen::MatrixXd &Mono)
  {
    return floquet_.MonodromyExact(U0, dU0, T, floquet_.phases, Mono);
  }
  // The Floquet solver and its settings (-floquet_*), read by SetFromOptions.
  FloquetSolver       &Floquet() { return floquet_; }
  const FloquetSolver &Floquet() const { return floquet_; }

  // steps: -shoot_steps, PETSC_DECIDE until SetUpFor chooses from the model (DefaultSteps).
  PetscInt  steps = PETSC_DECIDE;
  PetscReal eps1 = 1e-5, eps2 = 1e-5, fd_step = 1e-7, q_scale = 1.0;
  // -shoot_fd_motion: difference steps relative to the motion's size (EquilibriumDistance), not ||Z0||.
  PetscBool fd_motion = PETSC_FALSE;
  // SIGINT/SIGTERM raised from inside shooting (Newton and Krylov iterations, pre-periods, flows);
  // off where the caller polls between its own steps and keeps what it has (continuation).
  bool      interruptible = true;
  // The model's default pre-periods (DefaultPrePeriods) where -shoot_pre_periods is not given; off
  // where the start is already on a branch of cycles (continuation).
  bool      auto_pre_periods = true;
  PetscReal period = 0; // -shoot_period: the start period (and the bracket's centre) instead of the linear one; 0: linear
  // -shoot_start FILE, -shoot_start_from: the start (U0, dU0) and its period read from a results file
  // (io/start_state.h) instead of the energy estimate's: a cycle again at another -shoot_steps, a
  // settled transient's end, the full model from a reduced cycle (/expanded/Z0).
  std::string start_file, start_from = "auto";
  // -shoot_after_steady: -analyses auto, after a statistical steady state whose spectrum is periodic
  // (one base f1) and converged, shoots from its end state at T = 1 / f1 (at most
  // kAfterSteadyPrePeriods pre-periods, Newton only if they return): the cycle and its multipliers.
  PetscBool after_steady = PETSC_TRUE;
  static constexpr PetscInt kAfterSteadyPrePeriods = 20;
  // -shoot_exact_jacobian: tangent products (else finite differences); -shoot_jacobian_dense_max:
  // largest 2N + 1 for which the whole bordered Jacobian is built in one tangent integration and
  // factorised (the Krylov solve then converges in one iteration); above it GMRES on the products.
  PetscBool exact_jacobian = PETSC_TRUE;
  PetscInt  jacobian_dense_max = 200;
  // -shoot_linear_pc: above jacobian_dense_max, precondition GMRES with the LU of the bordered
  // Jacobian whose monodromy is that of the steady sliding linearisation (the step tangent at the
  // equilibrium reactions, raised to N_s by squaring; once per solve), up to 2N <= linear_pc_max.
  PetscBool linear_pc     = PETSC_TRUE;
  // -shoot_linear_pc_single: that monodromy's squarings in single precision from 2N = 1024 on.
  PetscBool linear_pc_single = PETSC_TRUE;
  PetscBool ew            = PETSC_TRUE; // -shoot_ew: inexact Newton for GMRES on products (Eisenstat-Walker)
  PetscBool ksp_eps1_stop = PETSC_TRUE; // -shoot_ksp_eps1_stop: GMRES stops where the next iterate meets eps1
  PetscBool monitor       = PETSC_FALSE; // -shoot_monitor: the pre-periods' and Newton's lines (also -shoot_snes_monitor)
  PetscInt  linear_pc_max = 6000;
  // -shoot_recycle: with -shoot_linear_pc, keep up to this many directions of the earlier Krylov
  // solves; at each Newton iteration their exact products (one block tangent integration, at the
  // price of a few one-column ones) correct the preconditioner to be exact on them (0: off).
  // Off by default: on the 3-DOF cycles it saves a quarter of the tangent integrations, but on the
  // 562-DOF pad cycle 8 or 32 recycled directions cut GMRES from 89 to 79 or 76 iterations in all and
  // the blocks ate the saving (docs/records.md, 2026-11-25).
  PetscInt  recycle = 0;
  PetscReal tangent_cache_mb = 2048; // -shoot_tangent_cache_mb
  // -shoot_pre_periods: at most this many periods of flow before Newton (PETSC_DECIDE until SetUpFor
  // chooses from the model: DefaultPrePeriods).
  PetscInt  pre_periods      = PETSC_DECIDE;
  // -shoot_pre_steps: steps per period of the pre-periods' flow until its first return within
  // -shoot_pre_tol (PETSC_DECIDE: DefaultPreSteps), then -shoot_steps to the next return; both phases
  // count in -shoot_pre_periods. The tolerance is far coarser than half the steps' discretisation
  // error, so above 200 DOFs they run at half of -shoot_steps (at least 100, at most -shoot_steps).
  PetscInt  pre_steps        = PETSC_DECIDE;
  // -shoot_pre_tol: ... stopping once the return distance is below (PETSC_DECIDE: DefaultPrePeriods).
  // On the 2625-DOF pad 0.5 / 0.35 / 0.2 / 0.1 / 0.02 take 2 / 3 / 4 / 7 / 24 periods, then 8 / 6 / 6 /
  // 6 / 5 Newton iterations; on the 31119-DOF pad 0.2 (6 periods) leaves Newton wandering at
  // ||H||/||Z0|| ~ 1 and 0.02 (38) converges in 5.
  PetscReal pre_tol          = PETSC_DECIDE;
  // -shoot_pre_fp_tol: the contact fixed point's tolerance in the pre-periods' flow (the theta
  // integrator's own, -theta_fp_tol, if that is looser). They only have to come within -shoot_pre_tol
  // of the cycle; Newton's flows and everything after keep -theta_fp_tol (1e-12). 1e-6 is 300 times
  // below the coarse pre-periods' own period error (3.3e-4 at 100 steps). On the 31119-DOF pad it
  // takes 9.8 contact iterations a step (1e-8: 14.5, 1e-12: 24.1), the 43 return distances, the
  // Newton iterates and the cycle as at 1e-8; the half brake's 58 pre-periods and 10 Newton
  // iterations are unchanged too (docs/records.md "Pre-periods' contact tolerance 1e-6").
  PetscReal pre_fp_tol       = 1e-6;
  // -shoot_pre_boost b: each pre-period's energy change 1 + g made (1 + g)^(1 + b) by scaling the
  // state's deviation from Z_e (pre_periods.cpp); 0: the plain flow.
  PetscReal pre_boost        = 10;
  // -shoot_pre_drift: the pre-periods' flow keeps the period it runs over (a new period is a new step
  // set-up) while the estimate differs from it by at most this times the last return distance, as a
  // fraction of the period; 0: a set-up at every period's estimate.
  PetscReal pre_drift        = 1e-2;
  // -shoot_pre_retries: when Newton fails from pre-periods that returned within their tolerance,
  // the flow goes on from where they stopped to a 10 times smaller return distance and Newton starts
  // again from there, up to this many times.
  PetscInt  pre_retries      = 2;
  // -shoot_pre_stagnation W: stop the pre-periods once the best return distance of the last W is not
  // below half the best before them (at least W before; a move of the start period starts afresh).
  // PETSC_DECIDE: off in -analyses shooting, which asks for a cycle; -analyses auto takes
  // Pipeline::Route::kAutoStagnation, where a flow that does not return only delays the statistics.
  PetscInt  pre_stagnation   = PETSC_DECIDE;
  // -shoot_deflate_power, -shoot_deflate_shift: deflation of the sliding equilibrium Z_e (Farrell,
  // Birkisson & Funke 2015): SNES solves m(Z0) (H, p) = 0, m = (d / d_0)^-p + shift,
  // d = |(omega_0 (U0 - U_e), dU0)|, d_0 at the start, so that neither Newton nor a globalisation on
  // the residual's norm can settle on Z_e (periodic with any T: ||H|| = 0 there).
  PetscReal deflate_power = 0, deflate_shift = 1;

private:
  friend struct ShootingCallbacks;
  // The Floquet computation runs on the flow, its tangents and the stored trajectory below.
  friend class FloquetSolver;
  FloquetSolver  floquet_{*this};
  PetscErrorCode SetUpFor(const Model &model, const SlidingEquilibrium &eq, ThetaIntegrator &ti);
  PetscErrorCode SetUpAt(PetscReal T); // the integrator's step matrices for h = T / N_s, unless already
  // Counts a flow of n steps: a period integration when n = N_s, else pro rata in partial_steps_.
  void           CountSteps(PetscInt n)
  {
    if (n >= steps) ++evaluations_;
    else partial_steps_ += n;
  }
  PetscErrorCode VectorField(Vec U, Vec dU, const Eigen::VectorXd &r, Vec gU, Vec gdU); // G(Z)
  // The steps of Solve: the SNES, KSP and preconditioner for this model's back end and size (and
  // the per-solve state reset); the -shoot_pre_periods from (U0, dU0, T0), leaving the start of
  // Newton in x; Newton from x, leaving the returned iterate in x and (aU_, adU_); the reason of a
  // failed SNES; the returned Z0 on rank 0 in the natural order (U, dU).
  PetscErrorCode SetUpNewton();
  // The pre-periods from (U0, dU0) at the start period T0, until the return distance is below tol
  // (-shoot_pre_tol, or a retry's tighter one); they add to pre_done_.
  PetscErrorCode PrePeriods(Vec U0, Vec dU0, PetscReal T0, PetscReal tol, Vec x);
  PetscErrorCode DeviationEnergy(Vec U, Vec dU, PetscReal *E); // 1/2 dU^T M dU + 1/2 (U - U_e)^T K (U - U_e)
  PetscErrorCode Newton(Vec x, ShootingResult &res);
  PetscErrorCode NewtonFailure(SNESConvergedReason reason);
  std::string    FailureHint(const ShootingResult &res) const; // the options that help, after a failed Newton
  PetscErrorCode GatherZ0(Vec x, ShootingResult &res);
  PetscErrorCode Orbit(Vec U0, Vec dU0, PetscReal T, ShootingResult &res);
  // The flow from the last residual evaluation (x, Z(x), last reaction): the anchor reuses it.
  VecH            lastx_, lastU1_, lastdU1_;
  Eigen::VectorXd last_r_;
  bool            last_valid_ = false;
  // Trajectory of the flow from trx_ (states, reactions, local velocities, h-sources), natural order.
  bool            record_ = false, tr_valid_ = false, trC_ready_ = false;
  VecH            trx_;
  PetscReal       trT_ = 0;
  Eigen::MatrixXd trU_, trdU_, trR_, trV_, trC_;
  Eigen::MatrixXd trdUm_, trCm_; // trdU_ and trC_ in the modal coordinates of the tangents (ThetaIntegrator::ModalTangent)
  std::vector<ThetaIntegrator::StepData::Factor> trF_; // per step of the stored flow
  double trF_mb_ = 0;                                   // their memory when all are kept (MB)
  Eigen::VectorXd sdUi_, sdUn_, sc_, svs_, sve_, sr_, vloc_;
  // A flow on several ranks: the whole state (U, dU), the reactions and the step's contact
  // iterations and residual, stepped by rank 0 and broadcast to the others after each step.
  Eigen::VectorXd lead_;
  PetscErrorCode  EnsureTrajectory(Vec x);
  PetscErrorCode  Full(Vec v, Eigen::Ref<Eigen::VectorXd> out);
  PetscErrorCode  ToNatural(Vec x, Eigen::VectorXd &z);       // packed (Z, T) -> (U, dU, T), every rank
  PetscErrorCode  FromNatural(const Eigen::VectorXd &z, Vec x);
  PetscErrorCode  BuildDenseJacobian(Vec x);
  Eigen::MatrixXd Jd_;
  Eigen::PartialPivLU<Eigen::MatrixXd> jlu_;
  void            DecideJacobianForm(); // jdense_ and jlinear_ from the model's size and the options
  bool            jdense_ = false; // this solve uses the dense bordered Jacobian
  bool            jlinear_ = false; // ... or the linearised-monodromy preconditioner (-shoot_linear_pc)
  Eigen::MatrixXd Mlin_;            // its monodromy, built at the first Jacobian of a solve
  PetscReal       Mlin_T_ = 0;      // ... at this period (a restart within 1e-3 of it keeps it)
  BorderedLU      jpc_;             // the bordered Mlin_ - I, factorised once per start
  bool            jpc_anchored_ = false; // its factor has the phase row
  PetscErrorCode  BuildLinearPreconditioner(Vec x);
  // Recycled subspace (newton.cpp): P^-1 z + Zc Uc^T z is exact on span(S), S the orthonormal
  // recycled directions (natural order, 2N + 1 rows), from Y = J S computed in one block product.
  Eigen::MatrixXd              rec_S_, rec_YS_, rec_Zc_, rec_Uc_; // rec_YS_ = J S at the last Newton iterate
  std::vector<Eigen::VectorXd> rec_w_, rec_y_; // the products (w, J w) of the solve under way
  PetscInt                     tangent_columns_ = 0, recycled_columns_ = 0;
  PetscErrorCode               RecycleSetUp(Vec x); // at each Jacobian, after the base preconditioner
  void                         RecycleSelect();      // S from the last solve's products (Ritz vectors)
  PetscErrorCode               JacobianBlock(Vec x, const Eigen::MatrixXd &Z, Eigen::MatrixXd &Y); // natural order, deflation included
  void                         BasePreconditioner(const Eigen::MatrixXd &z, Eigen::MatrixXd &y) const;
  VecH            jx_;              // where Jd_ was built
  AllGather       gather_;
  PetscMPIInt     size_ = 1, rank_ = 0;
  PetscInt        tangents_ = 0, setups_ = 0, N_ = 0;
  // Bisection flows of the phase pieces stop after flow_stop_ steps; their steps, in partial_steps_,
  // count as period integrations pro rata.
  PetscInt        flow_stop_ = -1, partial_steps_ = 0;
  PetscInt        flow_passes_ = 0; // contact iterations of the last Flow, summed over its steps
  PetscInt        pre_done_ = 0; // pre-periods run in the last Solve
  PetscInt        pre_coarse_ = 0; // ... of them at -shoot_pre_steps
  PetscInt        pre_passes_ = 0, pre_steps_run_ = 0; // ... their contact iterations and steps
  PetscReal       PreContactIterations() const { return pre_steps_run_ > 0 ? (PetscReal)pre_passes_ / pre_steps_run_ : 0; }
  // The values SetUpFor chose for steps, pre_periods, pre_steps, pre_tol (PETSC_DECIDE given), chosen again for
  // the next model unless changed since; and whether they were chosen (reported once per solve).
  PetscInt        auto_steps_ = -2, auto_pre_ = -2, auto_pre_steps_ = -2;
  PetscReal       auto_pre_tol_ = -2;
  PetscInt        auto_reported_ = -1;
  PetscErrorCode  ChooseDefaults(); // in SetUpFor, once N_ is known
  // Called after every step of Flow while set (the pre-periods' section returns): step index, state, reactions.
  std::function<PetscErrorCode(PetscInt, Vec, Vec, const Eigen::VectorXd &)> on_step_;
  PetscReal       pre_measured_ = 0;   // ... the period their motion returned with (0: none)
  bool            recentred_    = false; // ... and whether the bracket was moved onto it
  PetscReal       pre_T_    = 0; // ... and the period they ended with
  PetscReal       pre_e_    = 0;     // ... their last return distance
  PetscInt        retry_patience_ = 0; // Newton iterations without a better iterate before a restart (0: none to come)
  PetscReal       pre_tol_used_ = 0; // ... and the tolerance the last of them ran to (-shoot_pre_retries tighten it)
  bool            pre_returned_ = false; // ... and whether they stopped on the return criterion
  bool            pre_stagnated_ = false; // ... or on -shoot_pre_stagnation, with the two best distances
  PetscReal       pre_best_recent_ = 0, pre_best_before_ = 0;
  void           *ksp_default_ctx_ = nullptr; // KSPConvergedDefault's, wrapped by KrylovConverged
  PetscReal       rnorm0_          = 0;
  bool            confirm_only_    = false; // this Newton step only confirms |dT| / T < eps2
  PetscReal       reach_ratio_     = 0;     // GMRES stops at this reduction: 0.3 eps1 ||Z|| / ||F|| (0: no such stop)

  MPI_Comm                 comm_;
  const Model             *model_ = nullptr;
  ThetaIntegrator         *ti_    = nullptr;
  Eigen::VectorXd          r_init_;
  PetscReal                T_setup_ = -1, T0_ = 0;
  PetscInt                 nloc_ = 0, evaluations_ = 0;
  VecH                     U_, dU_, U1_, dU1_, wU_, wdU_, gU_, gdU_, aU_, adU_, tmp_;
  VecH                     xa_, ZaU_, ZadU_, GaU_, GadU_; // anchor
  VecH                     xbase_, fbase_, xp_, fp_;
  KSPH                     mass_ksp_;
  SNES                     snes_ = nullptr;
  MatH                     J_;
  bool                     anchored_ = false;
  std::vector<PetscReal>   hist_res_, hist_T_;
  PetscReal                best_res_ = kInf;
  PetscInt                 criterion_iterate_ = -1;
  VecH                     best_x_;
  std::string              fail_reason_;
  PetscReal                z_e_dist0_ = 0;
  VecH                     Ue_;
  PetscReal                dist0_ = 0;
  PetscBool                linesearch_given_ = PETSC_FALSE; // -shoot_snes_linesearch_type at SetFromOptions
  PetscErrorCode           EquilibriumDistance(Vec U, Vec dU, PetscReal *d); // weighted; U - U_e left in tmp_
  PetscErrorCode           Deflation(Vec U, Vec dU, PetscReal *m, PetscReal *coef);
  PetscErrorCode           SetDeflationBase(SNES snes, Vec x);
  // At the base of the Jacobian products: m, the undeflated residual F and grad m (deflated products
  // m J v + (grad m . v) F).
  PetscReal                defl_m_ = 0;
  VecH                     deflF_, deflgU_, deflgdU_;
};

} // namespace squeal
