// Newton on the bordered shooting system (docs/method.md §6): the residual (H, p), its Jacobian
// products (exact tangents or forward differences), the anchor of the phase row, the deflation of
// the sliding equilibrium, the SNES set-up for this model and the callbacks that carry the
// stopping rule (6.3), the anchor updates and the preconditioners.
#include "squeal/shooting/shooting.h"
#include "internal.h"
#include "squeal/core/inf.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace squeal {

PetscErrorCode ShootingCallbacks::Function(SNES, Vec x, Vec f, void *ctx)
{
  auto *s = static_cast<Shooting *>(ctx);
  PetscFunctionBeginUser;
  PetscCall(s->Residual(x, f));
  PetscFunctionReturn(0);
}

PetscErrorCode ShootingCallbacks::Jacobian(SNES snes, Vec x, Mat, Mat, void *ctx)
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
    if (s->jlinear_) PetscCall(s->RecycleSetUp(x));
    PetscFunctionReturn(0);
  }
  // The base point of the products: reuse the residual SNES just computed there.
  if (s->xbase_) PetscCall(VecEqual(x, s->xbase_, &same));
  if (!same) {
    PetscCall(VecCopy(x, s->xbase_));
    PetscCall(s->Residual(x, s->fbase_));
  }
  if (s->jlinear_) PetscCall(s->BuildLinearPreconditioner(x));
  PetscFunctionReturn(0);
}

// The dense bordered Jacobian's LU as preconditioner: GMRES converges in one iteration (or the
// LU of the linearised one, -shoot_linear_pc: GMRES then iterates on what the cycle adds).
PetscErrorCode ShootingCallbacks::DenseSolve(PC pc, Vec v, Vec y)
{
  Shooting       *s;
  Eigen::VectorXd z;
  PetscFunctionBeginUser;
  PetscCall(PCShellGetContext(pc, &s));
  PetscCall(s->ToNatural(v, z));
  Eigen::MatrixXd out;
  s->BasePreconditioner(z, out);
  // The recycled directions' correction: exact on span(J S) (RecycleSetUp).
  if (s->rec_Zc_.cols() > 0) out.noalias() += s->rec_Zc_ * (s->rec_Uc_.transpose() * z);
  PetscCall(s->FromNatural(out.col(0), y));
  PetscFunctionReturn(0);
}

void Shooting::BasePreconditioner(const Eigen::MatrixXd &z, Eigen::MatrixXd &y) const
{
  if (jdense_) y = jlu_.solve(z);
  else jpc_.Solve(z, y);
  if (defl_m_ > 0) y /= defl_m_; // (m J)^-1: the rank-one part of the deflated Jacobian is left to GMRES
}

PetscErrorCode ShootingCallbacks::Mult(Mat J, Vec v, Vec y)
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
  if (s->jlinear_ && s->recycle > 0) {
    // The pairs (w, J w) of this solve: the next Newton iteration recycles their Ritz vectors.
    Eigen::VectorXd w, Jw;
    PetscCall(s->ToNatural(v, w));
    PetscCall(s->ToNatural(y, Jw));
    if ((PetscInt)s->rec_w_.size() >= 4 * s->recycle) s->rec_w_.erase(s->rec_w_.begin()), s->rec_y_.erase(s->rec_y_.begin());
    s->rec_w_.push_back(std::move(w));
    s->rec_y_.push_back(std::move(Jw));
  }
  PetscFunctionReturn(0);
}

// GMRES on products: PETSc's test, and once ||H|| / ||Z0|| < eps1 the solve only has to tell
// whether |dT| / T < eps2 (quadratic convergence makes dT tiny there): a residual reduction of
// 1e-2 decides that and still improves the iterate, at a third of the products of a tight solve.
// Before that, a solve stops where its residual would put the next iterate below eps1 (Update).
PetscErrorCode ShootingCallbacks::KrylovConverged(KSP ksp, PetscInt it, PetscReal rnorm, KSPConvergedReason *reason, void *ctx)
{
  auto *s = static_cast<Shooting *>(ctx);
  PetscFunctionBeginUser;
  PetscCall(KSPConvergedDefault(ksp, it, rnorm, reason, s->ksp_default_ctx_));
  if (it == 0) s->rnorm0_ = rnorm;
  else if (*reason == KSP_CONVERGED_ITERATING && s->confirm_only_ && rnorm <= 1e-2 * s->rnorm0_) *reason = KSP_CONVERGED_RTOL;
  else if (*reason == KSP_CONVERGED_ITERATING && rnorm <= s->reach_ratio_ * s->rnorm0_) {
    // Only on the true residual (right preconditioning): with left preconditioning the chain's
    // preconditioned residual met the reduction in 2 iterations where the true one had not moved,
    // and Newton stalled for an iteration.
    KSPNormType nt;
    PetscCall(KSPGetNormType(ksp, &nt));
    if (nt == KSP_NORM_UNPRECONDITIONED) *reason = KSP_CONVERGED_RTOL;
  }
  PetscFunctionReturn(0);
}

PetscErrorCode ShootingCallbacks::Update(SNES snes, PetscInt)
{
  Shooting *s;
  Vec       x;
  PetscFunctionBeginUser;
  PetscCall(SNESGetApplicationContext(snes, &s));
  s->confirm_only_ = s->ew && !s->hist_res_.empty() && s->hist_res_.back() < s->eps1;
  PetscCall(SNESGetSolution(snes, &x));
  // Short of eps1, the step need not bring the linear residual (the next residual to first order)
  // below 0.3 eps1 ||Z||: where Eisenstat-Walker asks more (quadratic convergence's last step)
  // GMRES stops at that reduction of its true residual (right preconditioning, KrylovConverged),
  // and the next iterate confirms (records.md, "Step factors in float").
  s->reach_ratio_ = 0;
  if (s->ew && s->ksp_eps1_stop && !s->confirm_only_ && s->deflate_power <= 0 && !s->hist_res_.empty()) {
    PetscReal T, nU, ndU, fnorm;
    PetscCall(s->Unpack(x, s->wU_, s->wdU_, &T));
    PetscCall(VecNorm(s->wU_, NORM_2, &nU));
    PetscCall(VecNorm(s->wdU_, NORM_2, &ndU));
    PetscCall(SNESGetFunctionNorm(snes, &fnorm));
    if (fnorm > 0) s->reach_ratio_ = 0.3 * s->eps1 * std::hypot(nU, ndU) / fnorm;
  }
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

PetscErrorCode ShootingCallbacks::Converged(SNES snes, PetscInt it, PetscReal, PetscReal, PetscReal fnorm, SNESConvergedReason *reason,
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
  mon = (PetscBool)(mon || s->monitor);
  if (mon) {
    // Distance from the sliding equilibrium (the trivial root) and the flow's contact regime.
    PetscReal dq, open = 0, stick = 0;
    PetscCall(VecWAXPY(s->tmp_, -1.0, s->Ue_, s->wU_));
    PetscCall(VecNorm(s->tmp_, NORM_2, &dq));
    PetscBool same = PETSC_FALSE;
    if (s->tr_valid_) PetscCall(VecEqual(x, s->trx_, &same));
    const bool regime = same && s->trR_.rows() > 0; // the reactions are kept along the flow for exact products only
    if (regime) {
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
    char rtxt[64] = "regime not recorded";
    if (regime) std::snprintf(rtxt, sizeof rtxt, "open %.1f%% stick %.1f%%", 100 * (double)open, 100 * (double)stick);
    PetscCall(PetscPrintf(s->comm_,
                          "  shooting %2" PetscInt_FMT ": ||H||/||Z0|| = %.3e  T = %.9f s  dT/T = %.3e  |U-Ue| = %.3e |dU| = %.3e"
                          "  %s  ksp %" PetscInt_FMT "%s\n",
                          it, (double)res, (double)T, it > 0 ? (double)(std::abs(dT) / T) : 0.0, (double)dq, (double)ndU, rtxt, kit,
                          mtxt));
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
    // With a restart to come (-shoot_pre_retries), a Newton whose best residual has not improved for
    // retry_patience_ iterations makes way for it: on the half brake's interface-reduced model the
    // first start reached 4.6e-3 at iteration 7 and then wandered at 0.08-7 up to the 20th, while the
    // converging runs there improve every iteration or two once they go below their start.
    const size_t nb = (size_t)(std::min_element(s->hist_res_.begin(), s->hist_res_.end()) - s->hist_res_.begin());
    if (*reason == SNES_CONVERGED_ITERATING && s->retry_patience_ > 0 && n - 1 - nb >= (size_t)s->retry_patience_) {
      *reason         = SNES_DIVERGED_DTOL;
      s->fail_reason_ = "no better iterate in the last " + std::to_string(n - 1 - nb) + " Newton iterations";
    }
    PetscCall(SNESGetTolerances(snes, nullptr, nullptr, nullptr, &max_it, nullptr));
    if (*reason == SNES_CONVERGED_ITERATING && it >= max_it) {
      *reason        = SNES_DIVERGED_MAX_IT;
      s->fail_reason_ = "no convergence in " + std::to_string(max_it) + " Newton iterations (-shoot_snes_max_it)";
    }
  }
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
    char b[160];
    std::snprintf(b, sizeof b, "the period left (T0/2, 2 T0) = (%.6g, %.6g) s: T = %.6g s", (double)(0.5 * T0_), (double)(2 * T0_), (double)T);
    fail_reason_ = b;
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

// Krylov subspace recycling for the sequence of bordered systems (Parks, de Sturler et al., SIAM
// J. Sci. Comput. 28 (2006) 1651, in the form of a preconditioner update): with S orthonormal
// and Y = J S exactly (one block tangent integration: the columns share the stored flow and each
// step's factor, and run as matrix-matrix products, so k columns cost a few one-column products),
//   P_new^-1 z = P^-1 z + (S - P^-1 Y) (Y^T Y)^+ Y^T z
// maps J S c to S c: the preconditioned operator is the identity on span(S). GMRES then has to
// explore only what the new iterate adds. S is the span of the earlier solves' Krylov directions
// (the slowly converging ones recur from one Newton iteration to the next); it is only a subspace,
// so a stale S costs iterations, never accuracy.
void Shooting::RecycleSelect()
{
  using Eigen::Index;
  using Eigen::MatrixXd;
  const Index n = 2 * N_ + 1;
  // Every pair (w, J w) known at the last iterate: the recycled basis with its exact products, then
  // the last solve's Krylov products.
  Index m = rec_S_.rows() == n ? rec_S_.cols() : 0;
  for (const auto &w : rec_w_) m += w.size() == n;
  if (m == 0) return;
  MatrixXd W(n, m), Y(n, m);
  Index    k = 0;
  if (rec_S_.rows() == n && rec_YS_.cols() == rec_S_.cols()) W.leftCols(rec_S_.cols()) = rec_S_, Y.leftCols(rec_S_.cols()) = rec_YS_, k = rec_S_.cols();
  for (size_t i = 0; i < rec_w_.size(); ++i)
    if (rec_w_[i].size() == n) W.col(k) = rec_w_[i], Y.col(k) = rec_y_[i], ++k;
  rec_w_.clear(), rec_y_.clear();
  // Orthonormal Q spanning W (Gram-Schmidt twice, dependent columns dropped).
  MatrixXd Q(n, k), JQ;
  Index    q = 0;
  for (Index j = 0; j < k; ++j) {
    Eigen::VectorXd v  = W.col(j);
    const PetscReal n0 = v.norm();
    if (!(n0 > 0)) continue;
    for (int pass = 0; pass < 2; ++pass) v -= Q.leftCols(q) * (Q.leftCols(q).transpose() * v);
    const PetscReal nv = v.norm();
    if (!(nv > 1e-8 * n0)) continue;
    Q.col(q++) = v / nv;
  }
  Q.conservativeResize(n, q);
  // J Q from the pairs: Q = W X with X the least-squares coefficients (W has full column rank on
  // the kept columns; the dropped ones are in their span).
  const MatrixXd X = W.colPivHouseholderQr().solve(Q);
  JQ               = Y * X;
  // Rayleigh-Ritz for the preconditioned operator P^-1 J on span(Q): GMRES is slowed by the
  // eigenvalues away from the cluster at 1; recycle the Ritz vectors of the largest |theta - 1|.
  MatrixXd PJQ;
  BasePreconditioner(JQ, PJQ);
  const MatrixXd                   B = Q.transpose() * PJQ;
  Eigen::ComplexEigenSolver<MatrixXd> es(B, true);
  std::vector<Index>               order(q);
  for (Index i = 0; i < q; ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](Index a, Index b) {
    return std::abs(es.eigenvalues()(a) - 1.0) > std::abs(es.eigenvalues()(b) - 1.0);
  });
  // Real and imaginary parts of each chosen vector (a conjugate pair spans a real plane).
  MatrixXd G(q, 2 * q);
  Index    g = 0;
  for (Index i = 0; i < q && g < recycle; ++i) {
    const Eigen::VectorXcd y = es.eigenvectors().col(order[i]);
    for (int part = 0; part < 2 && g < recycle; ++part) {
      Eigen::VectorXd v = part == 0 ? Eigen::VectorXd(y.real()) : Eigen::VectorXd(y.imag());
      const PetscReal n0 = v.norm();
      if (!(n0 > 1e-12 * y.norm())) continue;
      for (int pass = 0; pass < 2; ++pass) v -= G.leftCols(g) * (G.leftCols(g).transpose() * v);
      if (!(v.norm() > 1e-8 * n0)) continue;
      G.col(g++) = v.normalized();
    }
  }
  rec_S_ = Q * G.leftCols(g);
}

PetscErrorCode Shooting::JacobianBlock(Vec x, const Eigen::MatrixXd &Z, Eigen::MatrixXd &Y)
{
  const Eigen::Index n2 = 2 * N_;
  Eigen::MatrixXd    dZ1;
  PetscFunctionBeginUser;
  // The block form of Mult: J z = (dZ(T) - dZ0, g^T dZ0), deflated m J z + (grad m . z) F.
  PetscCall(TangentFlow(x, Z.topRows(n2), Z.row(n2), dZ1));
  Y.resize(n2 + 1, Z.cols());
  Y.topRows(n2) = dZ1 - Z.topRows(n2);
  if (anchored_) {
    Eigen::VectorXd g(n2);
    PetscCall(Full(GaU_, g.head(N_)));
    PetscCall(Full(GadU_, g.tail(N_)));
    Y.row(n2) = g.transpose() * Z.topRows(n2);
  } else Y.row(n2).setZero();
  if (defl_m_ > 0) {
    Eigen::VectorXd gm(n2), F;
    PetscCall(Full(deflgU_, gm.head(N_)));
    PetscCall(Full(deflgdU_, gm.tail(N_)));
    PetscCall(ToNatural(deflF_, F));
    Y *= defl_m_;
    Y.noalias() += F * (gm.transpose() * Z.topRows(n2));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::RecycleSetUp(Vec x)
{
  PetscFunctionBeginUser;
  rec_Zc_.resize(0, 0), rec_Uc_.resize(0, 0);
  if (recycle <= 0) PetscFunctionReturn(0);
  RecycleSelect();
  if (rec_S_.cols() == 0) PetscFunctionReturn(0);
  Eigen::MatrixXd PY;
  PetscCall(JacobianBlock(x, rec_S_, rec_YS_));
  const Eigen::MatrixXd &Y = rec_YS_;
  recycled_columns_ += rec_S_.cols();
  // (Y^T Y)^+ Y^T = V Sigma^-1 U^T on the singular values above round-off.
  Eigen::BDCSVD<Eigen::MatrixXd> svd(Y, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd         &sv = svd.singularValues();
  Eigen::Index                   r  = 0;
  while (r < sv.size() && sv[r] > 1e-12 * sv[0]) ++r;
  if (r == 0) PetscFunctionReturn(0);
  BasePreconditioner(Y, PY);
  rec_Zc_ = (rec_S_ - PY) * svd.matrixV().leftCols(r) * sv.head(r).cwiseInverse().asDiagonal();
  rec_Uc_ = svd.matrixU().leftCols(r);
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
  PetscReal eps = fd_step * nx / nv;
  if (fd_motion && T0_ > 0) {
    // A step of fd_step times the motion's size in the metric (omega_0 U, dU, (d / T0) T): the
    // raw norm is the velocities' and would move the displacements by far more than their motion.
    PetscReal d, a, b, t;
    PetscCall(Unpack(x, U_, dU_, &t));
    PetscCall(EquilibriumDistance(U_, dU_, &d));
    PetscCall(Unpack(v, wU_, wdU_, &t));
    PetscCall(VecNorm(wU_, NORM_2, &a));
    PetscCall(VecNorm(wdU_, NORM_2, &b));
    const PetscReal w = 2 * PETSC_PI / T0_;
    const PetscReal s = std::sqrt(w * w * a * a + b * b + (d * t / T0_) * (d * t / T0_));
    if (d > 0 && s > 0) eps = fd_step * d / s;
  }
  PetscCall(VecWAXPY(xp_, eps, v, x));
  PetscCall(Residual(xp_, y));
  PetscCall(VecAXPY(y, -1.0, fbase_));
  PetscCall(VecScale(y, 1.0 / eps));
  PetscFunctionReturn(0);
}

void Shooting::DecideJacobianForm()
{
  jdense_  = ExactJacobian() && 2 * N_ + 1 <= jacobian_dense_max;
  // Difference products (-shoot_exact_jacobian 0) take the linear preconditioner where exact ones
  // would; below -shoot_jacobian_dense_max they keep plain GMRES on the small bordered system.
  jlinear_ = ti_ && ti_->Dense() && 2 * N_ + 1 > jacobian_dense_max && linear_pc && 2 * N_ <= linear_pc_max;
}

PetscErrorCode Shooting::PreparePreconditioner(Vec x, bool *have)
{
  PetscFunctionBeginUser;
  *have = false;
  if (!ExactJacobian() || deflate_power > 0) PetscFunctionReturn(0);
  DecideJacobianForm();
  if (!jdense_ && !jlinear_) PetscFunctionReturn(0);
  PetscCall(EnsureTrajectory(x));
  if (jdense_) PetscCall(BuildDenseJacobian(x));
  else PetscCall(BuildLinearPreconditioner(x));
  defl_m_ = 0;
  *have   = true;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::ApplyPreconditioner(Vec v, Vec y)
{
  Eigen::VectorXd z;
  Eigen::MatrixXd out;
  PetscFunctionBeginUser;
  PetscCall(ToNatural(v, z));
  BasePreconditioner(z, out);
  PetscCall(FromNatural(out.col(0), y));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::SetUpNewton()
{
  PetscFunctionBeginUser;
  DecideJacobianForm();
  {
    // GMRES on tangent products (one period integration each): far from the cycle Newton's step
    // needs no 1e-6 linear solve, so the Krylov tolerance follows the residual's decrease
    // (Eisenstat-Walker). On the 542-DOF pad: 58 products instead of 142 for the same cycle.
    // The dense Jacobian's LU solves exactly in one iteration: nothing to save there.
    PetscBool set = PETSC_FALSE;
    PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-snes_ksp_ew", &set));
    if (!set) {
      PetscCall(SNESKSPSetUseEW(snes_, (PetscBool)(ew && !jdense_ && (ExactJacobian() || jlinear_))));
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
      // Right preconditioning: GMRES then minimises the true residual, which Eisenstat-Walker's
      // tolerance is about, whatever the (recycled, changing) preconditioner does to its scale. On
      // the 562-DOF pad 5 Newton iterations instead of 6, on the 1420-DOF one 4 instead of 10. The
      // norm is set with the side: KSPSetUp fixed it for the side before (a KSP that ran left keeps
      // the preconditioned norm, which GMRES refuses on the right: PETSC_ERR_SUP at the
      // continuation's start point).
      PetscBool side_given = PETSC_FALSE, norm_given = PETSC_FALSE;
      PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-ksp_pc_side", &side_given));
      PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-ksp_norm_type", &norm_given));
      if (!side_given && (recycle > 0 || ew)) {
        PetscCall(KSPSetPCSide(ksp, PC_RIGHT));
        if (!norm_given) PetscCall(KSPSetNormType(ksp, KSP_NORM_UNPRECONDITIONED));
      }
    } else {
      PetscBool shell;
      PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCSHELL, &shell));
      if (shell) PetscCall(PCSetType(pc, PCNONE));
      if (!ExactJacobian() && exact_jacobian)
        PetscCall(PetscInfo(nullptr, "shooting: N = %" PetscInt_FMT " > -theta_dense_max: finite-difference products\n", N_));
    }
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Newton(Vec x, ShootingResult &res)
{
  SNESConvergedReason reason;
  PetscFunctionBeginUser;
  // Each start (the first, and every -shoot_pre_retries restart) anew: its own anchor, history,
  // best iterate and failure, and the linear preconditioner's monodromy at its own period (built at
  // the first Jacobian: over a period 1.3 % longer the lightly damped modes' phases move enough that
  // the half brake's restart from the state that converges in 8 iterations failed with the old one).
  // A restart of the same solve within 1e-3 of the period keeps it (the 90 kHz modes' phases move
  // by 0.08 rad at most); at size 1 of the brake example that saves the 17 s of its 3 716 columns.
  {
    PetscReal T;
    PetscCall(Unpack(x, aU_, adU_, &T));
    if (!(std::abs(T - Mlin_T_) <= 1e-3 * T)) Mlin_.resize(0, 0);
    jpc_.Reset();
  }
  PetscCall(VecSet(jx_, PETSC_INFINITY));
  anchored_ = false;
  hist_res_.clear();
  hist_T_.clear();
  best_res_ = kInf;
  fail_reason_.clear();
  criterion_iterate_ = -1;
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

} // namespace squeal
