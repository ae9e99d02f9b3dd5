#include "squeal/shooting/shooting.h"
#include "squeal/io/start_state.h"
#include "internal.h"
#include "squeal/core/inf.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace squeal {

namespace shoot_ev {
PetscLogEvent pre = 0, floquet = 0, tangent = 0, flow = 0, linear_pc = 0;
} // namespace shoot_ev

namespace {
PetscErrorCode RegisterEvents()
{
  PetscFunctionBeginUser;
  if (shoot_ev::pre) PetscFunctionReturn(0);
  PetscCall(PetscLogEventRegister("ShootPrePeriods", SNES_CLASSID, &shoot_ev::pre));
  PetscCall(PetscLogEventRegister("ShootFloquet", SNES_CLASSID, &shoot_ev::floquet));
  PetscCall(PetscLogEventRegister("ShootTangentFlow", SNES_CLASSID, &shoot_ev::tangent));
  PetscCall(PetscLogEventRegister("ShootFlow", SNES_CLASSID, &shoot_ev::flow));
  PetscCall(PetscLogEventRegister("ShootLinearPC", SNES_CLASSID, &shoot_ev::linear_pc));
  PetscFunctionReturn(0);
}
} // namespace

Shooting::~Shooting()
{
  if (ksp_default_ctx_) (void)KSPConvergedDefaultDestroy(ksp_default_ctx_);
  if (snes_) PetscCallVoid(SNESDestroy(&snes_));
}

PetscErrorCode Shooting::SetFromOptions()
{
  OptionChecks checks;
  PetscBool    pre_tol_set = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscCall(RegisterEvents());
  PetscOptionsBegin(comm_, "shoot_", "Shooting for the limit cycle", "Shooting");
  PetscCall(PetscOptionsInt("-steps",
                            "Theta-method steps per period N_s (h = T / N_s; default from the model: 1000 up to N = 99 DOFs, "
                            "where the bordered Jacobian is dense at the default -shoot_jacobian_dense_max, else 200)",
                            "Shooting", steps, &steps, nullptr));
  SquealOptionsReal("-eps1", "Stop when ||Z(Z0,T) - Z0|| / ||Z0|| < eps1 ...", "Shooting", &eps1, Range::Positive(), checks);
  SquealOptionsReal("-eps2", "... and |dT| / T < eps2 at the same iterate", "Shooting", &eps2, Range::Positive(), checks);
  SquealOptionsReal("-fd_step", "Relative finite-difference step of the flow derivatives", "Shooting", &fd_step, Range::Positive(),
                    checks);
  SquealOptionsReal("-period", "Start period (s), the centre of the period bracket (T/2, 2T), instead of the unstable mode's "
                    "linear period (0): for a cycle far from it (the settled period of -analyses transient)",
                    "Shooting", &period, Range::NonNegative(), checks);
  SquealOptionsReal("-q_scale", "Start from this multiple of the energy estimate's amplitude q0", "Shooting", &q_scale,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsBool("-after_steady",
                             "-analyses auto: after a converged statistical steady state with a periodic spectrum (one base f1), shoot "
                             "from its end state at T = 1 / f1 for the cycle and its Floquet multipliers",
                             "Shooting", after_steady, &after_steady, nullptr));
  PetscCall(io::StartOptions(PetscOptionsObject, "Shooting",
                             "Start from a state in a squeal results file (.h5) instead of the energy estimate: a cycle's /shooting/Z0 "
                             "(again at other -shoot_steps), a settled transient's last record or a steady state's end, a reduced "
                             "cycle on the full model (/expanded/Z0); its period is the start period unless -shoot_period is given",
                             start_file, start_from));
  PetscCall(PetscOptionsBool("-fd_motion",
                             "Finite-difference steps of the flow derivatives relative to the motion's size |(omega_0 (U0 - U_e), dU0)| "
                             "(and the period's share) instead of ||Z0||",
                             "Shooting", fd_motion, &fd_motion, nullptr));
  PetscCall(PetscOptionsBool("-exact_jacobian",
                             "Jacobian products from the exact step tangents along the stored flow (dense theta back end; "
                             "else finite differences of the flow)",
                             "Shooting", exact_jacobian, &exact_jacobian, nullptr));
  PetscCall(PetscOptionsInt("-jacobian_dense_max",
                            "Largest 2N + 1 for which the exact bordered Jacobian is built in one tangent integration and factorised "
                            "(above: GMRES on tangent products)",
                            "Shooting", jacobian_dense_max, &jacobian_dense_max, nullptr));
  PetscCall(PetscOptionsBool("-monitor",
                             "One line per pre-period return and per Newton iteration: return distance, period, distance from the "
                             "equilibrium, contact regime (-shoot_snes_monitor prints the same)",
                             "Shooting", monitor, &monitor, nullptr));
  PetscCall(PetscOptionsBool("-linear_pc",
                             "Above -shoot_jacobian_dense_max: precondition GMRES with the LU of the bordered Jacobian of the steady "
                             "sliding linearisation's monodromy (one step tangent raised to N_s by squaring)",
                             "Shooting", linear_pc, &linear_pc, nullptr));
  PetscCall(PetscOptionsBool("-linear_pc_single",
                             "The linear preconditioner's monodromy squared in single precision from 2N = 1024 on (sgemm: half the "
                             "time; float's 1e-7 is far below what a preconditioner needs)",
                             "Shooting", linear_pc_single, &linear_pc_single, nullptr));
  PetscCall(PetscOptionsInt("-pre_periods",
                            "Integrate this many periods T0 from the start (the energy estimate) before Newton: brings the start near "
                            "an attracting cycle whose shape differs from the unstable mode's (default from the model: 0 up to "
                            "N = 200 DOFs, at most 200 above)",
                            "Shooting", pre_periods, &pre_periods, nullptr));
  PetscCall(PetscOptionsInt("-pre_steps",
                            "Steps per period of the pre-periods' flow until it returns within -shoot_pre_tol; then -shoot_steps until "
                            "it returns again, Newton starting from there (default from the model: above N = 200 DOFs half of "
                            "-shoot_steps, at least 100 and at most -shoot_steps; else -shoot_steps; restarts after a failed Newton "
                            "use -shoot_steps)",
                            "Shooting", pre_steps, &pre_steps, nullptr));
  PetscCall(PetscOptionsBool("-ew",
                             "GMRES on tangent products: inexact Newton, with Eisenstat-Walker Krylov tolerances "
                             "(-shoot_snes_ksp_ew_* tune them) and a residual reduction of 1e-2 for the step that only confirms |dT|/T < eps2",
                             "Shooting", ew, &ew, nullptr));
  PetscCall(PetscOptionsBool("-ksp_eps1_stop",
                             "With -shoot_ew and right preconditioning (the default with -shoot_linear_pc; -shoot_ksp_pc_side left: not): GMRES stops once "
                             "its residual would bring the next iterate below 0.3 eps1 (false: Eisenstat-Walker's tolerance alone)",
                             "Shooting", ksp_eps1_stop, &ksp_eps1_stop, nullptr));
  // Not SquealOptionsReal: PETSC_DECIDE (the model's default) is negative.
  PetscCall(PetscOptionsReal("-pre_tol",
                             "Stop the -shoot_pre_periods early once the period-corrected return distance |Z(T) - Z0 + dt G| / |Z(T)| is "
                             "below this and two successive returns of the motion to a Poincare section give periods within 1 % of "
                             "each other; beyond 5 % of T that period becomes the start period and the bracket's centre (0: run them "
                             "all; default from the model: 0.05 up to N = 200 DOFs, 0.02 above)",
                             "Shooting", pre_tol, &pre_tol, &pre_tol_set));
  PetscCall(PetscOptionsInt("-pre_retries",
                            "When Newton fails from pre-periods that returned within -shoot_pre_tol: continue the flow from where they "
                            "stopped to a 10 times smaller return distance and start Newton again, up to this many times (0: never)",
                            "Shooting", pre_retries, &pre_retries, nullptr));
  PetscCall(PetscOptionsInt("-pre_stagnation",
                            "Stop the -shoot_pre_periods once the best return distance of the last W periods is not below half the "
                            "best of those before them (at least W before; 0: never; default: off in -analyses shooting, 20 in "
                            "-analyses auto, where a flow that does not return only delays the statistical steady state)",
                            "Shooting", pre_stagnation, &pre_stagnation, nullptr));
  SquealOptionsReal("-deflate_power",
                    "Deflate the sliding equilibrium Z_e (a trivial root: periodic with any T): Newton on m(Z0) H with "
                    "m = (d / d_0)^-p + shift, d = |(omega_0 (U0 - U_e), dU0)|, d_0 its value at the start, and a "
                    "backtracking line search on it unless -shoot_snes_linesearch_type is given (0: off)",
                    "Shooting", &deflate_power, Range::NonNegative(), checks);
  SquealOptionsReal("-pre_boost",
                    "While the pre-periods' flow still gains energy at its linear rate (5 periods steady within 1.5 x, at least "
                    "3/4 of the fastest so far), scale the state's deviation from the sliding equilibrium after each period so "
                    "that its energy changes by (1 + g)^(1 + b) instead of 1 + g (at most 5 % a period), until the gain stops; "
                    "Newton does not start from such a flow, and after it starts at 0.3 x -shoot_pre_tol (0: the plain flow)",
                    "Shooting", &pre_boost, Range::NonNegative(), checks);
  SquealOptionsReal("-pre_drift",
                    "The pre-periods' flow keeps the period it runs over (and its step set-up) while the period estimate "
                    "differs from it by at most this times the last return distance (relative to the period, and at most 2e-3); "
                    "the return distance is corrected to the estimate to first order; the fine periods after the coarse ones "
                    "(-shoot_pre_steps) keep the exact period (0: a set-up at every period)",
                    "Shooting", &pre_drift, Range::NonNegative(), checks);
  SquealOptionsReal("-pre_fp_tol",
                    "Contact fixed-point tolerance in the pre-periods' flow (-theta_fp_tol if that is looser; Newton's flows and "
                    "everything after use -theta_fp_tol)",
                    "Shooting", &pre_fp_tol, Range::Positive(), checks);
  SquealOptionsReal("-deflate_shift", "Shift of the deflation operator m (its value far from Z_e)", "Shooting", &deflate_shift,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsReal("-tangent_cache_mb",
                             "Memory for the per-step factors of the contact tangent system along the flow (reused by every "
                             "Jacobian product of a Newton iteration; 0: refactorise in each product)",
                             "Shooting", tangent_cache_mb, &tangent_cache_mb, nullptr));
  PetscCall(PetscOptionsInt("-linear_pc_max", "Largest 2N for -shoot_linear_pc (dense 2N x 2N matrices)", "Shooting", linear_pc_max,
                            &linear_pc_max, nullptr));
  PetscCall(PetscOptionsInt("-recycle",
                            "With -shoot_linear_pc: recycle up to this many Krylov directions of the earlier linear solves, whose exact "
                            "products (one block tangent integration per Newton iteration) make the preconditioner exact on them (0: off)",
                            "Shooting", recycle, &recycle, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  // A missing or foreign file fails here, before any model work.
  if (!start_file.empty()) PetscCall(io::CheckStartFile(comm_, start_file, "-shoot_start"));
  PetscCheck(steps == PETSC_DECIDE || steps >= 2, comm_, kErrInput, "option -shoot_steps = %" PetscInt_FMT ": expected >= 2", steps);
  PetscCheck(pre_periods == PETSC_DECIDE || pre_periods >= 0, comm_, kErrInput,
             "option -shoot_pre_periods = %" PetscInt_FMT ": expected >= 0", pre_periods);
  PetscCheck(!pre_tol_set || (pre_tol >= 0 && std::isfinite(pre_tol)), comm_, kErrInput,
             "option -shoot_pre_tol = %g: expected >= 0", (double)pre_tol);
  PetscCheck(pre_steps == PETSC_DECIDE || pre_steps >= 2, comm_, kErrInput, "option -shoot_pre_steps = %" PetscInt_FMT ": expected >= 2",
             pre_steps);
  PetscCheck(pre_retries >= 0, comm_, kErrInput, "option -shoot_pre_retries = %" PetscInt_FMT ": expected >= 0", pre_retries);
  PetscCheck(pre_stagnation == PETSC_DECIDE || pre_stagnation >= 0, comm_, kErrInput,
             "option -shoot_pre_stagnation = %" PetscInt_FMT ": expected >= 0 (0: never stop on stagnation; -1: the default)",
             pre_stagnation);
  PetscCheck(recycle >= 0, comm_, kErrInput, "option -shoot_recycle = %" PetscInt_FMT ": expected >= 0", recycle);
  PetscCheck(tangent_cache_mb >= 0, comm_, kErrInput, "option -shoot_tangent_cache_mb = %g: expected >= 0", (double)tangent_cache_mb);

  SNESLineSearch ls;
  KSP            ksp;
  PC             pc;
  PetscCall(SNESCreate(comm_, &snes_));
  PetscCall(SNESSetOptionsPrefix(snes_, "shoot_"));
  PetscCall(SNESSetType(snes_, SNESNEWTONLS));
  PetscCall(SNESGetLineSearch(snes_, &ls));
  PetscCall(SNESLineSearchSetType(ls, SNESLINESEARCHBASIC)); // the talk's plain Newton
  // Solve switches to backtracking when deflating, unless the line search is given here.
  PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-snes_linesearch_type", &linesearch_given_));
  PetscCall(SNESGetKSP(snes_, &ksp));
  PetscCall(KSPSetType(ksp, KSPGMRES));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCSetType(pc, PCNONE));
  // Products are finite differences with ~1e-7 relative noise: asking GMRES for much more than
  // 1e-6 makes it stagnate or break down (seen on the chain model at 1e-8); Newton needs no more.
  PetscCall(KSPSetTolerances(ksp, 1e-6, PETSC_DEFAULT, PETSC_DEFAULT, 200));
  PetscCall(SNESSetTolerances(snes_, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, 20, PETSC_DEFAULT));
  PetscCall(SNESSetFromOptions(snes_));
  PetscCall(KSPSetFromOptions(ksp)); // read -shoot_ksp_* now, so that a typo is caught up front
  // Our monitor prints what the method's stopping rule looks at; PETSc's would print ||F||.
  PetscCall(SNESMonitorCancel(snes_));
  // SIGINT/SIGTERM between Newton iterations and between Krylov iterations (each one a tangent
  // integration: seconds at FE scale), raised as an error: the best iterate is still written.
  PetscCall(SNESMonitorSet(
    snes_,
    [](SNES s, PetscInt, PetscReal, void *ctx) -> PetscErrorCode {
      return static_cast<Shooting *>(ctx)->interruptible ? InterruptPoint(PetscObjectComm((PetscObject)s), "shooting's Newton iterations") : 0;
    },
    this, nullptr));
  PetscCall(KSPMonitorSet(
    ksp,
    [](KSP k, PetscInt, PetscReal, void *ctx) -> PetscErrorCode {
      return static_cast<Shooting *>(ctx)->interruptible ? InterruptPoint(PetscObjectComm((PetscObject)k), "shooting's Krylov iterations") : 0;
    },
    this, nullptr));
  PetscCall(floquet_.SetFromOptions());
  PetscFunctionReturn(0);
}

// Steps per period. The trapezoidal rule's relative period error at the cycle's own frequency is
// (2 pi / N_s)^2 / 12: 3.3e-6 at 1000 steps, 8.2e-5 at 200, below what a reduced FE model answers
// for (the 562-DOF pad's unstable eigenvalue is 9.0e-4 from the full model's) and below 1e-4, the
// period agreement asked of a cycle against its transient (check_pad_cycle.py). The cost decides:
// where the bordered Jacobian is dense (2N + 1 <= 200, the default -shoot_jacobian_dense_max) a Newton iteration is
// one tangent integration and 1000 steps cost little (the 3-DOF cases: the defaults they were
// checked with); above, every GMRES iteration and every Floquet column is a period of flow, and 200
// steps make them 5 times cheaper (the reduced pads were run at 200: docs/records.md).
PetscInt Shooting::DefaultSteps(PetscInt N)
{
  // The size, not -shoot_jacobian_dense_max itself: a 3-DOF case on the GMRES route (tests force
  // it) keeps its 1000 steps.
  return 2 * N + 1 <= 200 ? 1000 : 200;
}

// Pre-periods. Up to 200 DOFs Newton converges from the energy estimate itself (the 3-DOF cases,
// the 180-DOF reduced small pad in 6 iterations): no pre-periods, and 0.05 if they are asked for.
// Above, the cycle's shape is far from the unstable mode's (separation and stick at many contacts):
// from the estimate Newton did not converge in 20 iterations on the 562-DOF pad, and at a return
// distance of 0.2 it wandered on the 1420-DOF one, while 0.02 converged both (24 and 38 periods, then
// 5 Newton iterations each). A period of flow costs what one GMRES iteration costs, so up to 200
// of them, stopping at 0.02 once the period holds.
void Shooting::DefaultPrePeriods(PetscInt N, PetscInt *pre_periods, PetscReal *pre_tol)
{
  const bool large = N > 200;
  *pre_periods     = large ? 200 : 0;
  *pre_tol         = large ? 0.02 : 0.05;
}

PetscInt Shooting::DefaultPreSteps(PetscInt N, PetscInt steps)
{
  // The pre-periods' flow only has to come within -shoot_pre_tol (0.02) of the cycle: half the steps
  // move the cycle by far less (the theta-method's phase error (omega h)^2 / 12 is 3e-4 at 100 steps
  // a period) and halve the cost of the 24-39 periods the FE pads need. Small models keep every step:
  // they have no pre-periods unless asked, and their cycles (impacts, several loops) are short.
  return N > 200 ? std::max<PetscInt>(100, steps / 2) : steps;
}

PetscErrorCode Shooting::ChooseDefaults()
{
  PetscFunctionBeginUser;
  // The options left at PETSC_DECIDE, or at what this chose for the last model, follow this one.
  PetscInt  pp;
  PetscReal pt;
  DefaultPrePeriods(N_, &pp, &pt);
  const bool s = steps == PETSC_DECIDE || steps == auto_steps_, p = pre_periods == PETSC_DECIDE || pre_periods == auto_pre_,
             t = pre_tol == PETSC_DECIDE || pre_tol == auto_pre_tol_;
  if (s) steps = auto_steps_ = DefaultSteps(N_);
  if (pre_steps == PETSC_DECIDE || pre_steps == auto_pre_steps_) pre_steps = auto_pre_steps_ = std::min(steps, DefaultPreSteps(N_, steps));
  if (p) pre_periods = auto_pre_ = auto_pre_periods ? pp : 0;
  if (t) pre_tol = auto_pre_tol_ = pt;
  // Said once per model size where the choice differs from the small models' (3-DOF) defaults.
  if (((s && steps != 1000) || (p && pre_periods != 0)) && N_ != auto_reported_) {
    char pre[128] = "no pre-periods";
    if (pre_periods > 0)
      std::snprintf(pre, sizeof pre, "up to %" PetscInt_FMT " pre-periods of %" PetscInt_FMT " steps to a return distance of %g", pre_periods,
                    pre_steps, (double)pre_tol);
    PetscCall(PetscPrintf(comm_,
                          "shooting: for N = %" PetscInt_FMT " DOFs %" PetscInt_FMT " steps per period and %s (-shoot_steps, "
                          "-shoot_pre_periods, -shoot_pre_steps, -shoot_pre_tol: chosen from the model unless given)\n",
                          N_, steps, pre));
  }
  auto_reported_ = N_;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::SetUpFor(const Model &model, const SlidingEquilibrium &eq, ThetaIntegrator &ti)
{
  PetscFunctionBeginUser;
  floquet_.Reset();
  if (!snes_) PetscCall(SetFromOptions());
  model_ = &model;
  ti_    = &ti;
  ti.SetManySetUps(true); // one step size per period: -theta_modal_step auto takes the modal step where it can
  PetscCall(VecGetLocalSize(model.F, &nloc_));
  for (VecH *v : {&U_, &dU_, &U1_, &dU1_, &wU_, &wdU_, &gU_, &gdU_, &aU_, &adU_, &tmp_, &ZaU_, &ZadU_, &GaU_, &GadU_, &Ue_, &deflgU_, &deflgdU_})
    PetscCall(VecDuplicate(model.F, v->out()));
  PetscCall(VecCopy(eq.U, Ue_));
  const PetscInt nc = model.contacts.Size();
  r_init_.setZero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) {
    r_init_[3 * c + kT] = model.contacts.Mu() * eq.N[c];
    r_init_[3 * c + kN] = eq.N[c];
  }
  for (VecH *v : {&xa_, &xbase_, &fbase_, &xp_, &fp_, &best_x_, &lastx_, &trx_, &jx_, &deflF_}) PetscCall(CreateState(v->out()));
  for (VecH *v : {&lastU1_, &lastdU1_}) PetscCall(VecDuplicate(model.F, v->out()));
  PetscCallMPI(MPI_Comm_size(comm_, &size_));
  PetscCallMPI(MPI_Comm_rank(comm_, &rank_));
  PetscCall(VecGetSize(model.F, &N_));
  PetscCall(ChooseDefaults());
  if (size_ > 1) PetscCall(gather_.SetUp(model.F));
  last_valid_ = tr_valid_ = false;
  PetscCall(VecSet(xbase_, PETSC_INFINITY));
  // M^-1 for the vector field G(Z).
  PetscCall(KSPCreate(comm_, mass_ksp_.out()));
  PetscCall(KSPSetOptionsPrefix(mass_ksp_, "shoot_mass_"));
  PetscCall(UseDirectSolver(mass_ksp_, Factorisation::SPD));
  PetscCall(KSPSetOperators(mass_ksp_, model.M, model.M));
  PetscCall(KSPSetFromOptions(mass_ksp_));
  PetscInt n, nl;
  PetscCall(VecGetSize(xa_, &n));
  PetscCall(VecGetLocalSize(xa_, &nl));
  PetscCall(MatCreateShell(comm_, nl, nl, n, n, this, J_.out()));
  PetscCall(MatShellSetOperation(J_, MATOP_MULT, (void (*)(void))ShootingCallbacks::Mult));
  T_setup_ = -1;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::CreateState(Vec *x) const
{
  PetscMPIInt rank, size;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  // Local block (U, dU) of this rank, and T at the very end, on the last rank.
  PetscCall(VecCreateMPI(comm_, 2 * nloc_ + (rank == size - 1 ? 1 : 0), PETSC_DETERMINE, x));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Pack(Vec U, Vec dU, PetscReal T, Vec x) const
{
  PetscScalar       *a;
  const PetscScalar *u, *du;
  PetscInt           nl;
  PetscFunctionBeginUser;
  PetscCall(VecGetLocalSize(x, &nl));
  PetscCall(VecGetArray(x, &a));
  PetscCall(VecGetArrayRead(U, &u));
  PetscCall(VecGetArrayRead(dU, &du));
  for (PetscInt i = 0; i < nloc_; ++i) a[i] = u[i], a[nloc_ + i] = du[i];
  if (nl > 2 * nloc_) a[2 * nloc_] = T;
  PetscCall(VecRestoreArrayRead(dU, &du));
  PetscCall(VecRestoreArrayRead(U, &u));
  PetscCall(VecRestoreArray(x, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Unpack(Vec x, Vec U, Vec dU, PetscReal *T) const
{
  const PetscScalar *a;
  PetscScalar       *u, *du;
  PetscInt           nl;
  PetscMPIInt        size;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  PetscCall(VecGetLocalSize(x, &nl));
  PetscCall(VecGetArrayRead(x, &a));
  PetscCall(VecGetArray(U, &u));
  PetscCall(VecGetArray(dU, &du));
  for (PetscInt i = 0; i < nloc_; ++i) u[i] = a[i], du[i] = a[nloc_ + i];
  PetscReal t = nl > 2 * nloc_ ? PetscRealPart(a[2 * nloc_]) : 0;
  PetscCall(VecRestoreArray(dU, &du));
  PetscCall(VecRestoreArray(U, &u));
  PetscCall(VecRestoreArrayRead(x, &a));
  PetscCallMPI(MPI_Bcast(&t, 1, MPIU_REAL, size - 1, comm_));
  if (T) *T = t;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Orbit(Vec U0, Vec dU0, PetscReal T, ShootingResult &res)
{
  PetscInt        N;
  PetscMPIInt     rank;
  Eigen::VectorXd r = r_init_;
  StepInfo        info;
  std::vector<int> st;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCall(VecGetSize(U0, &N));
  const PetscInt nc     = model_->contacts.Size();
  PetscBool      stored = PETSC_FALSE;
  if (tr_valid_ && trT_ == T && trU_.cols() == steps + 1 && trR_.rows() == 3 * nc) {
    PetscCall(Pack(U0, dU0, T, xp_));
    PetscCall(VecEqual(xp_, trx_, &stored));
  }
  res.orbit_t.clear();
  res.orbit_U.clear();
  res.orbit_status.clear();
  if (stored) {
    // The converged residual's flow is this orbit, stored with its reactions: no stepping, no scatters.
    if (rank == 0) {
      for (PetscInt i = 0; i <= steps; ++i) {
        res.orbit_U.insert(res.orbit_U.end(), trU_.col(i).data(), trU_.col(i).data() + N);
        res.orbit_t.push_back(i * T / steps);
        if (i > 0 && nc > 0) {
          ti_->Contact().Status(trR_.col(i - 1), st);
          res.orbit_status.insert(res.orbit_status.end(), st.begin(), st.end());
        }
      }
    }
  } else {
  PetscCall(SetUpAt(T));
  VecScatter sc;
  Vec        z;
  PetscCall(VecScatterCreateToZero(U0, &sc, &z));
  PetscCall(VecCopy(U0, U1_));
  PetscCall(VecCopy(dU0, dU1_));
  for (PetscInt i = 0; i <= steps; ++i) {
    if (i > 0) PetscCall(ti_->Step(U1_, dU1_, r, &info));
    PetscCall(VecScatterBegin(sc, U1_, z, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(sc, U1_, z, INSERT_VALUES, SCATTER_FORWARD));
    if (rank == 0) {
      const PetscScalar *a;
      PetscCall(VecGetArrayRead(z, &a));
      for (PetscInt k = 0; k < N; ++k) res.orbit_U.push_back(PetscRealPart(a[k]));
      PetscCall(VecRestoreArrayRead(z, &a));
      res.orbit_t.push_back(i * T / steps);
      if (i > 0 && nc > 0) {
        ti_->Contact().Status(r, st);
        res.orbit_status.insert(res.orbit_status.end(), st.begin(), st.end());
      }
    }
  }
  PetscCall(VecDestroy(&z));
  PetscCall(VecScatterDestroy(&sc));
  }
  if (rank == 0) {
    res.peak_to_peak.assign(N, 0.0);
    for (PetscInt k = 0; k < N; ++k) {
      PetscReal lo = kInf, hi = -kInf;
      for (PetscInt i = 0; i <= steps; ++i) lo = std::min(lo, res.orbit_U[i * N + k]), hi = std::max(hi, res.orbit_U[i * N + k]);
      res.peak_to_peak[k] = hi - lo;
    }
    if (!res.orbit_status.empty()) {
      PetscReal n0 = 0, n1 = 0;
      for (PetscInt s : res.orbit_status) n0 += s == kOpen, n1 += s == kStick;
      res.frac_separated = n0 / res.orbit_status.size();
      res.frac_stuck     = n1 / res.orbit_status.size();
    }
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Solve(const Model &model, const SlidingEquilibrium &eq, ThetaIntegrator &ti, Vec U0, Vec dU0, PetscReal T0,
                               ShootingResult &res)
{
  VecH x;
  PetscFunctionBeginUser;
  PetscCall(SetUpFor(model, eq, ti));
  res          = ShootingResult{};
  T0_          = T0;
  evaluations_ = tangents_ = setups_ = partial_steps_ = pre_done_ = pre_coarse_ = pre_passes_ = pre_steps_run_ = tangent_columns_ = recycled_columns_ = 0;
  pre_T_       = T0;
  pre_measured_ = 0, recentred_ = false;
  // Set up at T0 now: which back end the model gets decides how the bordered system is solved.
  T_setup_ = PETSC_MAX_REAL; // this model, or its new mu or load, may not be the one last set up
  Mlin_.resize(0, 0);        // ... nor its linearisation's monodromy
  PetscCall(SetUpAt(T0));
  PetscCall(SetUpNewton());
  PetscCall(CreateState(x.out()));
  pre_e_ = 0, pre_returned_ = false, pre_stagnated_ = false, pre_tol_used_ = pre_tol;
  if (pre_periods > 0) PetscCall(PrePeriods(U0, dU0, T0, pre_tol, x));
  else PetscCall(Pack(U0, dU0, T0, x));
  if (after_pre_periods) {
    VecH      U, dU;
    PetscReal T;
    bool      newton = true;
    PetscCall(VecDuplicate(U0, U.out()));
    PetscCall(VecDuplicate(dU0, dU.out()));
    PetscCall(Unpack(x, U, dU, &T));
    PetscCall(after_pre_periods({pre_done_, pre_e_, T, pre_measured_, pre_returned_, pre_stagnated_, pre_best_recent_, pre_best_before_}, U, dU, &newton));
    if (!newton) {
      res.reason              = "Newton not started (after_pre_periods)";
      res.period              = T;
      res.pre_periods         = pre_done_;
      res.pre_coarse_periods  = pre_coarse_;
      res.pre_contact_iterations = PreContactIterations();
      res.pre_period          = pre_T_;
      res.pre_measured_period = pre_measured_;
      PetscFunctionReturn(0);
    }
  }
  VecH      xpre; // where the last pre-periods stopped: the retries go on from there
  PetscReal tol = pre_tol;
  if (pre_periods > 0 && pre_retries > 0) {
    PetscCall(VecDuplicate(x, xpre.out()));
    PetscCall(VecCopy(x, xpre));
  }
  // Whether a restart can follow this Newton (pre-periods that returned, restarts left); patience
  // in iterations before making way for it (newton.cpp, Converged).
  constexpr PetscInt kPatience = 10;
  auto patience = [&](PetscInt retry) { return pre_periods > 0 && pre_returned_ && retry < pre_retries ? kPatience : 0; };
  retry_patience_ = patience(0);
  PetscCall(Newton(x, res));
  // Near the instability threshold the cycle's Floquet multipliers crowd 1 (the half brake at
  // mu = 0.05: 0.9993), so the bordered Jacobian is nearly singular there and Newton's basin is
  // small: from a return distance of 0.02 its first step leaves it, from 0.002 it converges in 8
  // iterations (docs/fe-workflow.md). The flow still contracts towards an attracting cycle: go on
  // with it from where the pre-periods stopped rather than from Newton's last iterate.
  for (PetscInt retry = 1; !res.converged && retry <= pre_retries && pre_periods > 0 && pre_returned_; ++retry) {
    tol *= 0.1;
    PetscCall(PetscPrintf(comm_,
                          "shooting: Newton did not converge from the return distance %.2e (%s): the flow goes on to %g, then Newton "
                          "again (retry %" PetscInt_FMT " of -shoot_pre_retries %" PetscInt_FMT ")\n",
                          (double)pre_e_, res.reason.c_str(), (double)tol, retry, pre_retries));
    VecH      U, dU;
    PetscReal T;
    PetscCall(VecDuplicate(U0, U.out()));
    PetscCall(VecDuplicate(dU0, dU.out()));
    PetscCall(Unpack(xpre, U, dU, &T));
    PetscCall(PrePeriods(U, dU, T, tol, x));
    PetscCall(VecCopy(x, xpre));
    res.pre_retries = retry;
    retry_patience_ = patience(retry);
    PetscCall(Newton(x, res));
  }
  pre_tol_used_ = tol, retry_patience_ = 0;
  PetscCall(GatherZ0(x, res));
  PetscCall(Orbit(aU_, adU_, res.period, res));
  const PetscInt newton_steps = evaluations_ * steps + partial_steps_;
  res.newton_evaluations      = evaluations_ + (partial_steps_ + steps - 1) / steps;
  if (res.converged && floquet_.compute) {
    PetscCall(PetscLogEventBegin(shoot_ev::floquet, 0, 0, 0, 0));
    PetscCall(floquet_.Compute(aU_, adU_, res.period, res));
    PetscCall(PetscLogEventEnd(shoot_ev::floquet, 0, 0, 0, 0));
  }
  res.flow_evaluations    = evaluations_ + (partial_steps_ + steps - 1) / steps;
  res.floquet_evaluations = (evaluations_ * steps + partial_steps_ - newton_steps + steps - 1) / steps;
  res.tangent_evaluations = tangents_;
  res.tangent_columns     = tangent_columns_;
  res.recycled_columns    = recycled_columns_;
  res.setups              = setups_;
  res.pre_periods         = pre_done_;
  res.pre_coarse_periods  = pre_coarse_;
  res.pre_contact_iterations = PreContactIterations();
  res.pre_period          = pre_T_;
  res.pre_measured_period = pre_measured_;
  res.bracket_centre      = T0_;
  res.bracket_recentred   = recentred_;
  // From the energy estimate, Newton can wander where the cycle's shape is far from the unstable
  // mode's (FE pads: separation and stick at many contacts); a few periods of flow first fix that.
  PetscCheck(res.converged, comm_, PETSC_ERR_NOT_CONVERGED, "shooting did not converge: %s (best ||H||/||Z0|| = %.3e at T = %.7f s)%s",
             res.reason.c_str(), (double)res.residual, (double)res.period, FailureHint(res).c_str());
  PetscFunctionReturn(0);
}

// What to change when Newton did not converge, from what this solve did: the option that helps
// in that situation, not only the Krylov solver's.
std::string Shooting::FailureHint(const ShootingResult &res) const
{
  const bool collapsed = res.reason.find("collapsed") != std::string::npos && !(deflate_power > 0);
  // The period pushed out of the bracket: a cycle far from the linear period (at mu = 5 on case 1
  // it settles at 2.14 T_lin), which more pre-periods at T0 do not reach.
  const bool  bracket = res.reason.find("the period left") != std::string::npos;
  const bool  krylov  = res.reason.find("Krylov") != std::string::npos;
  std::string h;
  char        b[320];
  // Without the dense back end the products are finite differences of the flow, whose noise and
  // status changes break GMRES down on FE models (the 562-DOF pad: DIVERGED_BREAKDOWN).
  if (exact_jacobian && ti_ && !ti_->Dense()) {
    // Beyond a few thousand DOFs the dense matrices do not fit: reduce first.
    if (N_ <= 4000)
      std::snprintf(b, sizeof b,
                    "; the Jacobian products were finite differences of the flow (N = %" PetscInt_FMT " DOFs on the sparse theta "
                    "back end): -theta_dense_max %" PetscInt_FMT " puts the model on the dense one, whose exact step tangents GMRES needs",
                    N_, N_);
    else
      std::snprintf(b, sizeof b,
                    "; the Jacobian products were finite differences of the flow (N = %" PetscInt_FMT " DOFs on the sparse theta "
                    "back end): reduce the model (-reduce_type craig_bampton -reduce_fmax) so that it fits the dense back end, "
                    "whose exact step tangents GMRES needs",
                    N_);
    h += b;
  }
  if (collapsed) h += "; keep Newton off the equilibrium with -shoot_deflate_power 2";
  if (bracket)
    h += recentred_ ? "; it had been recentred on the period the pre-periods' motion returned with, which had not yet "
                      "settled: more -shoot_pre_periods (a smaller -shoot_pre_tol), or take the settled period of a "
                      "transient (-analyses transient) and start from it with -shoot_period"
                    : "; the cycle's period may be far from the linear one (period-doubled or strongly nonlinear): run "
                      "-shoot_pre_periods (e.g. 100), which measure the period of the motion and recentre the bracket on it, or "
                      "take the settled period of a transient (-analyses transient) and start from it with -shoot_period";
  else if (pre_periods == 0)
    h += "; if the cycle attracts, start closer with periods of flow: -shoot_pre_periods 200 -shoot_pre_tol 0.02";
  else if (pre_returned_) {
    if (res.pre_retries > 0)
      std::snprintf(b, sizeof b,
                    "; the flow returned within %g after %" PetscInt_FMT " pre-period(s) in all (-shoot_pre_retries %" PetscInt_FMT
                    " taken) and Newton still failed: if the cycle attracts, start closer with more -shoot_pre_retries or a "
                    "smaller -shoot_pre_tol; a cycle whose Floquet multipliers crowd 1 is nearly neutral and hard to pin down",
                    (double)pre_tol_used_, pre_done_, res.pre_retries);
    else std::snprintf(b, sizeof b, "; if the cycle attracts, start closer: a smaller -shoot_pre_tol");
    h += b;
  } else {
    std::snprintf(b, sizeof b,
                  "; the %" PetscInt_FMT " pre-periods did not bring the flow back within -shoot_pre_tol %g: if the motion is "
                  "periodic, more -shoot_pre_periods; if it never returns (irregular), there is no cycle to shoot for "
                  "(-analyses transient shows the motion)",
                  pre_done_, (double)pre_tol_used_);
    h += b;
  }
  // GMRES that ran out of iterations after a close start: its own options, and the step, whose
  // status changes make the period map rough.
  if (krylov && !(exact_jacobian && ti_ && !ti_->Dense()) && !bracket && pre_periods > 0)
    h += "; the Krylov solve itself: -shoot_ksp_max_it, -shoot_ksp_gmres_restart, or more -shoot_steps (status changes within "
         "a step make the products rough)";
  return h;
}

PetscErrorCode Shooting::GatherZ0(Vec x, ShootingResult &res)
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  VecScatter sc;
  Vec        z;
  PetscCall(VecScatterCreateToZero(x, &sc, &z));
  PetscCall(VecScatterBegin(sc, x, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, x, z, INSERT_VALUES, SCATTER_FORWARD));
  // Global order of x is rank by rank (U block, dU block, [T]); put it back as (U, dU).
  if (rank == 0) {
    PetscInt           n;
    const PetscScalar *a;
    const PetscInt    *ranges;
    PetscMPIInt        size;
    PetscCallMPI(MPI_Comm_size(comm_, &size));
    PetscCall(VecGetOwnershipRanges(model_->F, &ranges));
    PetscCall(VecGetSize(z, &n));
    PetscCall(VecGetArrayRead(z, &a));
    const PetscInt N = ranges[size];
    res.Z0.assign(2 * N, 0.0);
    PetscInt off = 0;
    for (PetscMPIInt q = 0; q < size; ++q) {
      const PetscInt nl = ranges[q + 1] - ranges[q];
      for (PetscInt i = 0; i < nl; ++i) {
        res.Z0[ranges[q] + i]     = PetscRealPart(a[off + i]);
        res.Z0[N + ranges[q] + i] = PetscRealPart(a[off + nl + i]);
      }
      off += 2 * nl;
    }
    PetscCall(VecRestoreArrayRead(z, &a));
  }
  PetscCall(VecDestroy(&z));
  PetscCall(VecScatterDestroy(&sc));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::View(const ShootingResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  char recycled[64] = "";
  if (res.recycled_columns > 0) std::snprintf(recycled, sizeof recycled, ", %" PetscInt_FMT " of them recycled directions", res.recycled_columns);
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "shooting: %s in %" PetscInt_FMT " Newton iteration(s) (%" PetscInt_FMT
                                   " corrections applied), %" PetscInt_FMT " period integrations (Newton %" PetscInt_FMT
                                   ", Floquet %" PetscInt_FMT "; %" PetscInt_FMT " of them linear tangent integrations of %" PetscInt_FMT
                                   " columns in all%s), %" PetscInt_FMT " step set-ups\n",
                                   res.reason.c_str(), res.iterations, res.corrections, res.flow_evaluations, res.newton_evaluations,
                                   res.floquet_evaluations, res.tangent_evaluations, res.tangent_columns, recycled, res.setups));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "limit cycle period %.7f s (%.4f Hz), ||H||/||Z0|| = %.2e\n", (double)res.period,
                                   1 / (double)res.period, (double)res.residual));
  if (res.pre_retries > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "Newton started %" PetscInt_FMT " time(s) more (-shoot_pre_retries), after %" PetscInt_FMT
                                     " pre-period(s) in all, from a return distance below %g\n",
                                     res.pre_retries, res.pre_periods, (double)pre_tol_used_));
  if (res.bracket_recentred)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "start period and bracket (T/2, 2 T) = (%.6g, %.6g) s moved to the period the pre-periods' motion "
                                     "returned with, %.7f s (their last measurement %.7f s)\n",
                                     0.5 * (double)res.bracket_centre, 2 * (double)res.bracket_centre, (double)res.bracket_centre,
                                     (double)res.pre_measured_period));
  std::string p2p;
  for (size_t j = 0; j < res.peak_to_peak.size() && j < 12; ++j) {
    char b[32];
    std::snprintf(b, sizeof b, "%s%.4e", j ? ", " : "", (double)res.peak_to_peak[j]);
    p2p += b;
  }
  PetscCall(PetscViewerASCIIPrintf(viewer, "peak-to-peak (m): %s\n", p2p.c_str()));
  PetscCall(PetscViewerASCIIPrintf(viewer, "regime: %s (separated %.1f %%, stuck %.1f %% of the period)\n",
                                   res.frac_separated > 0 && res.frac_stuck > 0 ? "separation/stick/slip"
                                   : res.frac_separated > 0                     ? "separation/slip"
                                   : res.frac_stuck > 0                         ? "stick/slip"
                                                                                : "pure sliding",
                                   100 * (double)res.frac_separated, 100 * (double)res.frac_stuck));
  PetscCall(floquet_.View(res, viewer));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Write(const ShootingResult &res, io::H5Writer &out) const
{
  PetscFunctionBeginUser;
  hsize_t sizes[3] = {res.Z0.size(), res.orbit_t.size(), res.peak_to_peak.size()};
  PetscCallMPI(MPI_Bcast(sizes, 3, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  const hsize_t nh = res.residual_history.size();
  PetscCall(out.WriteArray("/shooting/period", {}, &res.period));
  PetscCall(out.WriteArray("/shooting/Z0", {sizes[0]}, res.Z0.data()));
  PetscCall(out.WriteIntArray("/shooting/iterations", {}, &res.iterations));
  PetscCall(out.WriteArray("/shooting/residual_history", {nh}, res.residual_history.data()));
  PetscCall(out.WriteArray("/shooting/period_history", {nh}, res.period_history.data()));
  std::vector<PetscReal> fl;
  for (auto z : res.floquet) fl.insert(fl.end(), {z.real(), z.imag()});
  PetscCall(out.WriteArray("/shooting/floquet", {res.floquet.size(), 2}, fl.data()));
  if (!res.floquet_at_z0.empty()) {
    std::vector<PetscReal> f0;
    for (auto z : res.floquet_at_z0) f0.insert(f0.end(), {z.real(), z.imag()});
    PetscCall(out.WriteArray("/shooting/floquet_at_Z0", {res.floquet_at_z0.size(), 2}, f0.data()));
  }
  PetscCall(out.WriteArray("/shooting/orbit/t", {sizes[1]}, res.orbit_t.data()));
  PetscCall(out.WriteArray("/shooting/orbit/U", {sizes[1], sizes[2]}, res.orbit_U.data()));
  PetscCall(out.WriteAttribute("/shooting", "converged", (PetscInt)res.converged));
  PetscCall(out.WriteAttribute("/shooting", "corrections_applied", res.corrections));
  PetscCall(out.WriteAttribute("/shooting", "reason", res.reason.c_str()));
  PetscCall(out.WriteAttribute("/shooting", "steps_per_period", steps));
  PetscCall(out.WriteAttribute("/shooting", "pre_periods", res.pre_periods));
  PetscCall(out.WriteAttribute("/shooting", "pre_coarse_periods", res.pre_coarse_periods));
  PetscCall(out.WriteAttribute("/shooting", "pre_contact_iterations", res.pre_contact_iterations));
  PetscCall(out.WriteAttribute("/shooting", "pre_retries", res.pre_retries));
  PetscCall(out.WriteAttribute("/shooting", "trivial_multiplier_index", res.trivial));
  if (!res.floquet.empty()) {
    PetscCall(out.WriteAttribute("/shooting", "floquet_verdict", res.floquet_verdict.c_str()));
    PetscCall(out.WriteAttribute("/shooting", "floquet_margin", res.floquet_margin));
    PetscCall(out.WriteAttribute("/shooting", "floquet_error", res.floquet_error));
  }
  if (!res.floquet.empty()) {
    PetscCall(out.WriteAttribute("/shooting/floquet", "method", res.floquet_method.c_str()));
    PetscCall(out.WriteAttribute("/shooting/floquet", "phases", res.floquet_phases));
  }
  PetscCall(out.WriteAttribute("/shooting/period", "units", "s"));
  PetscCall(out.WriteAttribute("/shooting/Z0", "layout", "(U, dU)"));
  PetscFunctionReturn(0);
}

} // namespace squeal
