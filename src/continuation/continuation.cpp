#include "squeal/continuation/continuation.h"
#include "squeal/core/inf.h"
#include "squeal/core/errors.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace squeal {

PetscReal ContinuationPoint::LargestNonTrivial() const
{
  if (floquet.empty()) return NAN; // not computed (-floquet_compute 0)
  PetscReal m = 0;
  for (size_t i = 0; i < floquet.size(); ++i)
    if ((PetscInt)i != trivial) m = std::max(m, std::abs(floquet[i]));
  return m;
}

namespace {
// The monitor's stability column: "max|L| = 0.9996 stable", or that the multipliers were not asked for.
std::string Multipliers(const ContinuationPoint &p)
{
  if (p.floquet.empty()) return "multipliers not computed";
  char b[64];
  std::snprintf(b, sizeof b, "max|L| = %.4f %s", (double)p.LargestNonTrivial(), p.stable_cycle ? "stable" : "UNSTABLE");
  return b;
}
} // namespace

struct ContinuationCallbacks {
  // Product of the bordered Jacobian [dH/d(Z0,T) dH/dlambda; t^T S]: one flow for the (Z0, T)
  // part (forward difference, as in Shooting::JacobianProduct but from this corrector's own base
  // residual, which belongs to the current lambda), plus v_lambda times the stored dH/dlambda.
  static PetscErrorCode Mult(Mat J, Vec v, Vec y)
  {
    Continuation *c;
    PetscReal     vl, nv, nx, a;
    PetscFunctionBeginUser;
    PetscCall(MatShellGetContext(J, &c));
    PetscCall(c->FromExt(v, c->vx_, &vl));
    PetscCall(VecNorm(c->vx_, NORM_2, &nv));
    if (c->precond_) PetscCall(c->shoot_->JacobianProduct(c->x_, c->vx_, c->fp_)); // exact tangent along the flow at x_
    else if (nv > 0) {
      PetscCall(VecNorm(c->x_, NORM_2, &nx));
      const PetscReal eps = c->shoot_->fd_step * nx / nv;
      PetscCall(VecWAXPY(c->xp_, eps, c->vx_, c->x_));
      PetscCall(c->shoot_->Residual(c->xp_, c->fp_));
      ++c->flows_;
      PetscCall(VecAXPY(c->fp_, -1.0, c->f_));
      PetscCall(VecScale(c->fp_, 1.0 / eps));
    } else PetscCall(VecZeroEntries(c->fp_));
    PetscCall(VecAXPY(c->fp_, vl, c->fl_));
    PetscCall(c->RowDot(c->vx_, &a));
    PetscCall(c->ToExt(c->fp_, a + vl * c->row_l_, y));
    PetscFunctionReturn(0);
  }

  // [P^-1 b; c^T d]^-1 by its Schur complement, P shooting's preconditioner of the (Z0, T) block, b =
  // dH/dlambda, (c, d) the arclength row: xi = (rho - c^T P^-1 r) / (d - c^T P^-1 b), x = P^-1 r - xi P^-1 b.
  // Exact where P is the Jacobian's inverse.
  static PetscErrorCode Precondition(PC pc, Vec v, Vec y)
  {
    Continuation *c;
    PetscReal     rho, a;
    PetscFunctionBeginUser;
    PetscCall(PCShellGetContext(pc, &c));
    PetscCall(c->FromExt(v, c->vx_, &rho));
    PetscCall(c->shoot_->ApplyPreconditioner(c->vx_, c->wx_));
    PetscCall(c->RowDot(c->wx_, &a));
    const PetscReal den = c->row_l_ - c->cz_;
    const PetscReal xi  = den != 0 ? (rho - a) / den : 0.0;
    PetscCall(VecAXPY(c->wx_, -xi, c->pz_));
    PetscCall(c->ToExt(c->wx_, xi, y));
    PetscFunctionReturn(0);
  }
};

PetscErrorCode Continuation::RowDot(Vec vx, PetscReal *a) const
{
  PetscReal   vT;
  PetscScalar d1, d2;
  PetscFunctionBeginUser;
  PetscCall(shoot_->Unpack(vx, wU_, wdU_, &vT));
  PetscCall(VecDot(wU_, tan_->U, &d1));
  PetscCall(VecDot(wdU_, tan_->dU, &d2));
  *a = PetscRealPart(d1) / (su_ * su_) + PetscRealPart(d2) / (sdu_ * sdu_) + vT * tan_->T / (sT_ * sT_);
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::SetFromOptions()
{
  OptionChecks checks;
  char         name[16] = "mu", corr[16] = "auto";
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, "cont_", "Continuation of the limit cycle in mu or V", "Continuation");
  PetscCall(PetscOptionsString("-param", "Continuation parameter: mu or v", "Continuation", name, name, sizeof(name), nullptr));
  PetscCall(PetscOptionsReal("-min", "Lower end of the parameter range (default: mu 0, v 0.1)", "Continuation", lmin, &lmin, nullptr));
  PetscCall(PetscOptionsReal("-max", "Upper end of the parameter range (default: mu 0.6, v 10)", "Continuation", lmax, &lmax, nullptr));
  SquealOptionsReal("-ds", "Initial arclength step (scaled norm: U by the start cycle's size sqrt(||U0-Ue||^2 + ||dU0||^2/omega^2), dU by omega times it, T by T0, parameter by the range)",
                    "Continuation", &ds, Range::Positive(), checks);
  SquealOptionsReal("-ds_min", "Smallest step: a leg stops when a failed step would go below it", "Continuation", &ds_min,
                    Range::Positive(), checks);
  SquealOptionsReal("-ds_max", "Largest step", "Continuation", &ds_max, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-max_steps", "Points per leg at most", "Continuation", max_steps, &max_steps, nullptr));
  PetscCall(PetscOptionsInt("-max_it", "Corrector Newton iterations at most", "Continuation", max_it, &max_it, nullptr));
  SquealOptionsReal("-locate_tol", "Bisection tolerance in the parameter for regime changes (0: no bisection)", "Continuation",
                    &locate_tol, Range::NonNegative(), checks);
  SquealOptionsReal("-jump_tol", "Report a monodromy jump when a non-trivial |multiplier| changes by more than this between points",
                    "Continuation", &jump_tol, Range::Positive(), checks);
  SquealOptionsReal("-min_amplitude", "A leg ends (Hopf point) when the amplitude falls below this fraction of the start's",
                    "Continuation", &min_amplitude, Range::Closed(0.0, 1.0), checks);
  PetscCall(PetscOptionsBool("-equilibrium", "Stability of the sliding equilibrium at every point (Hopf point, hysteresis)",
                             "Continuation", equilibrium, &equilibrium, nullptr));
  PetscCall(PetscOptionsBool("-both", "Both directions from the start point (else towards -cont_max only)", "Continuation", both,
                             &both, nullptr));
  PetscCall(PetscOptionsBool("-monitor", "One progress line per point", "Continuation", monitor, &monitor, nullptr));
  PetscCall(PetscOptionsString("-corrector",
                               "arclength (Newton in (Z0, T, lambda), passes folds; above -shoot_jacobian_dense_max GMRES on exact tangents with "
                               "shooting's preconditioner), parameter (shooting's Newton at the predicted lambda; no folds), or auto (arclength, "
                               "parameter where shooting has no preconditioner)",
                               "Continuation", corr, corr, sizeof(corr), nullptr));
  PetscCall(PetscOptionsInt("-slices", "Parameter slices computed by groups of ranks, each from its own shooting solution at its upper end",
                            "Continuation", slices, &slices, nullptr));
  PetscCall(PetscOptionsInt("-fail_step", "Testing: declare the corrector of this step failed once (-1: never)", "Continuation",
                            fail_step, &fail_step, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  param = name;
  PetscCheck(param == "mu" || param == "v", comm_, kErrInput, "option -cont_param = '%s': expected mu or v", name);
  corrector = corr;
  PetscCheck(corrector == "auto" || corrector == "arclength" || corrector == "parameter", comm_, kErrInput,
             "option -cont_corrector = '%s': expected arclength, parameter or auto", corr);
  if (lmin == -kInf) lmin = param == "mu" ? 0.0 : 0.1;
  if (lmax == kInf) lmax = param == "mu" ? 0.6 : 10.0;
  PetscCheck(lmin < lmax, comm_, kErrInput, "options -cont_min = %g, -cont_max = %g: expected min < max", (double)lmin, (double)lmax);
  PetscCheck(param == "mu" ? lmin >= 0 : lmin > 0, comm_, kErrInput, "option -cont_min = %g: mu must be >= 0, v > 0", (double)lmin);
  PetscCheck(ds_min <= ds && ds <= ds_max, comm_, kErrInput, "options -cont_ds_min %g <= -cont_ds %g <= -cont_ds_max %g violated",
             (double)ds_min, (double)ds, (double)ds_max);
  PetscCheck(max_steps >= 1 && max_it >= 1, comm_, kErrInput, "options -cont_max_steps, -cont_max_it: expected >= 1");
  PetscCheck(slices >= 1, comm_, kErrInput, "option -cont_slices = %" PetscInt_FMT ": expected >= 1", slices);

  PC pc;
  PetscCall(KSPCreate(comm_, ksp_.out()));
  PetscCall(KSPSetOptionsPrefix(ksp_, "cont_"));
  PetscCall(KSPSetType(ksp_, KSPGMRES));
  PetscCall(KSPGetPC(ksp_, &pc));
  PetscCall(PCSetType(pc, PCNONE));
  // Finite-difference products carry ~1e-7 relative noise (as in shooting): no tighter than 1e-6.
  PetscCall(KSPSetTolerances(ksp_, 1e-6, PETSC_DEFAULT, PETSC_DEFAULT, 200));
  PetscCall(KSPSetFromOptions(ksp_));
  PetscCall(KSPGetTolerances(ksp_, &ksp_rtol_, &ksp_atol_, nullptr, nullptr));
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::SetParam(Model &model, PetscReal v) const
{
  PetscFunctionBeginUser;
  const ContactSet &cs = model.contacts;
  // The integrator's contact solver follows a new V by itself (ContactSet::FrictionState).
  model.contacts.SetFriction(param == "mu" ? v : cs.Mu(), param == "mu" ? cs.V() : v);
  PetscFunctionReturn(0);
}

PetscReal Continuation::GetParam(const Model &model) const { return param == "mu" ? model.contacts.Mu() : model.contacts.V(); }

PetscErrorCode Continuation::Create(State &s) const
{
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(model_->F, s.U.out()));
  PetscCall(VecDuplicate(model_->F, s.dU.out()));
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Copy(const State &x, State &y) const
{
  PetscFunctionBeginUser;
  if (!y.U) PetscCall(Create(y));
  PetscCall(VecCopy(x.U, y.U));
  PetscCall(VecCopy(x.dU, y.dU));
  y.T = x.T, y.lambda = x.lambda;
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Axpby(State &y, PetscReal a, const State &x, PetscReal b) const
{
  PetscFunctionBeginUser;
  PetscCall(VecAXPBY(y.U, a, b, x.U));
  PetscCall(VecAXPBY(y.dU, a, b, x.dU));
  y.T = a * x.T + b * y.T, y.lambda = a * x.lambda + b * y.lambda;
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Dot(const State &a, const State &b, PetscReal *d) const
{
  PetscScalar d1, d2;
  PetscFunctionBeginUser;
  PetscCall(VecDot(a.U, b.U, &d1));
  PetscCall(VecDot(a.dU, b.dU, &d2));
  *d = PetscRealPart(d1) / (su_ * su_) + PetscRealPart(d2) / (sdu_ * sdu_) + a.T * b.T / (sT_ * sT_) + a.lambda * b.lambda / (sl_ * sl_);
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::ToExt(Vec x, PetscReal last, Vec e) const
{
  const PetscScalar *a;
  PetscScalar       *b;
  PetscInt           nx, ne;
  PetscFunctionBeginUser;
  PetscCall(VecGetLocalSize(x, &nx));
  PetscCall(VecGetLocalSize(e, &ne));
  PetscCall(VecGetArrayRead(x, &a));
  PetscCall(VecGetArray(e, &b));
  for (PetscInt i = 0; i < nx; ++i) b[i] = a[i];
  if (ne > nx) b[nx] = last;
  PetscCall(VecRestoreArray(e, &b));
  PetscCall(VecRestoreArrayRead(x, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::FromExt(Vec e, Vec x, PetscReal *last) const
{
  const PetscScalar *b;
  PetscScalar       *a;
  PetscInt           nx, ne;
  PetscMPIInt        size;
  PetscReal          l = 0;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  PetscCall(VecGetLocalSize(x, &nx));
  PetscCall(VecGetLocalSize(e, &ne));
  PetscCall(VecGetArrayRead(e, &b));
  PetscCall(VecGetArray(x, &a));
  for (PetscInt i = 0; i < nx; ++i) a[i] = b[i];
  if (ne > nx) l = PetscRealPart(b[nx]);
  PetscCall(VecRestoreArray(x, &a));
  PetscCall(VecRestoreArrayRead(e, &b));
  PetscCallMPI(MPI_Bcast(&l, 1, MPIU_REAL, size - 1, comm_));
  *last = l;
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::FromRank0(const std::vector<PetscReal> &Z0, State &s) const
{
  VecScatter  sc;
  Vec         z;
  PetscMPIInt rank;
  PetscInt    N;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCall(VecGetSize(s.U, &N));
  PetscCall(VecScatterCreateToZero(s.U, &sc, &z));
  for (int part = 0; part < 2; ++part) {
    if (rank == 0) {
      PetscScalar *a;
      PetscCheck((PetscInt)Z0.size() == 2 * N, PETSC_COMM_SELF, PETSC_ERR_ARG_SIZ, "continuation: shooting Z0 has %zu entries, expected %" PetscInt_FMT,
                 Z0.size(), 2 * N);
      PetscCall(VecGetArray(z, &a));
      for (PetscInt i = 0; i < N; ++i) a[i] = Z0[part * N + i];
      PetscCall(VecRestoreArray(z, &a));
    }
    Vec t = part == 0 ? s.U : s.dU;
    PetscCall(VecScatterBegin(sc, z, t, INSERT_VALUES, SCATTER_REVERSE));
    PetscCall(VecScatterEnd(sc, z, t, INSERT_VALUES, SCATTER_REVERSE));
  }
  PetscCall(VecDestroy(&z));
  PetscCall(VecScatterDestroy(&sc));
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::FillPoint(const ShootingResult &sr, ContinuationPoint &pt) const
{
  PetscReal s[3] = {0, 0, 0};
  PetscFunctionBeginUser;
  pt.param        = GetParam(*model_);
  pt.period       = sr.period;
  pt.peak_to_peak = sr.peak_to_peak;
  for (PetscReal p : sr.peak_to_peak) s[0] = std::max(s[0], p);
  s[1] = sr.frac_separated, s[2] = sr.frac_stuck;
  // The orbit summary lives on rank 0; events are decided on every rank alike.
  PetscCallMPI(MPI_Bcast(s, 3, MPIU_REAL, 0, comm_));
  pt.amplitude = s[0], pt.frac_separated = s[1], pt.frac_stuck = s[2];
  pt.floquet           = sr.floquet;
  pt.trivial           = sr.trivial;
  pt.stable_cycle      = sr.stable_cycle;
  pt.newton_iterations = sr.corrections;
  pt.flow_evaluations  = sr.flow_evaluations;
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Corrector(const State &last, const State &pred, const State &t, State &y, PetscInt *its, std::string &why)
{
  PetscFunctionBeginUser;
  // The corrector's flows and GMRES products poll the signal inside each period integration (on
  // a fine step a flow takes seconds): a signal there fails this step only, and the leg stops
  // with its points so far.
  shoot_->interruptible = true;
  PetscCall(PushErrorHandlerQuietOnSignal());
  const PetscErrorCode err = CorrectorIterations(last, pred, t, y, its, why);
  PetscCall(PetscPopErrorHandler());
  shoot_->interruptible = false;
  if (err == PETSC_ERR_SIG) { // collective: InterruptPoint decides on every rank alike
    interrupted_ = true;
    why          = std::string("interrupted by ") + InterruptSignalName();
    PetscFunctionReturn(0);
  }
  PetscCall(err);
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::CorrectorIterations(const State &last, const State &pred, const State &t, State &y, PetscInt *its,
                                                 std::string &why)
{
  std::vector<PetscReal> hist;
  State                  d;
  PetscFunctionBeginUser;
  PetscCall(Copy(pred, y));
  PetscCall(Create(d));
  tan_ = &t;
  *its = 0;
  // Phase row anchored at the last point for the whole corrector, G(Z_last)^T (Z0 - Z_last) = 0:
  // re-anchoring at every iterate (as Shooting::Solve does) lets the phase drift along the orbit
  // from point to point, and on small cycles that drift is as large as the amplitude change, so
  // the secant loses the branch (seen near mu_c on case 1: the branch retraced itself).
  PetscCall(SetParam(*model_, last.lambda));
  PetscCall(shoot_->Pack(last.U, last.dU, last.T, x_));
  PetscCall(shoot_->SetAnchor(x_));
  ++flows_;
  for (PetscInt k = 0; k < max_it; ++k) {
    PetscReal nf, nU, ndU, a, dl, dT;
    PetscCall(InterruptRequested(comm_, &interrupted_));
    if (interrupted_) {
      why = std::string("interrupted by ") + InterruptSignalName();
      PetscFunctionReturn(0);
    }
    if (!(y.T > 0) || !(y.lambda > 0 || (param == "mu" && y.lambda == 0))) {
      // A corrector step past T = 0 or V = 0 (seen on case 1 in V near 1.25 m/s) is a failed step
      // to halve, not an error of the integrator's set-up.
      why = "the corrector left the physical domain (T = " + std::to_string(y.T) + " s, " + param + " = " + std::to_string(y.lambda) + ")";
      PetscFunctionReturn(0);
    }
    // dH/dlambda's flow first: the exact products' tangents follow the flow stored last, which
    // must be the residual's at lambda.
    const PetscReal el = shoot_->fd_step * std::max(std::abs(y.lambda), sl_);
    PetscCall(shoot_->Pack(y.U, y.dU, y.T, x_));
    PetscCall(SetParam(*model_, y.lambda + el));
    PetscCall(shoot_->Residual(x_, fl_));
    ++flows_;
    PetscCall(SetParam(*model_, y.lambda));
    PetscCall(shoot_->Residual(x_, f_));
    ++flows_;
    PetscCall(VecNorm(f_, NORM_2, &nf));
    PetscCall(VecNorm(y.U, NORM_2, &nU));
    PetscCall(VecNorm(y.dU, NORM_2, &ndU));
    const PetscReal res = nf / std::hypot(nU, ndU);
    if (PetscIsInfOrNanReal(res)) {
      why = "residual not finite (the period left (T0/2, 2 T0) of the last point, or NaN in the flow)";
      PetscFunctionReturn(0);
    }
    hist.push_back(res);
    const size_t n = hist.size();
    if (n >= 4 && hist[n - 1] > hist[n - 2] && hist[n - 2] > hist[n - 3] && hist[n - 3] > hist[n - 4]) {
      why = "the residual grew for 3 iterations in a row";
      PetscFunctionReturn(0);
    }
    // dH/dlambda at fixed (Z0, T); the phase row does not depend on lambda.
    PetscCall(VecAXPY(fl_, -1.0, f_));
    PetscCall(VecScale(fl_, 1.0 / el));
    row_l_ = t.lambda / (sl_ * sl_);
    if (precond_) {
      bool have;
      PetscCall(shoot_->PreparePreconditioner(x_, &have));
      PetscCheck(have, comm_, PETSC_ERR_PLIB, "continuation: shooting has no preconditioner for this model");
      PetscCall(shoot_->ApplyPreconditioner(fl_, pz_));
      PetscCall(RowDot(pz_, &cz_));
    }
    PetscCall(VecWAXPY(d.U, -1.0, pred.U, y.U));
    PetscCall(VecWAXPY(d.dU, -1.0, pred.dU, y.dU));
    d.T = y.T - pred.T, d.lambda = y.lambda - pred.lambda;
    PetscCall(Dot(t, d, &a));
    PetscCall(ToExt(f_, a, rhs_));
    PetscCall(VecScale(rhs_, -1.0));
    if (precond_) {
      // No linear residual below a thousandth of the corrector's own tolerance on ||H|| / ||Z0||:
      // the half brake's second iteration started at 3e-6 and took 10 tangent products to 1e-12.
      PetscCall(KSPSetTolerances(ksp_, ksp_rtol_, std::max(ksp_atol_, 1e-3 * shoot_->eps1 * std::hypot(nU, ndU)), PETSC_DEFAULT, PETSC_DEFAULT));
    }
    KSPConvergedReason kr;
    PetscCall(KSPSolve(ksp_, rhs_, dy_));
    PetscCall(KSPGetConvergedReason(ksp_, &kr));
    if (kr < 0) {
      why = std::string("GMRES on the bordered system: ") + KSPConvergedReasons[kr] + " (-cont_ksp_*)";
      PetscFunctionReturn(0);
    }
    PetscCall(FromExt(dy_, vx_, &dl));
    PetscCall(shoot_->Unpack(vx_, wU_, wdU_, &dT));
    PetscCall(VecAXPY(y.U, 1.0, wU_));
    PetscCall(VecAXPY(y.dU, 1.0, wdU_));
    y.T += dT, y.lambda += dl;
    *its = k + 1;
    // (6.3) at this iterate, its correction (applied) included, and the parameter settled too.
    if (res < shoot_->eps1 && std::abs(dT) / y.T < shoot_->eps2 && std::abs(dl) / sl_ < shoot_->eps2) {
      why.clear();
      PetscFunctionReturn(0);
    }
  }
  why = "no convergence in " + std::to_string(max_it) + " corrector iterations (-cont_max_it)";
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Polish(const State &y, ContinuationPoint &pt, State *sol, bool *ok, std::string &why, bool multipliers)
{
  SlidingEquilibrium eq;
  ShootingResult     sr;
  PetscErrorCode     err;
  PetscFunctionBeginUser;
  *ok = false;
  PetscCall(SetParam(*model_, y.lambda));
  // Failures below are results (the step is halved), not errors: keep PETSc quiet meanwhile.
  PetscCall(PetscPushErrorHandler(PetscIgnoreErrorHandler, nullptr));
  err = eqs_->Solve(*model_, eq);
  PetscCall(PetscPopErrorHandler());
  if (err) {
    why = "no sliding equilibrium at this parameter";
    PetscFunctionReturn(0);
  }
  if (wU_) { // (not yet for the start point, whose size is 1 in the norm scaled by it)
    // The cycle's size about this equilibrium in the arclength norm: the leg's steps stay below half
    // of it (Leg), so the branch is resolved where it shrinks onto the Hopf point.
    PetscReal nu, ndu;
    PetscCall(VecWAXPY(wU_, -1.0, eq.U, y.U));
    PetscCall(VecNorm(wU_, NORM_2, &nu));
    PetscCall(VecNorm(y.dU, NORM_2, &ndu));
    radius_ = std::sqrt(nu * nu / (su_ * su_) + ndu * ndu / (sdu_ * sdu_));
  }
  pt.equilibrium_unstable = -1;
  if (equilibrium) {
    StabilityResult sres;
    PetscCall(PetscPushErrorHandler(PetscIgnoreErrorHandler, nullptr));
    err = stab_->Solve(*model_, eq, sres);
    PetscCall(PetscPopErrorHandler());
    if (!err) {
      pt.equilibrium_unstable = (PetscInt)sres.unstable.size();
      pt.max_growth           = sres.MaxOscillatorySigma();
    }
  }
  // The point's Newton iterations and Floquet multipliers are most of its time: a signal there
  // fails this point only (the branch so far is kept) and the leg stops at its next poll.
  shoot_->interruptible = true;
  // The multipliers are most of a point's time on an FE model (the half brake: about 10 of 16 s),
  // and a point that the step control then rejects, or a bisection's, does not need them.
  PetscBool      &compute = shoot_->Floquet().compute;
  const PetscBool asked   = compute;
  compute                 = (PetscBool)(asked && multipliers);
  PetscCall(PetscPushErrorHandler(PetscIgnoreErrorHandler, nullptr));
  err = shoot_->Solve(*model_, eq, *ti_, y.U, y.dU, y.T, sr);
  PetscCall(PetscPopErrorHandler());
  const bool want       = compute;
  compute               = asked;
  shoot_->interruptible = false;
  flows_ += sr.flow_evaluations;
  if (err == PETSC_ERR_SIG) { // collective: InterruptPoint decides on every rank alike
    interrupted_ = true;
    why          = std::string("interrupted by ") + InterruptSignalName();
    PetscFunctionReturn(0);
  }
  if (err || !sr.converged) {
    char at[64];
    std::snprintf(at, sizeof at, "shooting at %s = %.6f: ", param.c_str(), (double)y.lambda);
    why = at + (sr.reason.empty() ? std::string("error ") + std::to_string(err) : sr.reason);
    PetscFunctionReturn(0);
  }
  if (sr.floquet.empty() && want) {
    why = "no Floquet multipliers";
    PetscFunctionReturn(0);
  }
  PetscCall(FillPoint(sr, pt));
  if (sol) {
    PetscCall(Copy(y, *sol));
    PetscCall(FromRank0(sr.Z0, *sol));
    sol->T = sr.period;
  }
  *ok = true;
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Leg(int dir, const State &start, std::vector<ContinuationPoint> &pts, std::vector<State> &sts,
                                 std::string &end)
{
  State     prev, last, t, pred, y;
  PetscReal h = ds;
  PetscFunctionBeginUser;
  pts.clear(), sts.clear();
  PetscCall(Copy(start, last));
  for (State *s : {&t, &pred, &y}) PetscCall(Create(*s));
  end = "-cont_max_steps points";
  bool      have_prev  = false;
  PetscReal last_ratio = -1; // predictor error / ds of the last rejected try of this step
  PetscReal amp_start = -1, growth_start = -1;
  while ((PetscInt)pts.size() < max_steps) {
    PetscReal nt;
    // SIGINT/SIGTERM: stop between points; the points so far are the result.
    PetscCall(InterruptRequested(comm_, &interrupted_));
    if (interrupted_) {
      end = std::string("interrupted by ") + InterruptSignalName();
      break;
    }
    // Unit tangent: the secant of the last two points, or a pure parameter step at the start.
    if (!have_prev) {
      PetscCall(VecZeroEntries(t.U));
      PetscCall(VecZeroEntries(t.dU));
      t.T = 0, t.lambda = dir * sl_;
    } else {
      PetscCall(Copy(last, t));
      PetscCall(Axpby(t, -1.0, prev, 1.0));
      PetscCall(Dot(t, t, &nt));
      PetscCall(VecScale(t.U, 1.0 / std::sqrt(nt)));
      PetscCall(VecScale(t.dU, 1.0 / std::sqrt(nt)));
      t.T /= std::sqrt(nt), t.lambda /= std::sqrt(nt);
    }
    PetscCall(Copy(last, pred));
    PetscCall(Axpby(pred, h, t, 1.0));
    ContinuationPoint pt;
    PetscLogDouble    t0, t1;
    PetscCall(PetscTime(&t0));
    const int before = flows_;
    // Past an end of the range: a last point exactly on it, by a shooting solve at fixed parameter
    // from the secant interpolated there (pred: the predictor, or a corrected point that the
    // arclength carried past the end, as at size 1 of the brake: mu = 0.160025 for 0.16).
    auto end_of_range = [&]() -> PetscErrorCode {
      const PetscReal bound = pred.lambda > lmax ? lmax : lmin;
      const PetscReal s     = (bound - last.lambda) / (pred.lambda - last.lambda);
      PetscCall(Axpby(pred, 1.0 - s, last, s)); // last + s (pred - last)
      pred.lambda = bound;
      bool        ok;
      std::string why;
      PetscCall(Polish(pred, pt, &y, &ok, why));
      if (ok) {
        PetscCall(PetscTime(&t1));
        pt.ds = s * h, pt.leg = dir, pt.seconds = t1 - t0, pt.flow_evaluations = flows_ - before;
        pts.push_back(pt);
        sts.emplace_back();
        PetscCall(Copy(y, sts.back()));
        if (monitor)
          PetscCall(PetscPrintf(comm_, "cont %c%3zu: %s = %.6f  T = %.7f s  amplitude %.4e m  separated %5.1f %%  stuck %5.1f %%  %s  (end of range)\n",
                                dir > 0 ? '+' : '-', pts.size(), param.c_str(), (double)pt.param, (double)pt.period, (double)pt.amplitude,
                                100 * (double)pt.frac_separated, 100 * (double)pt.frac_stuck, Multipliers(pt).c_str()));
        end = "reached the end of the range";
      } else end = interrupted_ ? why : "the shooting solve on the end of the range failed: " + why;
      return 0;
    };
    if (pred.lambda > lmax || pred.lambda < lmin) {
      PetscCall(end_of_range());
      break;
    }
    PetscInt    its = 0;
    std::string why;
    bool        ok = false;
    ++step_count_;
    if (by_parameter_) {
      // The point is shooting's solution at the predicted parameter, from the predicted (Z0, T);
      // its multipliers once the step control below accepts it.
      PetscCall(Polish(pred, pt, &y, &ok, why, false));
      its = pt.newton_iterations;
      if (!ok && why.empty()) why = "shooting failed";
    } else PetscCall(Corrector(last, pred, t, y, &its, why));
    if (why.empty() && step_count_ == fail_step) why = "declared failed by -cont_fail_step (test)", ok = false;
    if (why.empty() && have_prev) {
      // Step control by the predictor error (not on the first step: a pure parameter step): a corrected point farther than ds / 2 from the
      // predictor means the branch curves more than the step resolves, or the corrector jumped to
      // another piece of the branch (near mu_c on case 1 it retraced the branch with ds = 0.1).
      PetscReal e;
      PetscCall(Copy(y, t));
      PetscCall(Axpby(t, -1.0, pred, 1.0));
      PetscCall(Dot(t, t, &e));
      // Unless halving does not shrink the ratio: a kink of the branch (a contact status change),
      // where the secant is off by an O(1) angle whatever ds; accepted (seen at lift-off: 0.71 on case 1,
      // 1.53 on case 2); passing through the Hopf point onto the same cycles half a period on gave 5.2.
      const PetscReal ratio = std::sqrt(e) / h;
      const bool      kink  = last_ratio > 0 && ratio > 0.8 * last_ratio && ratio < 2;
      last_ratio            = ratio;
      if (ratio > 0.5 && !kink) {
        char msg[96];
        std::snprintf(msg, sizeof msg, "the corrected point is %.2f ds from the predictor (> 0.5)", (double)(std::sqrt(e) / h));
        why = msg;
      }
    }
    if (!why.empty()) ok = false;
    else if (!by_parameter_) PetscCall(Polish(y, pt, nullptr, &ok, why));
    else if (shoot_->Floquet().compute) {
      State sol; // Newton from its own solution: the residual's check, then the multipliers
      PetscCall(Polish(y, pt, &sol, &ok, why));
      if (ok) PetscCall(Copy(sol, y));
    }
    if (interrupted_) {
      end = std::string("interrupted by ") + InterruptSignalName();
      break;
    }
    if (!ok) {
      ++halvings_;
      if (h / 2 < ds_min) {
        PetscCall(PetscPrintf(comm_, "cont: step from %s = %.6f failed (%s); ds = %.3e cannot be halved below -cont_ds_min %.1e: leg ends\n",
                              param.c_str(), (double)last.lambda, why.c_str(), (double)h, (double)ds_min));
        end = "step failed at ds_min: " + why;
        break;
      }
      h /= 2;
      PetscCall(PetscPrintf(comm_, "cont: step from %s = %.6f failed (%s); halving ds to %.3e\n", param.c_str(), (double)last.lambda,
                            why.c_str(), (double)h));
      continue;
    }
    if (y.lambda > lmax || y.lambda < lmin) {
      PetscCall(Copy(y, pred));
      PetscCall(end_of_range());
      break;
    }
    PetscCall(PetscTime(&t1));
    pt.ds = h, pt.leg = dir, pt.seconds = t1 - t0, pt.flow_evaluations = flows_ - before, pt.newton_iterations = its;
    pts.push_back(pt);
    sts.emplace_back();
    PetscCall(Copy(y, sts.back()));
    if (monitor)
      PetscCall(PetscPrintf(comm_, "cont %c%3zu: %s = %.6f  T = %.7f s  amplitude %.4e m  separated %5.1f %%  stuck %5.1f %%  %s  %" PetscInt_FMT " its  ds %.3e  %.2f s\n",
                            dir > 0 ? '+' : '-', pts.size(), param.c_str(), (double)pt.param, (double)pt.period, (double)pt.amplitude,
                            100 * (double)pt.frac_separated, 100 * (double)pt.frac_stuck, Multipliers(pt).c_str(), its, (double)h, (double)pt.seconds));
    if (amp_start < 0) amp_start = pt.amplitude, growth_start = pt.max_growth;
    // The cycle shrinking onto the equilibrium: the Hopf point, where this branch is born. There
    // the equilibrium's growth rate goes to zero with the amplitude (as its square at a smooth
    // Hopf point; 1e-3 of the leg's first at the 3-DOF branches' ends); a growth rate still a
    // quarter of the first's means -cont_min_amplitude stopped a branch that goes on.
    if (pt.amplitude < min_amplitude * amp_start) {
      if (pt.equilibrium_unstable < 0) end = "the cycle shrank below -cont_min_amplitude of the leg's first (equilibrium not computed: -cont_equilibrium 0)";
      else if (pt.equilibrium_unstable == 0 || !(growth_start > 0) || pt.max_growth < 0.25 * growth_start)
        end = "the cycle shrank onto the sliding equilibrium (Hopf point)";
      else {
        char b[320];
        std::snprintf(b, sizeof b,
                      "the amplitude fell below -cont_min_amplitude = %g of the leg's first, but the sliding equilibrium's growth rate "
                      "is still %.3g 1/s (%.0f %% of the first's): not a Hopf point; lower -cont_min_amplitude",
                      (double)min_amplitude, (double)pt.max_growth, 100 * (double)(pt.max_growth / growth_start));
        end = b;
      }
      break;
    }
    PetscCall(Copy(last, prev));
    PetscCall(Copy(y, last));
    have_prev  = true;
    last_ratio = -1;
    if (its <= 3) h = std::min(1.5 * h, ds_max);
    else if (its >= 6) h = std::max(0.5 * h, ds_min);
    // Near the Hopf point the cycle is smaller than ds_max: a step of its own size jumped, on case 1
    // from the impact-aware start, from 1.06e-3 m sliding throughout (mu - mu_c = 1.6e-4) to the
    // separated cycles above lift-off, and the leg walked back up to mu = 0.5.
    h = std::max(std::min(h, 0.1 * radius_), ds_min);
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Run(Model &model, EquilibriumSolver &eqs, StabilitySolver &stab, ThetaIntegrator &ti, Shooting &shoot,
                                 const ShootingResult &start, ContinuationResult &res)
{
  PetscLogDouble t0, t1;
  PetscFunctionBeginUser;
  PetscCall(PetscTime(&t0));
  PetscCheck(start.converged, comm_, PETSC_ERR_ARG_WRONGSTATE, "continuation: the starting shooting solution did not converge");
  if (!ksp_) PetscCall(SetFromOptions());
  if (slices > 1) {
    PetscCall(RunSlices(res)); // the caller's model and start are not used: every slice builds its own
    PetscCall(PetscTime(&t1));
    res.seconds = t1 - t0;
    PetscFunctionReturn(0);
  }
  model_ = &model, eqs_ = &eqs, stab_ = &stab, ti_ = &ti, shoot_ = &shoot;
  // The branch polls between its own steps and keeps its points; an interrupt raised inside a
  // flow would lose them.
  // Its points start from the predictor on the branch, which the model's default pre-periods
  // (FE-sized models) would pull towards an attracting cycle: none unless given.
  struct Restore {
    Shooting &s;
    bool      was, pre;
    ~Restore() { s.interruptible = was, s.auto_pre_periods = pre; }
  } restore{shoot, shoot.interruptible, shoot.auto_pre_periods};
  shoot.interruptible    = false;
  shoot.auto_pre_periods = false;
  res                    = ContinuationResult{};
  res.param_name         = param;
  step_count_ = halvings_ = flows_ = 0;
  interrupted_            = false;
  const PetscReal lambda0 = GetParam(model);
  res.range_lo            = both ? lmin : lambda0;
  res.range_hi            = down_only_ ? lambda0 : lmax;
  PetscCheck(lambda0 >= lmin && lambda0 <= lmax, comm_, kErrInput,
             "continuation: the scene's %s = %g is outside [-cont_min, -cont_max] = [%g, %g]; widen the range", param.c_str(),
             (double)lambda0, (double)lmin, (double)lmax);

  State s0;
  PetscCall(Create(s0));
  PetscCall(FromRank0(start.Z0, s0));
  s0.T = start.period, s0.lambda = lambda0;

  // The start point: its equilibrium (for the norm's U scale and the equilibrium's stability).
  ContinuationPoint p0;
  {
    State sol;
    bool        ok;
    std::string why;
    PetscCall(Polish(s0, p0, &sol, &ok, why));
    PetscCheck(ok, comm_, PETSC_ERR_NOT_CONVERGED, "continuation: the start point does not reproduce: %s", why.c_str());
    SlidingEquilibrium eq;
    PetscCall(eqs.Solve(model, eq));
    VecH d;
    PetscCall(VecDuplicate(s0.U, d.out()));
    PetscCall(VecWAXPY(d, -1.0, eq.U, s0.U));
    // Scales that do not depend on where on the orbit the start sits: for a motion near one
    // harmonic, ||U - Ue||^2 + ||dU||^2 / omega^2 is the same at every phase; ||U0 - Ue|| and ||dU0||
    // alone are not (the impact-aware energy estimate's start on case 1 lands elsewhere on the
    // orbit than the former one, and the norm, hence the steps, changed with it).
    PetscReal nu, ndu;
    PetscCall(VecNorm(d, NORM_2, &nu));
    PetscCall(VecNorm(s0.dU, NORM_2, &ndu));
    const PetscReal omega = 2 * PETSC_PI / s0.T;
    su_                   = std::sqrt(nu * nu + ndu * ndu / (omega * omega));
    sdu_                  = omega * su_;
    if (!(su_ > 0)) su_ = 1, sdu_ = 1;
    // The parameter's scale in the arclength: the range's width, but no wider than the default
    // range (with -cont_max 1e6 the first step of ds = 0.05 jumped 5e4 m/s, to the range's end).
    sT_ = s0.T, sl_ = std::min(lmax - lmin, param == "mu" ? (PetscReal)0.6 : (PetscReal)10.0);
  }
  // On difference products without preconditioner, the arclength corrector's GMRES broke down on
  // the half brake (N = 782, multipliers 0.9993-0.9998) at every step from ds = 0.02 down to 1.6e-4.
  // So above the size where shooting's Jacobian is dense, the corrector takes shooting's exact
  // tangents and preconditioner; where shooting has none (the sparse back end), auto takes shooting
  // at the predicted parameter. Small models keep the difference products that their branches
  // were measured with.
  by_parameter_ = corrector == "parameter";
  precond_      = false;
  if (!by_parameter_ && 2 * model.Size() + 1 > shoot.jacobian_dense_max) {
    if (shoot.HasPreconditioner()) precond_ = true;
    else if (corrector == "auto") by_parameter_ = true;
  }
  if (by_parameter_)
    PetscCall(PetscPrintf(comm_,
                          "cont: corrector: shooting at the predicted %s (-cont_corrector %s%s); folds in %s are not passed\n", param.c_str(),
                          corrector.c_str(), corrector == "auto" ? ": shooting has no preconditioner for this model" : "", param.c_str()));
  else if (precond_)
    PetscCall(PetscPrintf(comm_,
                          "cont: corrector: arclength, GMRES on exact tangents preconditioned by shooting's preconditioner bordered by d/d%s "
                          "(-cont_corrector %s)\n",
                          param.c_str(), corrector.c_str()));
  // Work space of the corrector: the shooting state (U, dU, T) and the bordered one (+ lambda).
  PetscMPIInt rank, size;
  PetscInt    nx, Nx;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  for (VecH *v : {&x_, &f_, &fl_, &xp_, &fp_, &vx_}) PetscCall(shoot.CreateState(v->out()));
  PetscCall(VecDuplicate(model.F, wU_.out()));
  PetscCall(VecDuplicate(model.F, wdU_.out()));
  PetscCall(VecGetLocalSize(x_, &nx));
  PetscCall(VecGetSize(x_, &Nx));
  const PetscInt ne = nx + (rank == size - 1 ? 1 : 0);
  PetscCall(VecCreateMPI(comm_, ne, Nx + 1, rhs_.out()));
  PetscCall(VecDuplicate(rhs_, dy_.out()));
  PetscCall(MatCreateShell(comm_, ne, ne, Nx + 1, Nx + 1, this, J_.out()));
  PetscCall(MatShellSetOperation(J_, MATOP_MULT, (void (*)(void))ContinuationCallbacks::Mult));
  PetscCall(KSPSetOperators(ksp_, J_, J_));
  if (precond_) {
    PC pc;
    PetscCall(shoot.CreateState(pz_.out()));
    PetscCall(shoot.CreateState(wx_.out()));
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PCSetType(pc, PCSHELL));
    PetscCall(PCShellSetContext(pc, this));
    PetscCall(PCShellSetApply(pc, ContinuationCallbacks::Precondition));
    PetscCall(PCShellSetName(pc, "shooting's preconditioner bordered by dH/dlambda and the arclength row"));
    // Right: GMRES's residual is then the true one, which the tolerance is about.
    PetscCall(KSPSetPCSide(ksp_, PC_RIGHT));
  } else {
    PC        pc;
    PetscBool shell;
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCSHELL, &shell));
    if (shell) PetscCall(PCSetType(pc, PCNONE)); // a Run before on a larger model
  }

  if (monitor)
    PetscCall(PetscPrintf(comm_, "cont start: %s = %.6f  T = %.7f s  amplitude %.4e m  separated %5.1f %%  stuck %5.1f %%  %s\n",
                          param.c_str(), (double)p0.param, (double)p0.period, (double)p0.amplitude, 100 * (double)p0.frac_separated,
                          100 * (double)p0.frac_stuck, Multipliers(p0).c_str()));
  std::vector<ContinuationPoint> down, up;
  std::vector<State>             sdown, sup;
  std::string                    end_down, end_up;
  if (both) {
    PetscCall(Leg(-1, s0, down, sdown, end_down));
    PetscCall(PetscPrintf(comm_, "cont: leg towards %s = %g: %zu point(s), %s\n", param.c_str(), (double)lmin, down.size(), end_down.c_str()));
  }
  if (!interrupted_ && !down_only_) {
    PetscCall(Leg(+1, s0, up, sup, end_up));
    PetscCall(PetscPrintf(comm_, "cont: leg towards %s = %g: %zu point(s), %s\n", param.c_str(), (double)lmax, up.size(), end_up.c_str()));
  } else end_up = "not started (interrupted)";
  states_.clear();
  for (size_t i = down.size(); i-- > 0;) {
    res.points.push_back(down[i]);
    states_.push_back(std::move(sdown[i]));
  }
  res.points.push_back(p0);
  states_.emplace_back();
  PetscCall(Copy(s0, states_.back()));
  for (size_t i = 0; i < up.size(); ++i) {
    res.points.push_back(up[i]);
    states_.push_back(std::move(sup[i]));
  }
  if (both) res.leg_end.push_back(end_down);
  if (!down_only_) res.leg_end.push_back(end_up);
  PetscCall(Detect(res));
  PetscCall(SetParam(model, lambda0));
  res.halvings         = halvings_;
  res.interrupted      = interrupted_;
  res.flow_evaluations = flows_;
  PetscCall(PetscTime(&t1));
  res.seconds = t1 - t0;
  PetscFunctionReturn(0);
}

bool ContinuationResult::Covered() const
{
  if (points.empty() || interrupted) return false;
  PetscReal lo = kInf, hi = -kInf;
  for (const ContinuationPoint &p : points) lo = std::min(lo, p.param), hi = std::max(hi, p.param);
  const PetscReal tol = 1e-9 * std::max(range_hi - range_lo, (PetscReal)1e-300);
  return lo <= range_lo + tol && hi >= range_hi - tol;
}

PetscErrorCode Continuation::View(const ContinuationResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscReal sec = 0;
  PetscInt  fl  = 0;
  for (auto &p : res.points) sec += p.seconds, fl += p.flow_evaluations;
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "continuation in %s: %zu points, %" PetscInt_FMT " step halving(s), %.2f s (%.3f s and %.0f period integrations per point)\n",
                                   res.param_name.c_str(), res.points.size(), res.halvings, (double)res.seconds,
                                   res.points.empty() ? 0.0 : (double)(sec / res.points.size()),
                                   res.points.empty() ? 0.0 : (double)fl / res.points.size()));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  for (auto &e : res.leg_end) PetscCall(PetscViewerASCIIPrintf(viewer, "leg: %s\n", e.c_str()));
  if (!res.points.empty()) {
    const auto mm = std::minmax_element(res.points.begin(), res.points.end(),
                                        [](const ContinuationPoint &a, const ContinuationPoint &b) { return a.param < b.param; });
    PetscCall(PetscViewerASCIIPrintf(viewer, "%s: %s from %.6g to %.6g of the range [%.6g, %.6g] asked%s\n",
                                     res.Covered() ? "complete" : "partial", res.param_name.c_str(), (double)mm.first->param,
                                     (double)mm.second->param, (double)res.range_lo, (double)res.range_hi,
                                     res.Covered() ? "" : " (each leg above says why it stopped)"));
  }
  PetscCall(PetscViewerASCIIPrintf(viewer, "%10s %12s %12s %7s %7s %9s %9s %s\n", res.param_name.c_str(), "T (s)", "ampl. (m)", "sep %",
                                   "stick %", "max|L|", "eq. unst", "cycle"));
  for (auto &p : res.points) {
    char lmax[16] = "-";
    if (!p.floquet.empty()) std::snprintf(lmax, sizeof lmax, "%.4f", (double)p.LargestNonTrivial());
    PetscCall(PetscViewerASCIIPrintf(viewer, "%10.6f %12.8f %12.4e %7.1f %7.1f %9s %9" PetscInt_FMT " %s\n", (double)p.param,
                                     (double)p.period, (double)p.amplitude, 100 * (double)p.frac_separated, 100 * (double)p.frac_stuck, lmax,
                                     p.equilibrium_unstable, p.Verdict()));
  }
  for (auto &e : res.events)
    PetscCall(PetscViewerASCIIPrintf(viewer, "event %-16s %s = %.6f  (in [%.6f, %.6f])%s%s\n", e.type.c_str(), res.param_name.c_str(),
                                     (double)e.param, (double)e.lo, (double)e.hi, e.detail.empty() ? "" : ": ", e.detail.c_str()));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Write(const ContinuationResult &res, io::H5Writer &out) const
{
  PetscFunctionBeginUser;
  if (res.points.empty()) PetscFunctionReturn(0);
  const hsize_t n = res.points.size();
  hsize_t       N = n ? res.points[0].peak_to_peak.size() : 0, m = 0;
  PetscCallMPI(MPI_Bcast(&N, 1, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  for (auto &p : res.points) m = std::max<hsize_t>(m, p.floquet.size());
  std::vector<PetscReal> lam, T, amp, sep, stk, lmax, grow, sec, ptp, fl(n * m * 2, NAN);
  std::vector<PetscInt>  stable, equ, its, leg, slc;
  for (size_t i = 0; i < n; ++i) {
    const auto &p = res.points[i];
    lam.push_back(p.param), T.push_back(p.period), amp.push_back(p.amplitude), sep.push_back(p.frac_separated);
    stk.push_back(p.frac_stuck), lmax.push_back(p.LargestNonTrivial()), grow.push_back(p.max_growth), sec.push_back(p.seconds);
    stable.push_back(p.stable_cycle), equ.push_back(p.equilibrium_unstable), its.push_back(p.newton_iterations), leg.push_back(p.leg);
    slc.push_back(p.slice);
    for (hsize_t k = 0; k < N; ++k) ptp.push_back(k < p.peak_to_peak.size() ? p.peak_to_peak[k] : NAN);
    for (size_t k = 0; k < p.floquet.size(); ++k) fl[(i * m + k) * 2] = p.floquet[k].real(), fl[(i * m + k) * 2 + 1] = p.floquet[k].imag();
  }
  PetscCall(out.WriteArray("/continuation/param", {n}, lam.data()));
  PetscCall(out.WriteArray("/continuation/period", {n}, T.data()));
  PetscCall(out.WriteArray("/continuation/amplitude", {n}, amp.data()));
  PetscCall(out.WriteArray("/continuation/peak_to_peak", {n, N}, ptp.data()));
  PetscCall(out.WriteArray("/continuation/frac_separated", {n}, sep.data()));
  PetscCall(out.WriteArray("/continuation/frac_stuck", {n}, stk.data()));
  PetscCall(out.WriteArray("/continuation/floquet", {n, m, 2}, fl.data()));
  PetscCall(out.WriteArray("/continuation/largest_multiplier", {n}, lmax.data()));
  PetscCall(out.WriteIntArray("/continuation/stable", {n}, stable.data()));
  PetscCall(out.WriteIntArray("/continuation/equilibrium_unstable_modes", {n}, equ.data()));
  PetscCall(out.WriteArray("/continuation/equilibrium_growth_rate", {n}, grow.data()));
  PetscCall(out.WriteIntArray("/continuation/iterations", {n}, its.data()));
  PetscCall(out.WriteIntArray("/continuation/leg", {n}, leg.data()));
  PetscCall(out.WriteIntArray("/continuation/slice", {n}, slc.data()));
  PetscCall(out.WriteArray("/continuation/seconds", {n}, sec.data()));
  PetscCall(out.WriteAttribute("/continuation", "parameter", res.param_name.c_str()));
  PetscCall(out.WriteAttribute("/continuation", "step_halvings", res.halvings));
  PetscCall(out.WriteAttribute("/continuation", "flow_evaluations", res.flow_evaluations));
  PetscCall(out.WriteAttribute("/continuation", "seconds", res.seconds));
  PetscCall(out.WriteAttribute("/continuation", "interrupted", (PetscInt)res.interrupted));
  PetscCall(out.WriteAttribute("/continuation", "complete", (PetscInt)res.Covered()));
  PetscCall(out.WriteAttribute("/continuation", "range", std::vector<PetscReal>{res.range_lo, res.range_hi}));
  std::string legs;
  for (auto &e : res.leg_end) legs += (legs.empty() ? "" : "; ") + e;
  PetscCall(out.WriteAttribute("/continuation", "leg_end", legs.c_str()));
  const hsize_t          ne = res.events.size();
  std::vector<PetscReal> ep, elo, ehi;
  std::vector<PetscInt>  ei;
  std::string            types, details;
  for (auto &e : res.events) {
    ep.push_back(e.param), elo.push_back(e.lo), ehi.push_back(e.hi), ei.push_back(e.point);
    types += (types.empty() ? "" : ",") + e.type;
    details += (details.empty() ? "" : "\n") + e.detail;
  }
  PetscCall(out.WriteArray("/continuation/events/param", {ne}, ep.data()));
  PetscCall(out.WriteArray("/continuation/events/lo", {ne}, elo.data()));
  PetscCall(out.WriteArray("/continuation/events/hi", {ne}, ehi.data()));
  PetscCall(out.WriteIntArray("/continuation/events/point", {ne}, ei.data()));
  PetscCall(out.WriteAttribute("/continuation/events", "types", types.c_str()));
  PetscCall(out.WriteAttribute("/continuation/events", "details", details.c_str()));
  PetscFunctionReturn(0);
}

} // namespace squeal
