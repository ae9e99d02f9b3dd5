// Invariant circle of the stroboscopic map (include/squeal/torus/torus.h, docs/torus.md).
#include "squeal/torus/torus.h"
#include "squeal/integration/monodromy.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"
#include "squeal/steady/steady_state.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>

namespace squeal {

namespace {

// The Dirichlet kernel of order K = (M - 1)/2 and its derivative, as sums (no 0/0 at x = 0):
// D(x) = (1 + 2 sum_k cos k x) / M, so that the interpolant through u_l at theta_l is sum_l D(theta - theta_l) u_l.
PetscReal Dirichlet(PetscInt M, PetscReal x)
{
  PetscReal s = 1;
  for (PetscInt k = 1; k <= (M - 1) / 2; ++k) s += 2 * std::cos(k * x);
  return s / M;
}

PetscReal DirichletPrime(PetscInt M, PetscReal x)
{
  PetscReal s = 0;
  for (PetscInt k = 1; k <= (M - 1) / 2; ++k) s -= 2 * k * std::sin(k * x);
  return s / M;
}

} // namespace

Eigen::MatrixXd TorusSolver::ShiftMatrix(PetscInt M, PetscReal rho)
{
  Eigen::MatrixXd R(M, M);
  for (PetscInt j = 0; j < M; ++j)
    for (PetscInt l = 0; l < M; ++l) R(j, l) = Dirichlet(M, 2 * PETSC_PI * ((PetscReal)(j - l) / M + rho));
  return R;
}

Eigen::MatrixXd TorusSolver::DerivativeMatrix(PetscInt M)
{
  Eigen::MatrixXd D(M, M);
  for (PetscInt j = 0; j < M; ++j)
    for (PetscInt l = 0; l < M; ++l) D(j, l) = DirichletPrime(M, 2 * PETSC_PI * (PetscReal)(j - l) / M);
  return D;
}

Eigen::MatrixXd TorusSolver::FitCircle(const Eigen::MatrixXd &z, PetscReal rho, PetscInt M)
{
  // Basis 1, cos k a, sin k a (k <= (M - 1)/2) at a_k = 2 pi rho k; then the fit at theta_j.
  const PetscInt  K = z.cols(), nk = (M - 1) / 2;
  Eigen::MatrixXd B(K, M), E(M, M);
  auto            row = [&](PetscReal a, Eigen::MatrixXd &m, PetscInt i) {
    m(i, 0) = 1;
    for (PetscInt k = 1; k <= nk; ++k) m(i, 2 * k - 1) = std::cos(k * a), m(i, 2 * k) = std::sin(k * a);
  };
  for (PetscInt k = 0; k < K; ++k) row(2 * PETSC_PI * std::fmod(rho * k, 1.0), B, k);
  for (PetscInt j = 0; j < M; ++j) row(2 * PETSC_PI * j / M, E, j);
  const Eigen::MatrixXd C = B.colPivHouseholderQr().solve(z.transpose()); // M x n coefficients
  return (E * C).transpose();
}

PetscReal TorusSolver::EstimateRotation(const Eigen::MatrixXd &z)
{
  const PetscInt  K = z.cols();
  Eigen::MatrixXd c = z.colwise() - z.rowwise().mean();
  // First principal component's time series: the largest right singular vector.
  Eigen::BDCSVD<Eigen::MatrixXd> svd(c, Eigen::ComputeThinV);
  const Eigen::VectorXd          p = svd.matrixV().col(0);
  // Hann-windowed DFT on a fine grid of (0, 1/2], the peak refined by a parabola in the log power.
  const PetscInt         G = 64 * K;
  std::vector<PetscReal> pw(G + 1, 0);
  for (PetscInt g = 1; g <= G; ++g) {
    const PetscReal      nu = 0.5 * g / G;
    std::complex<double> s  = 0;
    for (PetscInt k = 0; k < K; ++k) s += (0.5 - 0.5 * std::cos(2 * PETSC_PI * k / (K - 1))) * p[k] * std::polar(1.0, -2 * PETSC_PI * nu * k);
    pw[g] = std::norm(s);
  }
  PetscInt best = 1;
  for (PetscInt g = 2; g <= G; ++g)
    if (pw[g] > pw[best]) best = g;
  PetscReal d = 0;
  if (best > 1 && best < G) {
    const PetscReal a = std::log(pw[best - 1]), b = std::log(pw[best]), e = std::log(pw[best + 1]);
    if (a - 2 * b + e < 0) d = 0.5 * (a - e) / (a - 2 * b + e);
  }
  return 0.5 * (best + d) / G;
}

// The SNES's context: the unknowns x = (w_0..w_{M-1}, T / T0, rho), w_j = u_j / s (per component),
// all on rank 0; every rank runs the same flows on the gathered x.
struct TorusSolver::Ctx {
  const FlowFn         *flow = nullptr;
  Eigen::VectorXd       s;
  Eigen::MatrixXd       w0, dw0, g0; // start circle (scaled), its theta derivative, the vector field there
  PetscInt              M = 0, n = 0, flows = 0, evaluations = 0;
  PetscReal             T0 = 0, wnorm = 1, rtol = 1e-6, eval_seconds = 0;
  VecScatter            scatter = nullptr;
  Vec                   full = nullptr;
  TorusResult          *res = nullptr;
  MPI_Comm              comm;
  bool                  monitor = false;
  std::chrono::steady_clock::time_point t0;
  // The preconditioner: the scaled monodromy and, per Fourier index, the LU of mono - e^{i 2 pi k rho}.
  Eigen::MatrixXd                                   mono_s;
  std::vector<Eigen::PartialPivLU<Eigen::MatrixXcd>> lu;
  PetscReal                                         lu_rho = -1;
  SNES                                              snes = nullptr;
};

struct TorusCallbacks {
  static PetscErrorCode Gather(TorusSolver::Ctx &c, Vec x, Eigen::VectorXd &out)
  {
    const PetscScalar *a;
    PetscFunctionBeginUser;
    PetscCall(VecScatterBegin(c.scatter, x, c.full, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(c.scatter, x, c.full, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecGetArrayRead(c.full, &a));
    out = Eigen::Map<const Eigen::VectorXd>(a, c.M * c.n + 2);
    PetscCall(VecRestoreArrayRead(c.full, &a));
    PetscFunctionReturn(0);
  }

  static PetscErrorCode Residual(SNES, Vec x, Vec f, void *ctx)
  {
    auto           &c = *static_cast<TorusSolver::Ctx *>(ctx);
    Eigen::VectorXd X, z1;
    const auto      t0 = std::chrono::steady_clock::now();
    PetscFunctionBeginUser;
    PetscCall(Gather(c, x, X));
    const PetscInt  M = c.M, n = c.n;
    const PetscReal T = X[M * n] * c.T0, rho = X[M * n + 1];
    PetscCheck(T > 0 && std::isfinite(T) && std::isfinite(rho), c.comm, PETSC_ERR_NOT_CONVERGED, "torus: Newton left the admissible set (T = %g s, rho = %g)",
               (double)T, (double)rho);
    const Eigen::Map<const Eigen::MatrixXd> W(X.data(), n, M);
    const Eigen::MatrixXd                   U = c.s.asDiagonal() * W; // unscaled states
    const Eigen::MatrixXd                   S = W * TorusSolver::ShiftMatrix(M, rho).transpose();
    Eigen::VectorXd                         F(M * n + 2);
    for (PetscInt j = 0; j < M; ++j) {
      PetscCall((*c.flow)(U.col(j), T, z1));
      ++c.flows;
      F.segment(j * n, n) = z1.cwiseQuotient(c.s) - S.col(j);
    }
    const Eigen::MatrixXd dW = W - c.w0;
    F[M * n]                 = (dW.cwiseProduct(c.dw0)).sum() / c.dw0.norm();
    F[M * n + 1]             = (dW.cwiseProduct(c.g0)).sum() / c.g0.norm();
    ++c.evaluations;
    c.eval_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    PetscMPIInt rank;
    PetscCallMPI(MPI_Comm_rank(c.comm, &rank));
    PetscScalar *a;
    PetscCall(VecGetArray(f, &a));
    if (rank == 0) std::copy(F.data(), F.data() + F.size(), a);
    PetscCall(VecRestoreArray(f, &a));
    PetscFunctionReturn(0);
  }

  // P^-1 on the circle's part (the DFT over the points, one solve per Fourier index), identity on (T, rho).
  static PetscErrorCode ApplyPC(PC pc, Vec r, Vec y)
  {
    TorusSolver::Ctx *cp;
    PetscFunctionBeginUser;
    PetscCall(PCShellGetContext(pc, &cp));
    auto          &c = *cp;
    const PetscInt M = c.M, n = c.n, K = (M - 1) / 2;
    Vec            x;
    Eigen::VectorXd X, R;
    PetscCall(SNESGetSolution(c.snes, &x));
    PetscCall(Gather(c, x, X));
    const PetscReal rho = X[M * n + 1];
    if (rho != c.lu_rho) {
      c.lu.clear();
      for (PetscInt k = -K; k <= K; ++k) {
        Eigen::MatrixXcd A = c.mono_s.cast<std::complex<double>>();
        A.diagonal().array() -= std::polar(1.0, 2 * PETSC_PI * k * rho);
        c.lu.emplace_back(A);
      }
      c.lu_rho = rho;
    }
    PetscCall(Gather(c, r, R));
    const Eigen::Map<const Eigen::MatrixXd> Rm(R.data(), n, M);
    Eigen::VectorXd                         Y = R;
    Eigen::Map<Eigen::MatrixXd>             Ym(Y.data(), n, M);
    Ym.setZero();
    for (PetscInt k = -K; k <= K; ++k) {
      Eigen::VectorXcd rk = Eigen::VectorXcd::Zero(n);
      for (PetscInt j = 0; j < M; ++j) rk += Rm.col(j).cast<std::complex<double>>() * std::polar(1.0, -2 * PETSC_PI * k * j / M);
      const Eigen::VectorXcd yk = c.lu[k + K].solve(rk / (double)M);
      for (PetscInt j = 0; j < M; ++j) Ym.col(j) += (yk * std::polar(1.0, 2 * PETSC_PI * k * j / M)).real();
    }
    PetscMPIInt rank;
    PetscCallMPI(MPI_Comm_rank(c.comm, &rank));
    PetscScalar *a;
    PetscCall(VecGetArray(y, &a));
    if (rank == 0) std::copy(Y.data(), Y.data() + Y.size(), a);
    PetscCall(VecRestoreArray(y, &a));
    PetscFunctionReturn(0);
  }

  // ||F|| / ||w|| below -torus_rtol (the norm of the circle's own unknowns, so the tolerance is relative to the motion).
  static PetscErrorCode Converged(SNES snes, PetscInt it, PetscReal, PetscReal, PetscReal fnorm, SNESConvergedReason *reason, void *ctx)
  {
    auto &c = *static_cast<TorusSolver::Ctx *>(ctx);
    PetscFunctionBeginUser;
    PetscCall(SNESConvergedDefault(snes, it, 0, 0, fnorm, reason, nullptr));
    if (*reason > 0) *reason = SNES_CONVERGED_ITERATING; // only the relative test below converges
    Vec             x;
    Eigen::VectorXd X;
    PetscCall(SNESGetSolution(snes, &x));
    PetscCall(Gather(c, x, X));
    const PetscReal rel = fnorm / X.head(c.M * c.n).norm();
    c.res->residual_history.push_back(rel);
    PetscInt lits = 0;
    PetscCall(SNESGetLinearSolveIterations(snes, &lits));
    if (c.monitor) {
      const PetscReal T = X[c.M * c.n] * c.T0, rho = X[c.M * c.n + 1];
      PetscCall(PetscPrintf(c.comm,
                            "  torus %2" PetscInt_FMT ": ||F||/||u|| %.3e  T %.9e s  rho %.9f  f1 %.4f Hz  f1*rho %.4f Hz  (%" PetscInt_FMT
                            " flows, %" PetscInt_FMT " Krylov its, %.1f s)\n",
                            it, (double)rel, (double)T, (double)rho, 1 / (double)T, (double)(rho / T), c.flows, lits,
                            std::chrono::duration<double>(std::chrono::steady_clock::now() - c.t0).count()));
    }
    if (rel < c.rtol) *reason = SNES_CONVERGED_FNORM_ABS;
    PetscFunctionReturn(0);
  }
};

TorusSolver::~TorusSolver()
{
  if (snes_) (void)SNESDestroy(&snes_);
}

PetscErrorCode TorusSolver::SetFromOptions()
{
  OptionChecks checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, "torus_", "Invariant torus of a quasi-periodic motion (invariant circle of the stroboscopic map)", "TorusSolver");
  PetscCall(PetscOptionsInt("-points", "Points M on the invariant circle (odd): trigonometric collocation of order (M-1)/2", "TorusSolver", points, &points,
                            nullptr));
  PetscCall(PetscOptionsReal("-f1", "Base frequency f1 (Hz), the stroboscopic period's 1/T (0: the start-up transient's measured period)", "TorusSolver", f1,
                             &f1, nullptr));
  checks.Add("torus_", "f1", &f1, Range::NonNegative());
  PetscCall(PetscOptionsReal("-f2", "Second frequency f2 (Hz) of the spectrum; rho = f2/f1 - 1 mod 1 (0: from the stroboscopic sequence)", "TorusSolver",
                             f2, &f2, nullptr));
  checks.Add("torus_", "f2", &f2, Range::NonNegative());
  PetscCall(PetscOptionsInt("-startup_periods", "Periods of the mode of the start-up transient (its -transient_* options) before the stroboscopic sequence",
                            "TorusSolver", startup_periods, &startup_periods, nullptr));
  PetscCall(PetscOptionsInt("-snapshots", "Stroboscopic samples the start circle is fitted on (PETSC_DECIDE: two turns of the circle, at least 4 M)",
                            "TorusSolver", snapshots, &snapshots, nullptr));
  PetscCall(PetscOptionsInt("-steps", "Theta-method steps per stroboscopic period", "TorusSolver", steps, &steps, nullptr));
  PetscCall(PetscOptionsInt("-retries", "Not converged: new starts, each 0.618 period further on the motion, at Newton's T and rho", "TorusSolver", retries,
                            &retries, nullptr));
  PetscCall(PetscOptionsInt("-refine_its", "Without -torus_f2: Newton iterations after which the sequence and start circle are made again at Newton's T and rho (0: never)",
                            "TorusSolver", refine_its, &refine_its, nullptr));
  PetscCall(PetscOptionsBool("-auto", "-analyses auto: after a quasi-periodic statistical steady state (two bases), the torus from its two lines (and its own start-up)",
                             "TorusSolver", in_auto, &in_auto, nullptr));
  PetscCall(PetscOptionsReal("-rtol", "Converged when ||F|| / ||u|| (scaled states) is below this", "TorusSolver", rtol, &rtol, nullptr));
  checks.Add("torus_", "rtol", &rtol, Range::Positive());
  PetscCall(PetscOptionsBool("-monitor", "One line per Newton iteration", "TorusSolver", monitor, &monitor, nullptr));
  PetscCall(PetscOptionsBool("-linear_pc", "Precondition GMRES with the steady sliding linearisation's monodromy, block-circulant over the circle (dense back end)",
                             "TorusSolver", linear_pc, &linear_pc, nullptr));
  PetscCall(PetscOptionsName("-view", "The torus after the solve ([viewer])", "TorusSolver", nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(points >= 3 && points % 2 == 1, comm_, kErrInput, "option -torus_points = %" PetscInt_FMT ": expected an odd number >= 3", points);
  PetscCheck(startup_periods >= 0, comm_, kErrInput, "option -torus_startup_periods = %" PetscInt_FMT ": expected >= 0", startup_periods);
  PetscCheck(snapshots == PETSC_DECIDE || snapshots >= points, comm_, kErrInput,
             "option -torus_snapshots = %" PetscInt_FMT ": expected at least -torus_points (%" PetscInt_FMT ")", snapshots, points);
  PetscCheck(retries >= 0, comm_, kErrInput, "option -torus_retries = %" PetscInt_FMT ": expected >= 0", retries);
  PetscCheck(refine_its >= 0, comm_, kErrInput, "option -torus_refine_its = %" PetscInt_FMT ": expected >= 0", refine_its);
  PetscCheck(steps >= 1, comm_, kErrInput, "option -torus_steps = %" PetscInt_FMT ": expected >= 1", steps);
  PetscCheck(f2 == 0 || f1 > 0, comm_, kErrInput, "option -torus_f2 = %g needs -torus_f1", (double)f2);
  if (!snes_) {
    PetscCall(SNESCreate(comm_, &snes_));
    PetscCall(SNESSetOptionsPrefix(snes_, "torus_"));
    KSP ksp;
    PetscCall(SNESGetKSP(snes_, &ksp));
    PetscCall(KSPSetType(ksp, KSPGMRES));
    PetscCall(KSPGMRESSetRestart(ksp, 100));
    PetscCall(KSPSetTolerances(ksp, 1e-4, PETSC_DEFAULT, PETSC_DEFAULT, 200));
    PetscCall(SNESSetTolerances(snes_, 0, 0, 0, 15, 10000));
    PetscCall(SNESKSPSetUseEW(snes_, PETSC_TRUE));
    // GMRES stopped at its iteration limit still gives a descent direction more often than not.
    PetscCall(SNESSetMaxLinearSolveFailures(snes_, 10));
    PetscCall(SNESSetFromOptions(snes_));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode TorusSolver::Solve(const FlowFn &flow, const Eigen::VectorXd &s, const Eigen::MatrixXd &circle, PetscReal T0, PetscReal rho0,
                                  TorusResult &res, const Eigen::MatrixXd *mono)
{
  Ctx         c;
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  if (!snes_) PetscCall(SetFromOptions());
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  const PetscInt M = circle.cols(), n = circle.rows();
  PetscCheck(M >= 3 && M % 2 == 1, comm_, kErrInput, "torus: %" PetscInt_FMT " points on the circle: expected an odd number >= 3", M);
  PetscCheck(s.size() == n && s.minCoeff() > 0, comm_, kErrInput, "torus: the scale needs %" PetscInt_FMT " positive entries", n);
  c.t0      = std::chrono::steady_clock::now();
  c.flow    = &flow;
  c.s       = s;
  c.M       = M;
  c.n       = n;
  c.T0      = T0;
  c.rtol    = rtol;
  c.comm    = comm_;
  c.res     = &res;
  c.monitor = monitor;
  res.M = M, res.n = n, res.T0 = T0, res.rho0 = rho0;
  res.residual_history.clear();
  c.w0  = s.cwiseInverse().asDiagonal() * circle;
  c.dw0 = c.w0 * DerivativeMatrix(M).transpose();
  // The vector field at the start circle from a short flow (a hundredth of the period): the time-shift phase condition.
  c.g0.resize(n, M);
  {
    Eigen::VectorXd z1;
    const PetscReal tau = T0 / 100;
    for (PetscInt j = 0; j < M; ++j) {
      PetscCall(flow(circle.col(j), tau, z1));
      c.g0.col(j) = (z1 - circle.col(j)).cwiseQuotient(s) / tau;
    }
  }
  Vec x, f;
  PetscCall(VecCreateMPI(comm_, rank == 0 ? M * n + 2 : 0, M * n + 2, &x));
  PetscCall(VecDuplicate(x, &f));
  PetscCall(VecScatterCreateToAll(x, &c.scatter, &c.full));
  {
    PetscScalar *a;
    PetscCall(VecGetArray(x, &a));
    if (rank == 0) {
      std::copy(c.w0.data(), c.w0.data() + M * n, a);
      a[M * n] = 1, a[M * n + 1] = rho0;
    }
    PetscCall(VecRestoreArray(x, &a));
  }
  Mat J;
  PetscCall(SNESSetFunction(snes_, f, TorusCallbacks::Residual, &c));
  PetscCall(MatCreateSNESMF(snes_, &J));
  PetscCall(MatSetOptionsPrefix(J, "torus_"));
  PetscCall(MatSetFromOptions(J));
  PetscCall(SNESSetJacobian(snes_, J, J, MatMFFDComputeJacobian, nullptr));
  PetscCall(SNESSetConvergenceTest(snes_, TorusCallbacks::Converged, &c, nullptr));
  {
    KSP ksp;
    PC  pc;
    PetscCall(SNESGetKSP(snes_, &ksp));
    PetscCall(KSPGetPC(ksp, &pc));
    c.snes = snes_;
    if (mono) {
      PetscCheck(mono->rows() == n && mono->cols() == n, comm_, kErrInput, "torus: the preconditioner's monodromy is %dx%d, expected %" PetscInt_FMT,
                 (int)mono->rows(), (int)mono->cols(), n);
      c.mono_s = s.cwiseInverse().asDiagonal() * (*mono) * s.asDiagonal();
      PetscCall(PCSetType(pc, PCSHELL));
      PetscCall(PCShellSetContext(pc, &c));
      PetscCall(PCShellSetApply(pc, TorusCallbacks::ApplyPC));
      PetscCall(PCShellSetName(pc, "torus: block-circulant linear monodromy"));
      PetscCall(KSPSetPCSide(ksp, PC_RIGHT));
    } else {
      PetscCall(PCSetType(pc, PCNONE));
    }
    res.preconditioned = mono != nullptr;
  }
  // A flow error (NaN, a contact solve that fails) inside Newton is a failed solve, reported, not an abort.
  PetscCall(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  PetscErrorCode ierr = SNESSolve(snes_, nullptr, x);
  PetscCall(PetscPopErrorHandler());
  SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
  if (!ierr) PetscCall(SNESGetConvergedReason(snes_, &reason));
  PetscCall(SNESGetIterationNumber(snes_, &res.iterations));
  PetscCall(SNESGetLinearSolveIterations(snes_, &res.krylov_iterations));
  res.converged = !ierr && reason > 0;
  res.reason    = ierr ? "error inside Newton (a flow failed or Newton left T > 0)" : SNESConvergedReasons[reason];
  Eigen::VectorXd X;
  PetscCall(TorusCallbacks::Gather(c, x, X));
  res.T        = X[M * n] * T0;
  res.rho      = X[M * n + 1];
  res.f1       = 1 / res.T;
  res.f2       = (1 + res.rho) / res.T;
  res.residual0 = res.residual_history.empty() ? 0 : res.residual_history.front();
  res.residual  = res.residual_history.empty() ? 0 : res.residual_history.back();
  res.flows += c.flows + M;
  res.seconds_per_residual = c.evaluations ? c.eval_seconds / c.evaluations : 0;
  res.seconds              = std::chrono::duration<double>(std::chrono::steady_clock::now() - c.t0).count();
  res.circle.clear();
  if (rank == 0) {
    const Eigen::MatrixXd U = s.asDiagonal() * Eigen::Map<const Eigen::MatrixXd>(X.data(), n, M);
    for (PetscInt j = 0; j < M; ++j)
      for (PetscInt i = 0; i < n; ++i) res.circle.push_back(U(i, j));
  }
  PetscCall(MatDestroy(&J));
  PetscCall(VecDestroy(&x));
  PetscCall(VecDestroy(&f));
  PetscCall(VecDestroy(&c.full));
  PetscCall(VecScatterDestroy(&c.scatter));
  PetscFunctionReturn(0);
}

PetscErrorCode TorusSolver::Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, ThetaIntegrator &ti,
                                TransientAnalysis &transient, TorusResult &res)
{
  const PetscInt N = model.Size(), nc = model.contacts.Size();
  PetscMPIInt    rank;
  PetscFunctionBeginUser;
  if (!snes_) PetscCall(SetFromOptions());
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  res = TorusResult{};
  // The start-up: the transient from the mode (as -analyses steady starts), its settings put back.
  TransientResult tr;
  {
    const PetscReal periods = transient.periods, t_final = transient.t_final, steps = transient.steps_per_period;
    const PetscInt  keep    = transient.keep_every;
    transient.periods = std::max<PetscInt>(startup_periods, 1), transient.t_final = 0;
    // As the statistics: at the transient's 1000 steps per period the 807-DOF pad's 300 start-up
    // periods were 300 000 steps, for an end state and a period.
    transient.steps_per_period = steady::StatisticsStepsPerPeriod(N, steps, transient.steps_given);
    if (transient.steps_per_period != steps)
      PetscCall(PetscPrintf(comm_, "torus: start-up at %g steps per period for N = %" PetscInt_FMT " DOFs (-transient_steps_per_period: chosen from the model unless given)\n",
                            (double)transient.steps_per_period, N));
    // Only the end state and the summary's period are used: about 50 records per period of the
    // mode do for the summary. Every step kept, the 807-DOF pad's 300 start-up periods held 5.1 GB.
    if (!transient.keep_every_set) transient.keep_every = std::max<PetscInt>(keep, (PetscInt)(transient.steps_per_period / 50));
    PetscErrorCode ierr = transient.Run(model, eq, stab, ti, tr);
    transient.periods = periods, transient.t_final = t_final, transient.keep_every = keep, transient.steps_per_period = steps;
    PetscCall(ierr);
  }
  res.startup_periods = startup_periods;
  PetscCheck(tr.complete, comm_, PETSC_ERR_NOT_CONVERGED, "torus: the start-up transient stopped early");
  std::vector<PetscReal> z(2 * N);
  if (rank == 0) {
    std::copy(tr.U.end() - N, tr.U.end(), z.begin());
    std::copy(tr.V.end() - N, tr.V.end(), z.begin() + N);
  }
  PetscCallMPI(MPI_Bcast(z.data(), (int)(2 * N), MPIU_REAL, 0, comm_));
  PetscReal T0 = f1 > 0 ? 1 / f1 : (tr.summary.period > 0 ? tr.summary.period / tr.summary.period_multiple : tr.T_ref);
  res.signal_dof = std::max<PetscInt>(0, tr.summary.signal_dof);

  // The period map Phi_T: -torus_steps theta steps of h = T / steps from the steady-sliding reactions, on y = z - z_e.
  AllGather gather;
  VecH      U, dU;
  PetscCall(VecDuplicate(model.F, U.out()));
  PetscCall(VecDuplicate(model.F, dU.out()));
  PetscCall(gather.SetUp(U));
  Eigen::VectorXd ze = Eigen::VectorXd::Zero(2 * N), r0 = Eigen::VectorXd::Zero(3 * nc);
  PetscCall(gather(eq.U, ze.head(N)));
  for (PetscInt c = 0; c < nc; ++c) r0[3 * c + kT] = model.contacts.Mu() * eq.N[c], r0[3 * c + kN] = eq.N[c];
  PetscInt lo, hi;
  PetscCall(VecGetOwnershipRange(U, &lo, &hi));
  PetscReal      h_set = -1;
  const PetscInt nsteps = steps;
  FlowFn         flow  = [&](const Eigen::VectorXd &y0, PetscReal T, Eigen::VectorXd &y1) -> PetscErrorCode {
    PetscFunctionBeginUser;
    // A short flow (the phase condition's vector field) takes one step of its own length.
    const PetscInt  ns = T < 0.5 * T0 ? 1 : nsteps;
    const PetscReal h  = T / ns;
    if (h != h_set) {
      PetscCall(ti.SetUp(model, h));
      h_set = h;
    }
    PetscScalar *u, *v;
    PetscCall(VecGetArray(U, &u));
    PetscCall(VecGetArray(dU, &v));
    for (PetscInt i = lo; i < hi; ++i) u[i - lo] = y0[i] + ze[i], v[i - lo] = y0[N + i];
    PetscCall(VecRestoreArray(U, &u));
    PetscCall(VecRestoreArray(dU, &v));
    Eigen::VectorXd r = r0;
    StepInfo        info;
    for (PetscInt k = 0; k < ns; ++k) {
      PetscCall(ti.Step(U, dU, r, &info));
      // An unconverged contact solve is noise in the flow, and MFFD differences it.
      if (!info.contact.converged) ++res.contact_unconverged, res.contact_residual_max = std::max(res.contact_residual_max, info.contact.residual);
    }
    y1.resize(2 * N);
    PetscCall(gather(U, y1.head(N)));
    PetscCall(gather(dU, y1.tail(N)));
    y1.head(N) -= ze.head(N);
    PetscCheck(y1.allFinite(), comm_, PETSC_ERR_FP, "torus: NaN in the period flow (T = %g s)", (double)T);
    PetscFunctionReturn(0);
  };

  // The stroboscopic sequence from the start-up's end (continued from y by later sequences).
  PetscReal rho = 0;
  if (f2 > 0) rho = f2 / f1 - 1 - std::floor(f2 / f1 - 1);
  Eigen::VectorXd y = Eigen::Map<Eigen::VectorXd>(z.data(), 2 * N) - ze, y1;
  auto sequence = [&](PetscReal T, PetscInt K, Eigen::MatrixXd &Y) -> PetscErrorCode {
    PetscFunctionBeginUser;
    Y.resize(2 * N, K);
    for (PetscInt k = 0; k < K; ++k) {
      Y.col(k) = y;
      PetscCall(flow(y, T, y1));
      y = y1;
    }
    res.flows += K;
    res.snapshots = K;
    res.snapshot_signal.clear();
    if (rank == 0)
      for (PetscInt k = 0; k < K; ++k) res.snapshot_signal.push_back(Y(res.signal_dof, k));
    PetscFunctionReturn(0);
  };
  // Two turns of the circle, at least 4 M samples.
  auto two_turns = [&](PetscReal r) { return std::clamp<PetscInt>((PetscInt)std::ceil(2 / std::max(std::min(r, 1 - r), 1e-3)), 4 * points, 400); };
  PetscInt K = snapshots;
  if (K == PETSC_DECIDE) K = rho > 0 ? two_turns(rho) : 200;
  Eigen::MatrixXd Y;
  PetscCall(sequence(T0, K, Y));
  if (rho == 0) rho = EstimateRotation(Y);
  // The fit on the last two turns only: T0 off by dT moves the samples along the flow by dT per
  // sample, and a longer sequence fits a wider band of the torus.
  Eigen::MatrixXd circle = FitCircle(Y.rightCols(std::min(K, two_turns(rho))), rho, points);
  // Displacements weighted by the base angular frequency, so that they count as velocities; both by the motion's size.
  const PetscReal w = 2 * PETSC_PI / T0, a = std::sqrt(Y.bottomRows(N).squaredNorm() / (N * K));
  PetscCheck(a > 0, comm_, PETSC_ERR_NOT_CONVERGED, "torus: no motion after the start-up (velocities all zero)");
  Eigen::VectorXd s(2 * N);
  s.head(N).setConstant(a / w);
  s.tail(N).setConstant(a);
  Eigen::MatrixXd mono;
  if (linear_pc && ti.Dense()) {
    // Weakly damped structural modes put many multipliers near the unit circle (as for shooting's
    // -shoot_linear_pc): those of the steady sliding linearisation, one step tangent at the
    // equilibrium reactions (every point closed and sliding) raised to the steps per period.
    const PetscReal h = T0 / nsteps;
    if (h != h_set) {
      PetscCall(ti.SetUp(model, h));
      h_set = h;
    }
    PetscCall(LinearMonodromy(ti, r0, nsteps, mono));
  }
  const Eigen::MatrixXd *pc = mono.size() ? &mono : nullptr;
  // An estimated start (no -torus_f2) is refined once: Newton's period and rotation number after
  // -torus_refine_its iterations make a new sequence and circle. The start-up's measured period is
  // the mean over its last few cycles, which the modulation biases (the small pad at V = 10 m/s:
  // 8664.02 Hz for a torus at 8662.42 Hz); a sequence sampled 2e-4 off the period drifts along the
  // flow by that much per sample, and Newton from the circle fitted on it crept at 1.2e-4 for 15
  // iterations, as from the spectrum's lines given with that f1 (5e-4). Fitted on a sequence at
  // Newton's period it converges as from the spectrum's lines (docs/torus.md).
  res.refined = false;
  if (f2 == 0 && refine_its > 0) {
    PetscInt  max_it, max_f;
    PetscReal atol, rtol_s, stol;
    PetscCall(SNESGetTolerances(snes_, &atol, &rtol_s, &stol, &max_it, &max_f));
    PetscCall(SNESSetTolerances(snes_, atol, rtol_s, stol, std::min(refine_its, max_it), max_f));
    PetscErrorCode ierr = Solve(flow, s, circle, T0, rho, res, pc);
    PetscCall(SNESSetTolerances(snes_, atol, rtol_s, stol, max_it, max_f));
    PetscCall(ierr);
    if (!res.converged && std::isfinite(res.T) && res.T > 0 && res.rho > 0 && res.rho < 1) {
      res.refined         = true;
      res.refine_T0       = T0, res.refine_rho0 = rho;
      res.refine_history  = res.residual_history;
      res.refine_seconds  = res.seconds;
      res.refine_iterations = res.iterations, res.refine_krylov = res.krylov_iterations;
      T0 = res.T, rho = res.rho;
      if (monitor)
        PetscCall(PetscPrintf(comm_, "  torus: start refined after %" PetscInt_FMT " iteration(s): a new sequence and circle at f1 %.4f Hz, rho %.9f\n",
                              res.iterations, 1 / (double)T0, (double)rho));
      // From the end of the first sequence: later on the same motion.
      PetscCall(sequence(T0, two_turns(rho), Y));
      circle = FitCircle(Y, rho, points);
      PetscCall(Solve(flow, s, circle, T0, rho, res, pc));
    }
  } else PetscCall(Solve(flow, s, circle, T0, rho, res, pc));
  // Not converged: another start elsewhere on the motion. Whether Newton converges depends on where
  // on the torus the start lies (the phase conditions pick the circle at the start's time phase):
  // on the small pad at V = 10 m/s the estimated start after 300 start-up periods stalled at
  // 1.2e-4, after 310 it converged (docs/torus.md). The state moves on by 0.618 of a period (a time
  // phase unlike the last's), then a new sequence at Newton's T and rho when they stayed close.
  for (PetscInt a = 0; a < retries && !res.converged; ++a) {
    if (std::isfinite(res.T) && std::abs(res.T - T0) < 1e-3 * T0 && res.rho > 0 && res.rho < 1) T0 = res.T, rho = res.rho;
    PetscCall(flow(y, 0.618 * T0, y1));
    y = y1;
    res.retry_history.push_back(res.residual);
    ++res.retries;
    if (monitor)
      PetscCall(PetscPrintf(comm_, "  torus: not converged (||F||/||u|| %.3e); retry %" PetscInt_FMT " from 0.618 period later, f1 %.4f Hz, rho %.9f\n",
                            (double)res.residual, res.retries, 1 / (double)T0, (double)rho));
    PetscCall(sequence(T0, two_turns(rho), Y));
    circle = FitCircle(Y, rho, points);
    PetscCall(Solve(flow, s, circle, T0, rho, res, pc));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode TorusSolver::View(const TorusResult &res, PetscViewer viewer) const
{
  PetscFunctionBeginUser;
  PetscCall(PetscViewerASCIIPrintf(viewer, "torus (invariant circle of the stroboscopic map, %" PetscInt_FMT " points): %s after %" PetscInt_FMT
                                           " Newton iteration(s) (%s), %" PetscInt_FMT " Krylov iterations, %" PetscInt_FMT " period flows, %.1f s (%.3f s per residual)\n",
                                   res.M, res.converged ? "converged" : "NOT converged", res.iterations, res.reason.c_str(), res.krylov_iterations,
                                   res.flows, (double)res.seconds, (double)res.seconds_per_residual));
  PetscCall(PetscViewerASCIIPrintf(viewer, "  ||F||/||u|| %.3e at the start circle (%" PetscInt_FMT " stroboscopic samples), %.3e at the end\n",
                                   (double)res.residual0, res.snapshots, (double)res.residual));
  const PetscReal fm = std::min(res.rho, 1 - res.rho) / res.T;
  PetscCall(PetscViewerASCIIPrintf(viewer, "  T = %.9e s: f1 = %.4f Hz, rotation number rho = %.8f: modulation f1 min(rho, 1 - rho) = %.4f Hz, f2 = f1 + %.4f = %.4f Hz\n",
                                   (double)res.T, (double)res.f1, (double)res.rho, (double)fm, (double)fm, (double)(res.f1 + fm)));
  PetscCall(PetscViewerASCIIPrintf(viewer, "  GMRES %s\n", res.preconditioned ? "preconditioned by the block-circulant linear monodromy" : "without preconditioner"));
  if (res.contact_unconverged)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  %" PetscInt_FMT " step(s) of the flows with an unconverged contact solve (largest residual %.2e)\n", res.contact_unconverged,
                                     (double)res.contact_residual_max));
  PetscCall(PetscViewerASCIIPrintf(viewer, "  start: f1 = %.4f Hz, rho = %.8f\n", 1 / (double)res.T0, (double)res.rho0));
  if (res.retries) {
    std::string h;
    for (PetscReal r : res.retry_history) h += (h.empty() ? "" : ", ") + std::to_string(r).substr(0, 8);
    PetscCall(PetscViewerASCIIPrintf(viewer, "  after %" PetscInt_FMT " retry(ies) (-torus_retries): the earlier starts ended at ||F||/||u|| %s; the counts above are the last start's\n",
                                     res.retries, h.c_str()));
  }
  if (res.refined) {
    PetscCall(PetscViewerASCIIPrintf(viewer, "  refined start (-torus_refine_its %" PetscInt_FMT "): the estimated f1 = %.4f Hz, rho = %.8f, ||F||/||u|| %.3e -> %.3e in %.1f s; "
                                             "sequence and circle made again at Newton's f1 and rho above\n",
                                     res.refine_iterations, 1 / (double)res.refine_T0, (double)res.refine_rho0,
                                     (double)(res.refine_history.empty() ? 0 : res.refine_history.front()),
                                     (double)(res.refine_history.empty() ? 0 : res.refine_history.back()), (double)res.refine_seconds));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode TorusSolver::ViewFromOptions(const TorusResult &res) const
{
  PetscFunctionBeginUser;
  PetscCall(squeal::ViewFromOptions(comm_, "torus_", [&](PetscViewer v) { return View(res, v); }));
  PetscFunctionReturn(0);
}

PetscErrorCode TorusSolver::Write(const TorusResult &res, io::H5Writer &out) const
{
  PetscFunctionBeginUser;
  unsigned long long sz[3] = {res.circle.size(), res.residual_history.size(), res.snapshot_signal.size()};
  PetscCallMPI(MPI_Bcast(sz, 3, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  PetscCall(out.WriteArray("/torus/circle", {(hsize_t)res.M, (hsize_t)(sz[0] / std::max<PetscInt>(res.M, 1))}, res.circle.data()));
  PetscCall(out.WriteArray("/torus/residual_history", {sz[1]}, res.residual_history.data()));
  PetscCall(out.WriteArray("/torus/snapshot_signal", {sz[2]}, res.snapshot_signal.data()));
  const char *g = "/torus";
  PetscCall(out.WriteAttribute(g, "converged", (PetscInt)res.converged));
  PetscCall(out.WriteAttribute(g, "reason", res.reason.c_str()));
  PetscCall(out.WriteAttribute(g, "period", res.T));
  PetscCall(out.WriteAttribute(g, "rotation_number", res.rho));
  PetscCall(out.WriteAttribute(g, "f1", res.f1));
  PetscCall(out.WriteAttribute(g, "f_modulation", std::min(res.rho, 1 - res.rho) / res.T));
  PetscCall(out.WriteAttribute(g, "residual", res.residual));
  PetscCall(out.WriteAttribute(g, "residual0", res.residual0));
  PetscCall(out.WriteAttribute(g, "iterations", res.iterations));
  PetscCall(out.WriteAttribute(g, "points", res.M));
  PetscCall(out.WriteAttribute(g, "krylov_iterations", res.krylov_iterations));
  PetscCall(out.WriteAttribute(g, "flows", res.flows));
  PetscCall(out.WriteAttribute(g, "signal_dof", res.signal_dof));
  PetscCall(out.WriteAttribute(g, "refined", (PetscInt)res.refined));
  PetscCall(out.WriteAttribute(g, "retries", res.retries));
  if (res.refined) {
    unsigned long long nr = res.refine_history.size();
    PetscCallMPI(MPI_Bcast(&nr, 1, MPI_UNSIGNED_LONG_LONG, 0, comm_));
    PetscCall(out.WriteArray("/torus/refine_history", {nr}, res.refine_history.data()));
    PetscCall(out.WriteAttribute(g, "refine_f1", 1 / res.refine_T0));
    PetscCall(out.WriteAttribute(g, "refine_rho", res.refine_rho0));
    PetscCall(out.WriteAttribute(g, "refine_seconds", res.refine_seconds));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
