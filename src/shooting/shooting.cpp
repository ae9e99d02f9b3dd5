#include "squeal/shooting/shooting.h"
#include "squeal/core/inf.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace squeal {

namespace {
// -log_view events: the parts of a shooting run (SNESSolve is PETSc's own).
PetscLogEvent ev_pre = 0, ev_floquet = 0, ev_tangent = 0, ev_flow = 0;
PetscErrorCode RegisterEvents()
{
  PetscFunctionBeginUser;
  if (ev_pre) PetscFunctionReturn(0);
  PetscCall(PetscLogEventRegister("ShootPrePeriods", SNES_CLASSID, &ev_pre));
  PetscCall(PetscLogEventRegister("ShootFloquet", SNES_CLASSID, &ev_floquet));
  PetscCall(PetscLogEventRegister("ShootTangentFlow", SNES_CLASSID, &ev_tangent));
  PetscCall(PetscLogEventRegister("ShootFlow", SNES_CLASSID, &ev_flow));
  PetscFunctionReturn(0);
}
} // namespace

// SNES callbacks: C functions that reach the Shooting object through their context.
struct ShootingCallbacks {
  static PetscErrorCode Function(SNES, Vec x, Vec f, void *ctx)
  {
    auto *s = static_cast<Shooting *>(ctx);
    PetscFunctionBeginUser;
    PetscCall(s->Residual(x, f));
    PetscFunctionReturn(0);
  }
  static PetscErrorCode Jacobian(SNES snes, Vec x, Mat, Mat, void *ctx)
  {
    auto *s = static_cast<Shooting *>(ctx);
    PetscBool same = PETSC_FALSE;
    PetscFunctionBeginUser;
    if (s->ExactJacobian()) {
      // Products are tangents along the residual's flow at x, stored when SNES computed it.
      PetscCall(s->EnsureTrajectory(x));
      if (s->jdense_) PetscCall(s->BuildDenseJacobian(x));
      else if (s->jlinear_) PetscCall(s->BuildLinearPreconditioner(x));
      PetscCall(VecCopy(x, s->xbase_));
      PetscCall(s->SetDeflationBase(snes, x));
      PetscFunctionReturn(0);
    }
    // The base point of the products: reuse the residual SNES just computed there.
    if (s->xbase_) PetscCall(VecEqual(x, s->xbase_, &same));
    if (!same) {
      PetscCall(VecCopy(x, s->xbase_));
      PetscCall(s->Residual(x, s->fbase_));
    }
    PetscFunctionReturn(0);
  }
  // The dense bordered Jacobian's LU as preconditioner: GMRES converges in one iteration (or the
  // LU of the linearised one, -shoot_linear_pc: GMRES then iterates on what the cycle adds).
  static PetscErrorCode DenseSolve(PC pc, Vec v, Vec y)
  {
    Shooting       *s;
    Eigen::VectorXd z;
    PetscFunctionBeginUser;
    PetscCall(PCShellGetContext(pc, &s));
    PetscCall(s->ToNatural(v, z));
    z = s->jlu_.solve(z);
    if (s->defl_m_ > 0) z /= s->defl_m_; // (m J)^-1: the rank-one part of the deflated Jacobian is left to GMRES
    PetscCall(s->FromNatural(z, y));
    PetscFunctionReturn(0);
  }
  static PetscErrorCode Mult(Mat J, Vec v, Vec y)
  {
    Shooting *s;
    PetscFunctionBeginUser;
    PetscCall(MatShellGetContext(J, &s));
    PetscCall(s->JacobianProduct(s->xbase_, v, y));
    if (s->defl_m_ > 0) {
      // d(m F) v = m J v + (grad m . v) F at the base (difference products differentiate m F itself).
      PetscScalar a, b;
      PetscCall(s->Unpack(v, s->wU_, s->wdU_, nullptr));
      PetscCall(VecDot(s->wU_, s->deflgU_, &a));
      PetscCall(VecDot(s->wdU_, s->deflgdU_, &b));
      PetscCall(VecScale(y, s->defl_m_));
      PetscCall(VecAXPY(y, a + b, s->deflF_));
    }
    PetscFunctionReturn(0);
  }
  // GMRES on products: PETSc's test, and once ||H|| / ||Z0|| < eps1 the solve only has to tell
  // whether |dT| / T < eps2 (quadratic convergence makes dT tiny there): a residual reduction of
  // 1e-2 decides that and still improves the iterate, at a third of the products of a tight solve.
  static PetscErrorCode KrylovConverged(KSP ksp, PetscInt it, PetscReal rnorm, KSPConvergedReason *reason, void *ctx)
  {
    auto *s = static_cast<Shooting *>(ctx);
    PetscFunctionBeginUser;
    PetscCall(KSPConvergedDefault(ksp, it, rnorm, reason, s->ksp_default_ctx_));
    if (it == 0) s->rnorm0_ = rnorm;
    else if (*reason == KSP_CONVERGED_ITERATING && s->confirm_only_ && rnorm <= 1e-2 * s->rnorm0_) *reason = KSP_CONVERGED_RTOL;
    PetscFunctionReturn(0);
  }
  static PetscErrorCode Update(SNES snes, PetscInt)
  {
    Shooting *s;
    Vec       x;
    PetscFunctionBeginUser;
    PetscCall(SNESGetApplicationContext(snes, &s));
    s->confirm_only_ = s->ew && !s->hist_res_.empty() && s->hist_res_.back() < s->eps1;
    PetscCall(SNESGetSolution(snes, &x));
    PetscCall(s->SetAnchor(x));
    // The new anchor is x itself, so the phase row of F(x) is 0: set it rather than integrate
    // the period again, for SNES's right-hand side and for the base of difference products.
    Vec f;
    PetscInt nl;
    PetscCall(SNESGetFunction(snes, &f, nullptr, nullptr));
    PetscCall(VecGetLocalSize(f, &nl));
    // Get/restore on every rank, not only on the one that owns the phase row: restoring bumps the
    // Vec's state, and a rank whose state did not move would keep its cached norm and skip the
    // reduction of the next VecNorm that the other rank enters (a deadlock under MPI).
    PetscScalar *a;
    PetscCall(VecGetArray(f, &a));
    if (nl > 2 * s->nloc_) a[2 * s->nloc_] = 0;
    PetscCall(VecRestoreArray(f, &a));
    PetscCall(VecCopy(x, s->xbase_));
    PetscCall(VecCopy(f, s->fbase_));
    PetscFunctionReturn(0);
  }
  static PetscErrorCode Converged(SNES snes, PetscInt it, PetscReal, PetscReal, PetscReal fnorm, SNESConvergedReason *reason,
                                  void *ctx)
  {
    auto     *s = static_cast<Shooting *>(ctx);
    Vec       x, f, dx;
    PetscReal T, nU, ndU, p = 0;
    PetscInt  max_it;
    PetscFunctionBeginUser;
    *reason = SNES_CONVERGED_ITERATING;
    PetscCall(SNESGetSolution(snes, &x));
    PetscCall(SNESGetFunction(snes, &f, nullptr, nullptr));
    PetscCall(s->Unpack(x, s->wU_, s->wdU_, &T));
    PetscCall(s->Unpack(f, s->aU_, s->adU_, &p));
    PetscCall(VecNorm(s->wU_, NORM_2, &nU));
    PetscCall(VecNorm(s->wdU_, NORM_2, &ndU));
    // SNES sees the deflated residual m (H, p): the stopping rule (6.3) reads H itself.
    PetscReal m, coef;
    PetscCall(s->Deflation(s->wU_, s->wdU_, &m, &coef));
    const PetscReal nH  = std::sqrt(std::max(0.0, fnorm * fnorm - p * p)) / m;
    const PetscReal res = nH / std::hypot(nU, ndU);
    char            mtxt[32] = "";
    if (s->deflate_power > 0) std::snprintf(mtxt, sizeof mtxt, "  m = %.3f", (double)m);
    s->hist_res_.push_back(res);
    s->hist_T_.push_back(T);
    if (res < s->best_res_) {
      s->best_res_ = res;
      PetscCall(VecCopy(x, s->best_x_));
    }
    PetscReal dT = kInf;
    if (it > 0) {
      PetscCall(SNESGetSolutionUpdate(snes, &dx));
      PetscCall(s->Unpack(dx, s->aU_, s->adU_, &dT));
    }
    PetscBool mon = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-snes_monitor", &mon));
    if (mon) {
      // Distance from the sliding equilibrium (the trivial root) and the flow's contact regime.
      PetscReal dq, open = 0, stick = 0;
      PetscCall(VecWAXPY(s->tmp_, -1.0, s->Ue_, s->wU_));
      PetscCall(VecNorm(s->tmp_, NORM_2, &dq));
      PetscBool same = PETSC_FALSE;
      if (s->tr_valid_) PetscCall(VecEqual(x, s->trx_, &same));
      if (same && s->trR_.rows() > 0) {
        std::vector<int> st;
        for (Eigen::Index i = 0; i < s->trR_.cols(); ++i) {
          s->ti_->Contact().Status(s->trR_.col(i), st);
          for (int c : st) open += c == kOpen, stick += c == kStick;
        }
        open /= (PetscReal)(s->trR_.cols() * s->trR_.rows() / 3), stick /= (PetscReal)(s->trR_.cols() * s->trR_.rows() / 3);
      }
      KSP      ksp;
      PetscInt kit = 0;
      PetscCall(SNESGetKSP(snes, &ksp));
      if (it > 0) PetscCall(KSPGetIterationNumber(ksp, &kit));
      PetscCall(PetscPrintf(s->comm_,
                            "  shooting %2" PetscInt_FMT ": ||H||/||Z0|| = %.3e  T = %.9f s  dT/T = %.3e  |U-Ue| = %.3e |dU| = %.3e"
                            "  open %.1f%% stick %.1f%%  ksp %" PetscInt_FMT "%s\n",
                            it, (double)res, (double)T, it > 0 ? (double)(std::abs(dT) / T) : 0.0, (double)dq, (double)ndU,
                            100 * (double)open, 100 * (double)stick, kit, mtxt));
    }
    if (PetscIsInfOrNanReal(fnorm)) {
      *reason        = SNES_DIVERGED_FNORM_NAN;
      s->fail_reason_ = "residual is NaN or infinite";
    } else if (it > 0 && s->hist_res_[s->hist_res_.size() - 2] < s->eps1 && std::abs(dT) / T < s->eps2) {
      // (6.3) at the same iterate x_{it-1}: its residual, and the correction (dZ, dT) computed
      // there, the one that produced x_it (applied: x_it is returned).
      *reason              = SNES_CONVERGED_FNORM_RELATIVE;
      s->criterion_iterate_ = it - 1;
    } else {
      const size_t n = s->hist_res_.size();
      if (n >= 4 && s->hist_res_[n - 1] > s->hist_res_[n - 2] && s->hist_res_[n - 2] > s->hist_res_[n - 3] &&
          s->hist_res_[n - 3] > s->hist_res_[n - 4]) {
        *reason        = SNES_DIVERGED_DTOL;
        s->fail_reason_ = "the residual grew for 3 iterations in a row";
      }
      // Plain Newton caught in a 2-cycle: the period map is not smooth near the cycle (a short
      // stick or contact phase that appears and disappears between the two iterates).
      const auto &r = s->hist_res_, &Th = s->hist_T_;
      if (n >= 6 && r[n - 1] > s->eps1) {
        bool two_cycle = std::abs(r[n - 1] - r[n - 2]) > 1e-2 * r[n - 1];
        for (size_t k = n - 1; k >= n - 2; --k)
          two_cycle = two_cycle && std::abs(r[k] - r[k - 2]) < 1e-2 * r[k] && std::abs(r[k - 2] - r[k - 4]) < 1e-2 * r[k] &&
                      std::abs(Th[k] - Th[k - 2]) < 1e-7 * Th[k] && std::abs(Th[k - 2] - Th[k - 4]) < 1e-7 * Th[k];
        if (two_cycle) {
          *reason = SNES_DIVERGED_DTOL;
          char msg[320];
          std::snprintf(msg, sizeof msg,
                        "Newton alternates between two iterates (||H||/||Z0|| = %.2e and %.2e): the period map is not smooth "
                        "near this cycle; try -shoot_snes_linesearch_type cp or more -shoot_steps",
                        (double)r[n - 2], (double)r[n - 1]);
          s->fail_reason_ = msg;
        }
      }
      // Orbit collapsing onto the equilibrium: a trivial fixed point of the flow.
      PetscCall(VecWAXPY(s->tmp_, -1.0, s->Ue_, s->wU_));
      PetscReal d;
      PetscCall(VecNorm(s->tmp_, NORM_2, &d));
      d = std::hypot(d, ndU);
      if (it == 0) s->z_e_dist0_ = d;
      else if (d < 1e-3 * s->z_e_dist0_) {
        *reason        = SNES_DIVERGED_DTOL;
        s->fail_reason_ = "the orbit collapsed onto the sliding equilibrium";
      }
      PetscCall(SNESGetTolerances(snes, nullptr, nullptr, nullptr, &max_it, nullptr));
      if (*reason == SNES_CONVERGED_ITERATING && it >= max_it) {
        *reason        = SNES_DIVERGED_MAX_IT;
        s->fail_reason_ = "no convergence in " + std::to_string(max_it) + " Newton iterations (-shoot_snes_max_it)";
      }
    }
    PetscFunctionReturn(0);
  }
};

Shooting::~Shooting()
{
  if (ksp_default_ctx_) (void)KSPConvergedDefaultDestroy(ksp_default_ctx_);
  if (snes_) PetscCallVoid(SNESDestroy(&snes_));
}

PetscErrorCode Shooting::SetFromOptions()
{
  OptionChecks checks;
  PetscFunctionBeginUser;
  PetscCall(RegisterEvents());
  PetscOptionsBegin(comm_, "shoot_", "Shooting for the limit cycle", "Shooting");
  PetscCall(PetscOptionsInt("-steps", "Theta-method steps per period N_s (h = T / N_s)", "Shooting", steps, &steps, nullptr));
  SquealOptionsReal("-eps1", "Stop when ||Z(Z0,T) - Z0|| / ||Z0|| < eps1 ...", "Shooting", &eps1, Range::Positive(), checks);
  SquealOptionsReal("-eps2", "... and |dT| / T < eps2 at the same iterate", "Shooting", &eps2, Range::Positive(), checks);
  SquealOptionsReal("-fd_step", "Relative finite-difference step of the flow derivatives", "Shooting", &fd_step, Range::Positive(),
                    checks);
  SquealOptionsReal("-q_scale", "Start from this multiple of the energy estimate's amplitude q0", "Shooting", &q_scale,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsBool("-floquet", "Compute Floquet multipliers at convergence", "Shooting", floquet, &floquet, nullptr));
  PetscCall(PetscOptionsInt("-floquet_dense_max", "Largest 2N for the dense monodromy (2N flows); above: SLEPc, matrix-free",
                            "Shooting", floquet_dense_max, &floquet_dense_max, nullptr));
  PetscCall(PetscOptionsBool("-floquet_exact", "Monodromy from exact step tangents (dense theta back end; else finite differences)",
                             "Shooting", floquet_exact, &floquet_exact, nullptr));
  PetscCall(PetscOptionsInt("-floquet_phases",
                            "Average the monodromy over this many starting points within one step of the orbit "
                            "(0: Gauss points on each piece where the contact statuses do not change, 1: none, K > 1: K midpoints; "
                            "default 0 for the dense monodromy, 1 for the matrix-free one)",
                            "Shooting", floquet_phases, &floquet_phases, nullptr));
  PetscCall(PetscOptionsBool("-exact_jacobian",
                             "Jacobian products from the exact step tangents along the stored flow (dense theta back end; "
                             "else finite differences of the flow)",
                             "Shooting", exact_jacobian, &exact_jacobian, nullptr));
  PetscCall(PetscOptionsInt("-jacobian_dense_max",
                            "Largest 2N + 1 for which the exact bordered Jacobian is built in one tangent integration and factorised "
                            "(above: GMRES on tangent products)",
                            "Shooting", jacobian_dense_max, &jacobian_dense_max, nullptr));
  PetscCall(PetscOptionsBool("-linear_pc",
                             "Above -shoot_jacobian_dense_max: precondition GMRES with the LU of the bordered Jacobian of the steady "
                             "sliding linearisation's monodromy (one step tangent raised to N_s by squaring)",
                             "Shooting", linear_pc, &linear_pc, nullptr));
  PetscCall(PetscOptionsInt("-pre_periods",
                            "Integrate this many periods T0 from the start (the energy estimate) before Newton: brings the start near "
                            "an attracting cycle whose shape differs from the unstable mode's",
                            "Shooting", pre_periods, &pre_periods, nullptr));
  PetscCall(PetscOptionsBool("-ew",
                             "GMRES on tangent products: inexact Newton, with Eisenstat-Walker Krylov tolerances "
                             "(-shoot_snes_ksp_ew_* tune them) and a residual reduction of 1e-2 for the step that only confirms |dT|/T < eps2",
                             "Shooting", ew, &ew, nullptr));
  SquealOptionsReal("-pre_tol",
                    "Stop the -shoot_pre_periods early once the period-corrected return distance |Z(T) - Z0 + dt G| / |Z(T)| is "
                    "below this (0: run them all)",
                    "Shooting", &pre_tol, Range::NonNegative(), checks);
  SquealOptionsReal("-deflate_power",
                    "Deflate the sliding equilibrium Z_e (a trivial root: periodic with any T): Newton on m(Z0) H with "
                    "m = (d / d_0)^-p + shift, d = |(omega_0 (U0 - U_e), dU0)|, d_0 its value at the start, and a "
                    "backtracking line search on it unless -shoot_snes_linesearch_type is given (0: off)",
                    "Shooting", &deflate_power, Range::NonNegative(), checks);
  SquealOptionsReal("-deflate_shift", "Shift of the deflation operator m (its value far from Z_e)", "Shooting", &deflate_shift,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsReal("-tangent_cache_mb",
                             "Memory for the per-step factors of the contact tangent system along the flow (reused by every "
                             "Jacobian product of a Newton iteration; 0: refactorise in each product)",
                             "Shooting", tangent_cache_mb, &tangent_cache_mb, nullptr));
  PetscCall(PetscOptionsInt("-linear_pc_max", "Largest 2N for -shoot_linear_pc (dense 2N x 2N matrices)", "Shooting", linear_pc_max,
                            &linear_pc_max, nullptr));
  SquealOptionsReal("-floquet_bisect_interp",
                    "Phase average: bisection intervals of the phase at most this wide start their flows from the mean of the "
                    "two ends' states before their first differing status change (0: every flow from the start of the period)",
                    "Shooting", &floquet_bisect_interp, Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-floquet_nev", "Multipliers computed by the matrix-free route (-shoot_floquet_eps_*)", "Shooting",
                            floquet_nev, &floquet_nev, nullptr));
  PetscCall(PetscOptionsInt("-floquet_block",
                            "Matrix-free route on exact tangents: block Arnoldi with this many columns per tangent integration "
                            "(0: SLEPc Krylov-Schur, one column per integration)",
                            "Shooting", floquet_block, &floquet_block, nullptr));
  PetscCall(PetscOptionsBool("-floquet_monitor", "Print the block Arnoldi's progress", "Shooting", floquet_monitor, &floquet_monitor, nullptr));
  PetscCall(PetscOptionsInt("-floquet_max_dim", "Block Arnoldi: largest Krylov basis (columns)", "Shooting", floquet_max_dim,
                            &floquet_max_dim, nullptr));
  SquealOptionsReal("-floquet_tol", "Block Arnoldi: relative residual of the -shoot_floquet_nev largest multipliers", "Shooting",
                    &floquet_tol, Range::Positive(), checks);
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(floquet_phases == PETSC_DECIDE || floquet_phases >= 0, comm_, kErrInput,
             "option -shoot_floquet_phases = %" PetscInt_FMT ": expected >= 0", floquet_phases);
  PetscCheck(steps >= 2, comm_, kErrInput, "option -shoot_steps = %" PetscInt_FMT ": expected >= 2", steps);
  PetscCheck(pre_periods >= 0, comm_, kErrInput, "option -shoot_pre_periods = %" PetscInt_FMT ": expected >= 0", pre_periods);
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
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::SetUpFor(const Model &model, const SlidingEquilibrium &eq, ThetaIntegrator &ti)
{
  PetscFunctionBeginUser;
  floquet_.Reset();
  if (!snes_) PetscCall(SetFromOptions());
  model_ = &model;
  ti_    = &ti;
  PetscCall(VecGetLocalSize(model.F, &nloc_));
  for (VecH *v : {&U_, &dU_, &U1_, &dU1_, &wU_, &wdU_, &gU_, &gdU_, &aU_, &adU_, &tmp_, &ZaU_, &ZadU_, &GaU_, &GadU_, &Ue_, &deflgU_, &deflgdU_})
    PetscCall(VecDuplicate(model.F, v->out()));
  PetscCall(VecCopy(eq.U, Ue_));
  const PetscInt nc = model.contacts.Size();
  r_init_.setZero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) {
    r_init_[3 * c + kT] = model.contacts.mu * eq.N[c];
    r_init_[3 * c + kN] = eq.N[c];
  }
  for (VecH *v : {&xa_, &xbase_, &fbase_, &xp_, &fp_, &best_x_, &lastx_, &trx_, &jx_, &deflF_}) PetscCall(CreateState(v->out()));
  for (VecH *v : {&lastU1_, &lastdU1_}) PetscCall(VecDuplicate(model.F, v->out()));
  PetscCallMPI(MPI_Comm_size(comm_, &size_));
  PetscCall(VecGetSize(model.F, &N_));
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

PetscErrorCode Shooting::SetUpAt(PetscReal T)
{
  PetscFunctionBeginUser;
  // A new period means a new step size: (S1)-(S3) again.
  if (T != T_setup_) {
    PetscCall(ti_->SetUp(*model_, T / steps));
    T_setup_ = T;
    ++setups_;
  }
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

PetscErrorCode Shooting::Flow(Vec U, Vec dU, PetscReal T, Vec U1, Vec dU1, Eigen::VectorXd *r_end, std::vector<PetscInt> *transitions)
{
  Eigen::VectorXd r = r_init_;
  StepInfo        info;
  std::vector<int> prev, cur;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(ev_flow, 0, 0, 0, 0));
  PetscCall(SetUpAt(T));
  PetscCall(VecCopy(U, U1));
  PetscCall(VecCopy(dU, dU1));
  const PetscInt nc = model_->contacts.Size();
  if (record_) {
    trU_.resize(N_, steps + 1), trdU_.resize(N_, steps + 1), trV_.resize(3 * nc, steps + 1), trR_.resize(3 * nc, steps);
    PetscCall(Full(U1, trU_.col(0)));
    PetscCall(Full(dU1, trdU_.col(0)));
    if (nc) {
      PetscCall(ti_->Local(dU1, vloc_));
      trV_.col(0) = vloc_;
    }
  }
  if (transitions) {
    transitions->clear();
    ti_->Contact().Status(r, prev);
  }
  const PetscInt run = flow_stop_ > 0 ? std::min(flow_stop_, steps) : steps;
  for (PetscInt i = 0; i < run; ++i) {
    PetscCall(ti_->Step(U1, dU1, r, &info));
    PetscCheck(r.size() == 0 || !std::isnan(info.contact.residual), comm_, PETSC_ERR_FP,
               "shooting: NaN in the flow at step %" PetscInt_FMT " of %" PetscInt_FMT " (T = %g s)", i + 1, steps, (double)T);
    if (record_) {
      PetscCall(Full(U1, trU_.col(i + 1)));
      PetscCall(Full(dU1, trdU_.col(i + 1)));
      if (nc) {
        trR_.col(i) = r;
        PetscCall(ti_->Local(dU1, vloc_));
        trV_.col(i + 1) = vloc_;
      }
    }
    if (transitions) {
      ti_->Contact().Status(r, cur);
      for (size_t c = 0; c < cur.size(); ++c)
        if (cur[c] != prev[c]) transitions->insert(transitions->end(), {i, (PetscInt)c, (PetscInt)cur[c]});
      std::swap(prev, cur);
    }
  }
  CountSteps(run);
  if (r_end) *r_end = r;
  PetscCall(PetscLogEventEnd(ev_flow, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::VectorField(Vec U, Vec dU, const Eigen::VectorXd &r, Vec gU, Vec gdU)
{
  PetscFunctionBeginUser;
  // G(Z) = (dU, M^-1 (F + H r - C dU - K U))
  PetscCall(VecCopy(dU, gU));
  PetscCall(MatMult(model_->K, U, tmp_));
  PetscCall(VecAYPX(tmp_, -1.0, model_->F));
  if (model_->HasDamping()) {
    PetscCall(MatMult(model_->C, dU, gdU));
    PetscCall(VecAXPY(tmp_, -1.0, gdU));
  }
  if (r.size()) PetscCall(model_->contacts.AddForce(r.data(), tmp_));
  PetscCall(KSPSolve(mass_ksp_, tmp_, gdU));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::SetAnchor(Vec x)
{
  PetscReal       T;
  Eigen::VectorXd r;
  PetscFunctionBeginUser;
  PetscBool same = PETSC_FALSE;
  PetscCall(Unpack(x, ZaU_, ZadU_, &T));
  // The anchor is the iterate whose residual SNES has just computed: reuse that flow.
  if (last_valid_) PetscCall(VecEqual(x, lastx_, &same));
  if (!same) {
    PetscCall(Flow(ZaU_, ZadU_, T, U1_, dU1_, &r));
    PetscCall(VectorField(U1_, dU1_, r, GaU_, GadU_));
  } else PetscCall(VectorField(lastU1_, lastdU1_, last_r_, GaU_, GadU_));
  anchored_ = true;
  PetscCall(VecSet(jx_, PETSC_INFINITY)); // a dense Jacobian holds the old anchor's row
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::EquilibriumDistance(Vec U, Vec dU, PetscReal *d)
{
  PetscReal       a, b;
  const PetscReal w = 2 * PETSC_PI / T0_;
  PetscFunctionBeginUser;
  PetscCall(VecWAXPY(tmp_, -1.0, Ue_, U));
  PetscCall(VecNorm(tmp_, NORM_2, &a));
  PetscCall(VecNorm(dU, NORM_2, &b));
  *d = std::hypot(w * a, b);
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Deflation(Vec U, Vec dU, PetscReal *m, PetscReal *coef)
{
  PetscReal d;
  PetscFunctionBeginUser;
  *m = 1, *coef = 0;
  if (!(deflate_power > 0) || !(dist0_ > 0)) PetscFunctionReturn(0);
  PetscCall(EquilibriumDistance(U, dU, &d));
  if (!(d > 0)) { // on the equilibrium itself the deflated residual is infinite
    *m = PETSC_INFINITY;
    PetscFunctionReturn(0);
  }
  const PetscReal q = std::pow(d / dist0_, -deflate_power);
  *m                = q + deflate_shift;
  *coef             = -deflate_power * q / (d * d); // grad m = coef (omega_0^2 (U - U_e), dU)
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Residual(Vec x, Vec f)
{
  PetscReal   T, p = 0;
  PetscScalar d1, d2;
  PetscFunctionBeginUser;
  PetscCall(Unpack(x, U_, dU_, &T));
  if (!(T > 0.5 * T0_ && T < 2 * T0_)) {
    fail_reason_ = "the period left (T0/2, 2 T0): T = " + std::to_string(T) + " s";
    if (snes_) PetscCall(SNESSetFunctionDomainError(snes_));
    PetscCall(VecSet(f, PETSC_INFINITY));
    PetscFunctionReturn(0);
  }
  // With exact products the Jacobian integrates the tangent along this very flow: keep it.
  record_ = ExactJacobian();
  PetscErrorCode ierr = Flow(U_, dU_, T, U1_, dU1_, &last_r_);
  record_ = false;
  PetscCall(ierr);
  if (ExactJacobian()) {
    PetscCall(VecCopy(x, trx_));
    trT_       = T;
    tr_valid_  = true;
    trC_ready_ = false;
  }
  PetscCall(VecCopy(x, lastx_));
  PetscCall(VecCopy(U1_, lastU1_));
  PetscCall(VecCopy(dU1_, lastdU1_));
  last_valid_ = true;
  PetscCall(VecAXPY(U1_, -1.0, U_));
  PetscCall(VecAXPY(dU1_, -1.0, dU_));
  if (anchored_) {
    PetscCall(VecWAXPY(wU_, -1.0, ZaU_, U_));
    PetscCall(VecWAXPY(wdU_, -1.0, ZadU_, dU_));
    PetscCall(VecDot(wU_, GaU_, &d1));
    PetscCall(VecDot(wdU_, GadU_, &d2));
    p = PetscRealPart(d1 + d2);
  }
  PetscCall(Pack(U1_, dU1_, p, f));
  if (deflate_power > 0) {
    PetscReal m, coef;
    PetscCall(Deflation(U_, dU_, &m, &coef));
    PetscCall(VecScale(f, m));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::SetDeflationBase(SNES snes, Vec x)
{
  PetscReal coef;
  Vec       f;
  PetscFunctionBeginUser;
  defl_m_ = 0;
  if (!(deflate_power > 0) || !(dist0_ > 0)) PetscFunctionReturn(0);
  PetscCall(Unpack(x, U_, dU_, nullptr));
  PetscCall(Deflation(U_, dU_, &defl_m_, &coef)); // leaves U0 - U_e in tmp_
  const PetscReal w = 2 * PETSC_PI / T0_;
  PetscCall(VecAXPBY(deflgU_, coef * w * w, 0.0, tmp_));
  PetscCall(VecAXPBY(deflgdU_, coef, 0.0, dU_));
  // SNES's function at x is m F(x) (its phase row set to 0 by the update): F = that / m.
  PetscCall(SNESGetFunction(snes, &f, nullptr, nullptr));
  PetscCall(VecAXPBY(deflF_, 1 / defl_m_, 0.0, f));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::JacobianProduct(Vec x, Vec v, Vec y)
{
  PetscReal nx, nv;
  PetscBool same = PETSC_FALSE;
  PetscFunctionBeginUser;
  if (ExactJacobian()) {
    Eigen::VectorXd z, out;
    if (jdense_) PetscCall(VecEqual(x, jx_, &same));
    PetscCall(ToNatural(v, z));
    const PetscInt n2 = 2 * N_;
    if (same) out = Jd_ * z;
    else {
      Eigen::MatrixXd    dZ1;
      Eigen::RowVectorXd dT(1);
      dT[0] = z[n2];
      PetscCall(TangentFlow(x, z.head(n2), dT, dZ1));
      Eigen::VectorXd g(n2);
      PetscCall(Full(GaU_, g.head(N_)));
      PetscCall(Full(GadU_, g.tail(N_)));
      out.resize(n2 + 1);
      out.head(n2) = dZ1.col(0) - z.head(n2);
      out[n2]      = anchored_ ? g.dot(z.head(n2)) : 0.0;
    }
    PetscCall(FromNatural(out, y));
    PetscFunctionReturn(0);
  }
  PetscCall(VecEqual(x, xbase_, &same));
  if (!same) {
    PetscCall(VecCopy(x, xbase_));
    PetscCall(Residual(x, fbase_));
  }
  PetscCall(VecNorm(v, NORM_2, &nv));
  if (nv == 0) {
    PetscCall(VecZeroEntries(y));
    PetscFunctionReturn(0);
  }
  PetscCall(VecNorm(x, NORM_2, &nx));
  const PetscReal eps = fd_step * nx / nv;
  PetscCall(VecWAXPY(xp_, eps, v, x));
  PetscCall(Residual(xp_, y));
  PetscCall(VecAXPY(y, -1.0, fbase_));
  PetscCall(VecScale(y, 1.0 / eps));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Full(Vec v, Eigen::Ref<Eigen::VectorXd> out)
{
  PetscFunctionBeginUser;
  if (size_ > 1) {
    PetscCall(gather_(v, out));
    PetscFunctionReturn(0);
  }
  const PetscScalar *a;
  PetscCall(VecGetArrayRead(v, &a));
  for (PetscInt i = 0; i < N_; ++i) out[i] = PetscRealPart(a[i]);
  PetscCall(VecRestoreArrayRead(v, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::ToNatural(Vec x, Eigen::VectorXd &z)
{
  PetscReal T;
  PetscFunctionBeginUser;
  z.resize(2 * N_ + 1);
  PetscCall(Unpack(x, wU_, wdU_, &T));
  PetscCall(Full(wU_, z.head(N_)));
  PetscCall(Full(wdU_, z.segment(N_, N_)));
  z[2 * N_] = T;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::FromNatural(const Eigen::VectorXd &z, Vec x)
{
  PetscInt     lo, hi, nl;
  PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(VecGetOwnershipRange(model_->F, &lo, &hi));
  PetscCall(VecGetLocalSize(x, &nl));
  PetscCall(VecGetArray(x, &a));
  for (PetscInt i = 0; i < nloc_; ++i) a[i] = z[lo + i], a[nloc_ + i] = z[N_ + lo + i];
  if (nl > 2 * nloc_) a[2 * nloc_] = z[2 * N_];
  PetscCall(VecRestoreArray(x, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::EnsureTrajectory(Vec x)
{
  PetscBool same = PETSC_FALSE;
  PetscFunctionBeginUser;
  if (tr_valid_) PetscCall(VecEqual(x, trx_, &same));
  if (!same) {
    PetscCall(Residual(x, fp_));
    PetscCheck(tr_valid_, comm_, PETSC_ERR_PLIB, "shooting: no flow at this iterate (period outside (T0/2, 2 T0))");
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::TangentFlow(Vec x, const Eigen::MatrixXd &dZ0, const Eigen::RowVectorXd &dT, Eigen::MatrixXd &dZ1)
{
  const PetscInt N = N_;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(ev_tangent, 0, 0, 0, 0));
  PetscCheck(ExactJacobian(), comm_, PETSC_ERR_SUP,
             "shooting: exact tangents need the dense theta back end (N = %" PetscInt_FMT " > -theta_dense_max) and -shoot_exact_jacobian",
             N);
  PetscCall(EnsureTrajectory(x));
  if (T_setup_ != trT_) { // a test or a difference product moved the step size since
    PetscCall(ti_->SetUp(*model_, trT_ / steps));
    T_setup_ = trT_;
    ++setups_;
    for (auto &f : trF_) f.valid = false;
  }
  const PetscInt nc = model_->contacts.Size();
  if (!trC_ready_) {
    // The h-sources depend on the base flow only: once per stored trajectory.
    trC_.resize(N, steps);
    for (auto &f : trF_) f.valid = false;
    for (PetscInt i = 0; i < steps; ++i) {
      sdUi_ = trdU_.col(i), sdUn_ = trdU_.col(i + 1), sve_ = trU_.col(i);
      if (nc) sr_ = trR_.col(i);
      else sr_.resize(0);
      PetscCall(ti_->StepTangentSource(sve_, sdUi_, sdUn_, sr_, sc_));
      trC_.col(i) = sc_;
    }
    trC_ready_ = true;
  }
  Eigen::MatrixXd    dU = dZ0.topRows(N), ddU = dZ0.bottomRows(N);
  Eigen::RowVectorXd dh = dT / (PetscReal)steps;
  ThetaIntegrator::StepData sd{&sdUi_, &sdUn_, &sc_, &svs_};
  // One-column products (GMRES) would refactorise each step's closed-point system every time:
  // keep the factors along this flow while they fit in -shoot_tangent_cache_mb.
  const double factor_mb = 8.0 * 9.0 * nc * nc * steps / 1048576.0;
  const bool   cache     = nc > 0 && factor_mb <= tangent_cache_mb;
  if (cache && (PetscInt)trF_.size() != steps) trF_.assign(steps, {});
  for (PetscInt i = 0; i < steps; ++i) {
    sd.factor = cache ? &trF_[i] : nullptr;
    sdUi_ = trdU_.col(i), sdUn_ = trdU_.col(i + 1), sc_ = trC_.col(i);
    if (nc) sr_ = trR_.col(i), svs_ = trV_.col(i), sve_ = trV_.col(i + 1);
    else sr_.resize(0), svs_.resize(0), sve_.resize(0);
    PetscCall(ti_->StepTangent(sr_, sve_, sd, dh, dU, ddU));
  }
  dZ1.resize(2 * N, dZ0.cols());
  dZ1.topRows(N)    = dU;
  dZ1.bottomRows(N) = ddU;
  ++evaluations_, ++tangents_;
  PetscCall(PetscLogEventEnd(ev_tangent, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::BuildDenseJacobian(Vec x)
{
  const PetscInt n2 = 2 * N_;
  PetscFunctionBeginUser;
  Eigen::MatrixXd    E = Eigen::MatrixXd::Identity(n2, n2 + 1), D;
  Eigen::RowVectorXd dT = Eigen::RowVectorXd::Zero(n2 + 1);
  dT[n2] = 1.0;
  PetscCall(TangentFlow(x, E, dT, D));
  Jd_.setZero(n2 + 1, n2 + 1);
  Jd_.topRows(n2) = D;
  Jd_.topLeftCorner(n2, n2).diagonal().array() -= 1.0;
  if (anchored_) {
    Eigen::VectorXd g(n2);
    PetscCall(Full(GaU_, g.head(N_)));
    PetscCall(Full(GadU_, g.tail(N_)));
    Jd_.row(n2).head(n2) = g.transpose();
  }
  jlu_.compute(Jd_);
  PetscCall(VecCopy(x, jx_));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::BuildLinearPreconditioner(Vec x)
{
  const PetscInt n2 = 2 * N_;
  PetscFunctionBeginUser;
  if (Mlin_.rows() != n2) {
    // Weakly damped structural modes put many multipliers near the unit circle, spread round it:
    // unpreconditioned GMRES needs about one iteration each. They are nearly those of the steady
    // sliding linearisation, whose monodromy costs one step tangent (2N columns at the equilibrium
    // reactions: every point closed and sliding, slip direction against V_c) and log2(N_s) squarings.
    Eigen::MatrixXd dU = Eigen::MatrixXd::Zero(N_, n2), ddU = Eigen::MatrixXd::Zero(N_, n2);
    dU.leftCols(N_).setIdentity();
    ddU.rightCols(N_).setIdentity();
    const Eigen::VectorXd v0 = Eigen::VectorXd::Zero(r_init_.size());
    PetscCall(ti_->StepTangent(r_init_, v0, dU, ddU));
    Eigen::MatrixXd S(n2, n2), P = Eigen::MatrixXd::Identity(n2, n2), tmp(n2, n2);
    S.topRows(N_)    = dU;
    S.bottomRows(N_) = ddU;
    for (PetscInt e = steps; e > 0; e >>= 1) {
      if (e & 1) tmp.noalias() = P * S, P.swap(tmp);
      if (e > 1) tmp.noalias() = S * S, S.swap(tmp);
    }
    Mlin_.swap(P);
  }
  // The period column is exact (one tangent integration of one column); the border is the anchor's.
  Eigen::MatrixXd    dT1;
  Eigen::RowVectorXd dT = Eigen::RowVectorXd::Ones(1);
  PetscCall(TangentFlow(x, Eigen::MatrixXd::Zero(n2, 1), dT, dT1));
  Jd_.setZero(n2 + 1, n2 + 1);
  Jd_.topLeftCorner(n2, n2) = Mlin_;
  Jd_.topLeftCorner(n2, n2).diagonal().array() -= 1.0;
  Jd_.col(n2).head(n2) = dT1.col(0);
  if (anchored_) {
    Eigen::VectorXd g(n2);
    PetscCall(Full(GaU_, g.head(N_)));
    PetscCall(Full(GadU_, g.tail(N_)));
    Jd_.row(n2).head(n2) = g.transpose();
  } else Jd_(n2, n2) = 1.0; // no phase row yet: keep the preconditioner regular
  jlu_.compute(Jd_);
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
  evaluations_ = tangents_ = setups_ = partial_steps_ = pre_done_ = 0;
  pre_T_       = T0;
  // Set up at T0 now: which back end the model gets decides how the bordered system is solved.
  PetscCall(ti_->SetUp(*model_, T0 / steps));
  T_setup_ = T0;
  ++setups_;
  PetscCall(SetUpNewton());
  PetscCall(CreateState(x.out()));
  if (pre_periods > 0) PetscCall(PrePeriods(U0, dU0, T0, x));
  else PetscCall(Pack(U0, dU0, T0, x));
  PetscCall(Newton(x, res));
  PetscCall(GatherZ0(x, res));
  PetscCall(Orbit(aU_, adU_, res.period, res));
  const PetscInt newton_steps = evaluations_ * steps + partial_steps_;
  res.newton_evaluations      = evaluations_ + (partial_steps_ + steps - 1) / steps;
  if (res.converged && floquet) {
    PetscCall(PetscLogEventBegin(ev_floquet, 0, 0, 0, 0));
    PetscCall(floquet_.Compute(aU_, adU_, res.period, res));
    PetscCall(PetscLogEventEnd(ev_floquet, 0, 0, 0, 0));
  }
  res.flow_evaluations    = evaluations_ + (partial_steps_ + steps - 1) / steps;
  res.floquet_evaluations = (evaluations_ * steps + partial_steps_ - newton_steps + steps - 1) / steps;
  res.tangent_evaluations = tangents_;
  res.setups              = setups_;
  res.pre_periods         = pre_done_;
  res.pre_period          = pre_T_;
  // From the energy estimate, Newton can wander where the cycle's shape is far from the unstable
  // mode's (FE pads: separation and stick at many contacts); a few periods of flow first fix that.
  const bool collapsed = res.reason.find("collapsed") != std::string::npos && !(deflate_power > 0);
  PetscCheck(res.converged, comm_, PETSC_ERR_NOT_CONVERGED, "shooting did not converge: %s (best ||H||/||Z0|| = %.3e at T = %.7f s)%s%s",
             res.reason.c_str(), (double)res.residual, (double)res.period,
             collapsed ? "; keep Newton off the equilibrium with -shoot_deflate_power 2" : "",
             res.reason.find("Krylov") != std::string::npos ? ""
             : pre_periods == 0 ? "; if the cycle attracts, start closer with a few periods of flow: -shoot_pre_periods 50"
             : pre_done_ < pre_periods ? "; if the cycle attracts, start closer: a smaller -shoot_pre_tol"
                                       : "; if the cycle attracts, start closer: more -shoot_pre_periods");
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::SetUpNewton()
{
  PetscFunctionBeginUser;
  jdense_  = ExactJacobian() && 2 * N_ + 1 <= jacobian_dense_max;
  jlinear_ = ExactJacobian() && !jdense_ && linear_pc && 2 * N_ <= linear_pc_max;
  {
    // GMRES on tangent products (one period integration each): far from the cycle Newton's step
    // needs no 1e-6 linear solve, so the Krylov tolerance follows the residual's decrease
    // (Eisenstat-Walker). On the 542-DOF pad: 58 products instead of 142 for the same cycle.
    // The dense Jacobian's LU solves exactly in one iteration: nothing to save there.
    PetscBool set = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-snes_ksp_ew", &set));
    if (!set) {
      PetscCall(SNESKSPSetUseEW(snes_, (PetscBool)(ew && !jdense_ && ExactJacobian())));
      // PETSc's default rtol_max 0.9 lets a step after a residual increase (status changes make
      // the period map non-smooth) stop after 2 GMRES iterations, and Newton then crawls: cap at 0.1.
      PetscCall(SNESKSPSetParametersEW(snes_, PETSC_DEFAULT, 0.1, 0.1, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT));
    }
  }
  if (!linesearch_given_) {
    // Deflated, the residual's norm has no minimum at Z_e any more: globalise on it.
    SNESLineSearch ls;
    PetscCall(SNESGetLineSearch(snes_, &ls));
    PetscCall(SNESLineSearchSetType(ls, deflate_power > 0 ? SNESLINESEARCHBT : SNESLINESEARCHBASIC));
  }
  Mlin_.resize(0, 0);
  {
    KSP ksp;
    PC  pc;
    PetscCall(SNESGetKSP(snes_, &ksp));
    PetscCall(KSPGetPC(ksp, &pc));
    if (jdense_) {
      // Exact dense Jacobian, factorised: its LU preconditions GMRES, which then stops at once.
      PetscCall(PCSetType(pc, PCSHELL));
      PetscCall(PCShellSetContext(pc, this));
      PetscCall(PCShellSetApply(pc, ShootingCallbacks::DenseSolve));
      PetscCall(PCShellSetName(pc, "LU of the exact bordered Jacobian"));
      PetscCall(KSPSetTolerances(ksp, 1e-12, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT));
    } else if (jlinear_) {
      if (!ksp_default_ctx_) PetscCall(KSPConvergedDefaultCreate(&ksp_default_ctx_));
      PetscCall(KSPSetConvergenceTest(ksp, ShootingCallbacks::KrylovConverged, this, nullptr));
      PetscCall(PCSetType(pc, PCSHELL));
      PetscCall(PCShellSetContext(pc, this));
      PetscCall(PCShellSetApply(pc, ShootingCallbacks::DenseSolve));
      PetscCall(PCShellSetName(pc, "LU of the bordered Jacobian of the sliding linearisation (-shoot_linear_pc)"));
    } else {
      PetscBool shell;
      PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCSHELL, &shell));
      if (shell) PetscCall(PCSetType(pc, PCNONE));
      if (!ExactJacobian() && exact_jacobian)
        PetscCall(PetscInfo(nullptr, "shooting: N = %" PetscInt_FMT " > -theta_dense_max: finite-difference products\n", N_));
    }
  }
  PetscCall(VecSet(jx_, PETSC_INFINITY));
  anchored_    = false;
  hist_res_.clear();
  hist_T_.clear();
  best_res_ = kInf;
  fail_reason_.clear();
  criterion_iterate_ = -1;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::PrePeriods(Vec U0, Vec dU0, PetscReal T0, Vec x)
{
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(ev_pre, 0, 0, 0, 0));
  // Where the cycle's shape is far from the unstable mode's (many contacts with separation and
  // stick), periods of the flow bring the start into the attracting cycle's neighbourhood. After
  // each period the return distance is read with the period corrected to first order along the
  // end point's vector field G: dt = -G.(Z1 - Z)/|G|^2, e = |Z1 - Z + dt G| / |Z1| (the residual
  // Newton would see at T + dt). It stops once e < -shoot_pre_tol and starts Newton at T + dt.
  VecH            U, dU;
  Eigen::VectorXd r;
  PetscBool       mon = PETSC_FALSE;
  PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-snes_monitor", &mon));
  PetscCall(VecDuplicate(U0, U.out()));
  PetscCall(VecDuplicate(dU0, dU.out()));
  PetscCall(VecCopy(U0, U));
  PetscCall(VecCopy(dU0, dU));
  PetscReal T = T0, e = kInf;
  PetscInt  k = 0;
  while (k < pre_periods) {
    PetscCall(Flow(U, dU, T, U1_, dU1_, &r, nullptr));
    ++k;
    PetscCall(VectorField(U1_, dU1_, r, gU_, gdU_));
    PetscScalar a1, a2, b1, b2;
    PetscReal   n1, n2;
    PetscCall(VecWAXPY(wU_, -1.0, U, U1_));
    PetscCall(VecWAXPY(wdU_, -1.0, dU, dU1_));
    PetscCall(VecDot(wU_, gU_, &a1));
    PetscCall(VecDot(wdU_, gdU_, &a2));
    PetscCall(VecDot(gU_, gU_, &b1));
    PetscCall(VecDot(gdU_, gdU_, &b2));
    const PetscReal dt = PetscRealPart(b1 + b2) > 0 ? -PetscRealPart(a1 + a2) / PetscRealPart(b1 + b2) : 0.0;
    PetscCall(VecAXPY(wU_, dt, gU_));
    PetscCall(VecAXPY(wdU_, dt, gdU_));
    PetscCall(VecNorm(wU_, NORM_2, &n1));
    PetscCall(VecNorm(wdU_, NORM_2, &n2));
    const PetscReal d = std::hypot(n1, n2);
    PetscCall(VecNorm(U1_, NORM_2, &n1));
    PetscCall(VecNorm(dU1_, NORM_2, &n2));
    e = d / std::hypot(n1, n2);
    PetscCall(VecCopy(U1_, U));
    PetscCall(VecCopy(dU1_, dU));
    if (mon)
      PetscCall(PetscPrintf(comm_, "  pre-period %3" PetscInt_FMT ": return distance %.3e at T + dt = %.9f s\n", k, (double)e,
                            (double)(T + dt)));
    // The corrected period is used from here on only while it stays near T0: far from the cycle
    // the first-order correction can be large and meaningless.
    if (std::abs(dt) < 0.05 * T0) T += dt;
    if (e < pre_tol) break;
  }
  PetscCall(PetscPrintf(comm_,
                        "shooting: start after %" PetscInt_FMT " period(s) of the flow from the given state (-shoot_pre_periods %" PetscInt_FMT
                        ", -shoot_pre_tol %g): return distance %.2e, T = %.9f s\n",
                        k, pre_periods, (double)pre_tol, (double)e, (double)T));
  pre_done_ = k, pre_T_ = T;
  PetscCall(PetscLogEventEnd(ev_pre, 0, 0, 0, 0));
  PetscCall(Pack(U, dU, T, x));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Newton(Vec x, ShootingResult &res)
{
  SNESConvergedReason reason;
  PetscFunctionBeginUser;
  PetscCall(VecCopy(x, best_x_));
  defl_m_ = 0;
  PetscCall(Unpack(x, wU_, wdU_, nullptr));
  PetscCall(EquilibriumDistance(wU_, wdU_, &dist0_));
  VecH f;
  PetscCall(VecDuplicate(x, f.out()));
  PetscCall(SNESSetFunction(snes_, f, ShootingCallbacks::Function, this));
  PetscCall(SNESSetJacobian(snes_, J_, J_, ShootingCallbacks::Jacobian, this));
  PetscCall(SNESSetApplicationContext(snes_, this));
  PetscCall(SNESSetUpdate(snes_, ShootingCallbacks::Update));
  PetscCall(SNESSetConvergenceTest(snes_, ShootingCallbacks::Converged, this, nullptr));
  PetscCall(SNESSolve(snes_, nullptr, x));
  PetscCall(SNESGetConvergedReason(snes_, &reason));
  PetscCall(SNESGetIterationNumber(snes_, &res.corrections));
  res.converged  = reason > 0;
  res.iterations = res.converged ? criterion_iterate_ : res.corrections;
  if (!res.converged && fail_reason_.empty()) PetscCall(NewtonFailure(reason));
  res.reason           = res.converged ? "converged" : fail_reason_;
  res.residual_history = hist_res_;
  res.period_history   = hist_T_;
  // The returned iterate: the solution, or the best one seen.
  if (!res.converged) PetscCall(VecCopy(best_x_, x));
  PetscCall(Unpack(x, aU_, adU_, &res.period));
  res.residual = res.converged ? hist_res_.back() : best_res_;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::NewtonFailure(SNESConvergedReason reason)
{
  PetscFunctionBeginUser;
  switch (reason) {
  case SNES_DIVERGED_LINE_SEARCH: fail_reason_ = "line search failure"; break;
  case SNES_DIVERGED_LINEAR_SOLVE: {
    KSP                ksp;
    KSPConvergedReason kr;
    PetscInt           kit;
    PetscCall(SNESGetKSP(snes_, &ksp));
    PetscCall(KSPGetConvergedReason(ksp, &kr));
    PetscCall(KSPGetIterationNumber(ksp, &kit));
    fail_reason_ = std::string("Krylov failure on the bordered system: ") + KSPConvergedReasons[kr] + " after " + std::to_string(kit) +
                   " iterations (-shoot_ksp_max_it, -shoot_ksp_rtol, -shoot_ksp_gmres_restart)";
    break;
  }
  case SNES_DIVERGED_FUNCTION_DOMAIN: fail_reason_ = "the period left (T0/2, 2 T0)"; break;
  default: fail_reason_ = SNESConvergedReasons[reason]; break;
  }
  PetscFunctionReturn(0);
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
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "shooting: %s in %" PetscInt_FMT " Newton iteration(s) (%" PetscInt_FMT
                                   " corrections applied), %" PetscInt_FMT " period integrations (Newton %" PetscInt_FMT
                                   ", Floquet %" PetscInt_FMT "; %" PetscInt_FMT " of them linear tangent integrations), %" PetscInt_FMT
                                   " step set-ups\n",
                                   res.reason.c_str(), res.iterations, res.corrections, res.flow_evaluations, res.newton_evaluations,
                                   res.floquet_evaluations, res.tangent_evaluations, res.setups));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "limit cycle period %.7f s (%.4f Hz), ||H||/||Z0|| = %.2e\n", (double)res.period,
                                   1 / (double)res.period, (double)res.residual));
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
  if (!res.floquet.empty()) {
    std::string verdict = res.floquet_verdict == "undecided" ? "UNDECIDED" : res.stable_cycle ? "STABLE" : "UNSTABLE";
    char        why[160];
    std::snprintf(why, sizeof why, " (margin 1 - max |L| = %.2e %s error %.2e)", (double)res.floquet_margin,
                  res.floquet_verdict == "undecided" ? "within the" : "beyond the", (double)res.floquet_error);
    PetscCall(PetscViewerASCIIPrintf(viewer, "Floquet multipliers (%s, %" PetscInt_FMT " phase(s) in one step): trivial one %.6f%+.6fi, |L - 1| = %.2e; cycle %s%s\n",
                                     res.floquet_method.c_str(), res.floquet_phases,
                                     res.floquet[res.trivial].real(), res.floquet[res.trivial].imag(),
                                     std::abs(res.floquet[res.trivial] - 1.0), verdict.c_str(), why));
    if (res.floquet_verdict == "undecided")
      PetscCall(PetscViewerASCIIPrintf(viewer, "  the multipliers' error is as large as the margin: refine -shoot_steps (the trivial "
                                               "multiplier's distance from 1 falls with the step) before trusting the verdict\n"));
    for (size_t i = 0; i < res.floquet.size() && i < 8; ++i)
      PetscCall(PetscViewerASCIIPrintf(viewer, "  %2zu  %+.6f %+.6fi  |L| = %.6f%s\n", i, res.floquet[i].real(), res.floquet[i].imag(),
                                       std::abs(res.floquet[i]), (PetscInt)i == res.trivial ? "  (trivial)" : ""));
    if (!res.floquet_at_z0.empty()) {
      PetscCall(PetscViewerASCIIPrintf(viewer,
                                       "  without the phase average (Jacobian at Z0): largest non-trivial |L| = %.6f, trivial |L - 1| = %.2e\n",
                                       res.largest_at_z0, std::abs(res.floquet_at_z0[res.trivial_at_z0] - 1.0)));
      if ((res.largest_at_z0 < 1) != res.stable_cycle)
        PetscCall(PetscViewerASCIIPrintf(viewer, "  WARNING: the two verdicts differ: the stability of this cycle depends on where the "
                                                 "status changes fall in their steps; refine -shoot_steps\n"));
    }
  }
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Write(const ShootingResult &res, io::H5Writer &out) const
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
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
