#include "squeal/stability/stability.h"
#include "squeal/core/inf.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"

#include <Eigen/LU>
#include <petscblaslapack.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace squeal {

PetscReal StabilityResult::MaxOscillatorySigma(PetscInt *which) const
{
  PetscReal best = -kInf;
  if (which) *which = -1;
  for (size_t i = 0; i < modes.size(); ++i)
    if (modes[i].Oscillatory() && modes[i].sigma > best) {
      best = modes[i].sigma;
      if (which) *which = (PetscInt)i;
    }
  return best;
}

PetscErrorCode StabilitySolver::SetComputeModes(bool modes)
{
  PetscFunctionBeginUser;
  modes_ = modes;
  PetscFunctionReturn(0);
}

PetscErrorCode StabilitySolver::SetFromOptions()
{
  ST  st;
  KSP ksp;
  PetscBool modes = modes_ ? PETSC_TRUE : PETSC_FALSE;
  OptionChecks checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, prefix_.c_str(), "Linear stability of steady sliding", "StabilitySolver");
  PetscCall(PetscOptionsBool("-modes", "Compute and write mode shapes", "StabilitySolver::SetComputeModes", modes, &modes, nullptr));
  PetscCall(PetscOptionsName("-view", "Print the eigenvalue table (ascii viewer)", "StabilitySolver::View", nullptr));
  SquealOptionsReal("-fmax", "Band (Hz) covered completely: nev grows until every eigenvalue with |lambda| < 2 pi fmax converged (0: only the nev asked)",
                    "StabilitySolver", &fmax_, Range::NonNegative(), checks);
  SquealOptionsReal("-fmin", "Lower end of the band (Hz): unstable modes below it are listed but not reported", "StabilitySolver",
                    &fmin_, Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-nev_max", "Largest nev the band growth may use", "StabilitySolver", nev_max_, &nev_max_, nullptr));
  PetscCall(PetscOptionsReal("-guard_fmax",
                             "Before the nonlinear analyses (energy, shooting, transient, steady, auto, torus, continuation), look for "
                             "unstable modes above the band up to this frequency (Hz) too, since the time integration carries every mode "
                             "of the model (-1: the top fixed-interface mode of a reduction made in this run, else off; 0: off)",
                             "StabilitySolver::SolveUpTo", guard_fmax_, &guard_fmax_, nullptr));
  PetscCall(PetscOptionsBool("-guard_route",
                             "-analyses auto: when a mode above the band (-stab_guard_fmax) grows faster than the band's mode, the "
                             "statistical steady state from the pre-periods' end, without Newton on the band's cycle",
                             "StabilitySolver::GuardRoute", guard_route_, &guard_route_, nullptr));
  PetscCall(PetscOptionsInt("-guard_dense_max",
                            "Largest 2 n_r for which -stab_guard_fmax's eigenvalues are all computed by LAPACK (dense, on rank 0) "
                            "instead of by the eigensolver's growing nev (0: always the eigensolver)",
                            "StabilitySolver::SolveUpTo", guard_dense_max_, &guard_dense_max_, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(guard_dense_max_ >= 0, comm_, kErrInput, "option -%sguard_dense_max = %" PetscInt_FMT ": expected >= 0", prefix_.c_str(),
             guard_dense_max_);
  PetscCheck(guard_fmax_ == -1 || guard_fmax_ >= 0, comm_, kErrInput,
             "option -%sguard_fmax = %g: expected a frequency >= 0 (0: off) or -1 (the reduction's top mode)", prefix_.c_str(), (double)guard_fmax_);
  PetscCheck(nev_max_ >= 1, comm_, kErrInput, "option -%snev_max = %" PetscInt_FMT ": expected >= 1", prefix_.c_str(), nev_max_);
  PetscCheck(fmax_ == 0 || fmin_ < fmax_, comm_, kErrInput, "options -%sfmin = %g, -%sfmax = %g: expected fmin < fmax", prefix_.c_str(),
             (double)fmin_, prefix_.c_str(), (double)fmax_);
  modes_ = modes;

  PetscCall(PEPCreate(comm_, pep_.out()));
  PetscCall(PEPSetOptionsPrefix(pep_, prefix_.c_str()));
  PetscCall(PEPSetType(pep_, PEPTOAR));
  PetscCall(PEPSetProblemType(pep_, PEP_GENERAL));
  PetscCall(PEPSetWhichEigenpairs(pep_, PEP_TARGET_MAGNITUDE));
  PetscCall(PEPSetTarget(pep_, 0.0));
  // ||K_r|| / ||M_r|| ~ omega^2 ~ 1e5 and more: scale lambda.
  PetscCall(PEPSetScale(pep_, PEP_SCALE_SCALAR, PETSC_DECIDE, nullptr, nullptr, PETSC_DECIDE, PETSC_DECIDE));
  PetscCall(PEPGetST(pep_, &st));
  PetscCall(STSetType(st, STSINVERT));
  PetscCall(STGetKSP(st, &ksp));
  PetscCall(UseDirectSolver(ksp, Factorisation::General)); // K_r is non-symmetric
  PetscCall(PEPSetFromOptions(pep_));
  // SIGINT/SIGTERM within a restart of the eigensolver (a 1200-cell chain's solve ran 300 s deaf).
  PetscCall(PEPMonitorSet(
    pep_,
    [](PEP pep, PetscInt, PetscInt, PetscScalar *, PetscScalar *, PetscReal *, PetscInt, void *) -> PetscErrorCode {
      return InterruptPoint(PetscObjectComm((PetscObject)pep), "the stability eigensolve");
    },
    nullptr, nullptr));
  PetscFunctionReturn(0);
}

PetscErrorCode StabilitySolver::NormaliseMode(const Model &model, Mode &m) const
{
  std::vector<PetscReal> re, im;
  PetscFunctionBeginUser;
  // Divide by the largest tangential contact component: frame-independent, and phi_t = 1 for the
  // 3-DOF system as in the reference.
  PetscCall(model.contacts.LocalComponents(m.phi_re, re));
  PetscCall(model.contacts.LocalComponents(m.phi_im, im));
  std::complex<PetscReal> z(0, 0);
  for (size_t k = 0; k < re.size(); ++k) {
    if (k % 3 == kN) continue;
    const std::complex<PetscReal> w(re[k], im[k]);
    if (std::abs(w) > std::abs(z)) z = w;
  }
  if (std::abs(z) == 0) {
    PetscReal nrm;
    PetscCall(VecNorm(m.phi_re, NORM_INFINITY, &nrm));
    z = nrm > 0 ? nrm : 1.0;
  }
  // (re + i im) / z = ((a re + b im) + i (a im - b re)) / |z|^2
  const PetscReal a = z.real(), b = z.imag(), s = std::norm(z);
  VecH            tmp;
  PetscCall(VecDuplicate(m.phi_re, tmp.out()));
  PetscCall(VecAXPBYPCZ(tmp, a / s, b / s, 0.0, m.phi_re, m.phi_im));
  PetscCall(VecAXPBY(m.phi_im, -b / s, a / s, m.phi_re));
  PetscCall(VecCopy(tmp, m.phi_re));
  PetscFunctionReturn(0);
}

namespace {
// Modes by frequency, then growth rate; the unstable ones in the band, most unstable first.
void SortModes(StabilityResult &res)
{
  std::sort(res.modes.begin(), res.modes.end(), [](const Mode &a, const Mode &b) {
    return a.omega != b.omega ? a.omega < b.omega : a.sigma < b.sigma;
  });
  res.unstable.clear();
  for (size_t i = 0; i < res.modes.size(); ++i)
    if (res.modes[i].Unstable() && res.InBand(res.modes[i])) res.unstable.push_back((PetscInt)i);
  std::sort(res.unstable.begin(), res.unstable.end(),
            [&](PetscInt a, PetscInt b) { return res.modes[a].sigma > res.modes[b].sigma; });
}
} // namespace

PetscErrorCode StabilitySolver::SolveUpTo(const Model &model, const SlidingEquilibrium &eq, PetscReal fmax, StabilityResult &res)
{
  PetscFunctionBeginUser;
  if (!pep_) PetscCall(SetFromOptions());
  // n_r >= N - (contact points): only then is the reduced problem worth building here.
  if (2 * (model.Size() - model.contacts.Size()) <= guard_dense_max_) {
    ReducedProblem rp;
    bool           done = false;
    PetscCall(InterruptPoint(comm_, "the stability analysis (before its eigensolve)"));
    PetscCall(BuildReducedProblem(model, eq, rp));
    PetscCheck(rp.n_r > 0, comm_, kErrInput, "stability: every DOF is constrained by contact; nothing can vibrate");
    res.fmin = 0, res.fmax = fmax;
    if (2 * rp.n_r <= guard_dense_max_) PetscCall(SolveAllDense(rp, res, &done));
    if (done) PetscFunctionReturn(0);
  }
  const PetscReal fmax0 = fmax_, fmin0 = fmin_;
  const bool      modes0 = modes_;
  fmax_ = fmax, fmin_ = 0, modes_ = false;
  const PetscErrorCode ierr = Solve(model, eq, res);
  fmax_ = fmax0, fmin_ = fmin0, modes_ = modes0;
  PetscCall(ierr);
  PetscFunctionReturn(0);
}

// The guard wants the eigenvalues up to the reduction's top mode, a large part of the spectrum:
// on the size-1 brake example (CB 90 kHz, n_r = 1 682) TOAR's growing nev took 35 s and stopped
// at 58 of the 90 kHz (-stab_nev_max 1000), where LAPACK's dgeev finds all 3 364 in 9.4 s.
// M_r = L M Q is not symmetric (L carries the friction), so: x = D y with D = diag(M_r)^-1/2
// (the interface DOFs' masses and the modes' 1 differ by 1e5 on a Craig-Bampton model), the LU of
// D M_r D, and lambda = s mu with s^2 = max |(D M_r D)^-1 D K_r D|, which brings the companion
// matrix's entries to at most about 1, so the low modes keep their accuracy next to the constraint
// modes' MHz.
PetscErrorCode StabilitySolver::SolveAllDense(const ReducedProblem &rp, StabilityResult &res, bool *done) const
{
  const PetscInt         n = rp.n_r, n2 = 2 * rp.n_r;
  PetscMPIInt            rank;
  PetscInt               outcome = 0; // on rank 0: 1 eigenvalues, 0 not (M_r singular, dgeev failed): the eigensolver then
  std::vector<PetscReal> w(2 * (size_t)n2);
  PetscBLASInt           nb, lwork = -1, info = 0, one = 1;
  PetscFunctionBeginUser;
  *done = false;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCall(PetscBLASIntCast(n2, &nb)); // before rank 0's part: nothing there may fail alone before the broadcast
  Eigen::MatrixXd M, C, K;
  PetscCall(GatherMatrix(rp.Mr, false, M));
  PetscCall(GatherMatrix(rp.Cr, false, C));
  PetscCall(GatherMatrix(rp.Kr, false, K));
  if (rank == 0) {
    const Eigen::VectorXd d = M.diagonal().cwiseAbs().cwiseMax(PETSC_SMALL * M.cwiseAbs().maxCoeff()).cwiseSqrt().cwiseInverse();
    for (Eigen::MatrixXd *X : {&M, &C, &K}) *X = d.asDiagonal() * *X * d.asDiagonal();
    const Eigen::PartialPivLU<Eigen::MatrixXd> lu(M);
    const PetscReal                            rc = lu.rcond();
    if (rc > 1e3 * PETSC_MACHINE_EPSILON) {
      K = lu.solve(K), C = lu.solve(C);
      const PetscReal kmax = K.cwiseAbs().maxCoeff(), s = kmax > 0 ? std::sqrt(kmax) : 1.0;
      Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n2, n2);
      A.topRightCorner(n, n).setIdentity();
      A.bottomLeftCorner(n, n)  = -K / (s * s);
      A.bottomRightCorner(n, n) = -C / s;
      M.resize(0, 0), C.resize(0, 0), K.resize(0, 0);
      PetscReal vl = 0, vr = 0, wq = 0;
      LAPACKgeev_("N", "N", &nb, A.data(), &nb, w.data(), w.data() + n2, &vl, &one, &vr, &one, &wq, &lwork, &info);
      lwork = (PetscBLASInt)std::max<PetscReal>(std::ceil(wq), 3.0 * n2); // dgeev's minimum without vectors: 3 n
      std::vector<PetscReal> work((size_t)lwork);
      LAPACKgeev_("N", "N", &nb, A.data(), &nb, w.data(), w.data() + n2, &vl, &one, &vr, &one, work.data(), &lwork, &info);
      // Growth rates within the companion matrix's round-off of 0 are 0: an undamped mode must not
      // read as unstable (Mode::Unstable is sigma > 0) because dgeev put it at +1e-9.
      const PetscReal floor = 1e3 * PETSC_MACHINE_EPSILON * s;
      for (PetscInt i = 0; i < n2; ++i) w[i] = std::abs(w[i] * s) <= floor ? 0.0 : w[i] * s, w[n2 + i] *= s;
      outcome = info == 0 ? 1 : 0;
      if (info) PetscCall(PetscInfo(nullptr, "stability: LAPACK dgeev failed (info %d); the guard's eigenvalues by the eigensolver\n", (int)info));
    } else PetscCall(PetscInfo(nullptr, "stability: M_r is singular (rcond %g); the guard's eigenvalues by the eigensolver\n", (double)rc));
  }
  PetscCallMPI(MPI_Bcast(&outcome, 1, MPIU_INT, 0, comm_));
  if (outcome == 0) PetscFunctionReturn(0);
  PetscCallMPI(MPI_Bcast(w.data(), (PetscMPIInt)w.size(), MPIU_REAL, 0, comm_));
  res.modes.clear();
  for (PetscInt i = 0; i < n2; ++i) {
    const PetscReal re = w[i], im = w[n2 + i];
    if (im < 0) continue; // dgeev lists each complex pair with the positive imaginary part first
    Mode m;
    m.sigma = re;
    m.omega = std::abs(im) <= 1e-12 * std::hypot(re, im) ? 0.0 : im;
    m.error = 0; // no eigenvector, no backward error: dgeev's is eps ||A||
    res.modes.push_back(std::move(m));
  }
  res.n_r = n, res.requested = res.converged = n2, res.solves = 1;
  res.all_eigenvalues = true, res.complete_radius = kInf;
  SortModes(res);
  *done = true;
  PetscFunctionReturn(0);
}

PetscErrorCode StabilitySolver::Solve(const Model &model, const SlidingEquilibrium &eq, StabilityResult &res)
{
  ReducedProblem rp;
  PetscFunctionBeginUser;
  if (!pep_) PetscCall(SetFromOptions());
  // A signal during the equilibrium (one factorisation, not polled inside) stops here.
  PetscCall(InterruptPoint(comm_, "the stability analysis (before its eigensolve)"));
  PetscCall(BuildReducedProblem(model, eq, rp));
  PetscCheck(rp.n_r > 0, comm_, kErrInput, "stability: every DOF is constrained by contact; nothing can vibrate");

  Mat A[3] = {rp.Kr, rp.Cr, rp.Mr};
  PetscCall(PEPSetOperators(pep_, 3, A));
  PetscInt nev, ncv, mpd;
  PetscCall(PEPGetDimensions(pep_, &nev, &ncv, &mpd));
  // All 2 n_r eigenvalues of a small problem unless the user asked for fewer.
  PetscBool nev_set, ncv_set;
  PetscCall(PetscOptionsHasName(nullptr, prefix_.c_str(), "-pep_nev", &nev_set));
  PetscCall(PetscOptionsHasName(nullptr, prefix_.c_str(), "-pep_ncv", &ncv_set));
  const PetscInt n_all = 2 * rp.n_r;
  if (!nev_set) nev = PetscMin(n_all, 8);
  nev = PetscMin(nev, n_all);
  const PetscInt  nev_cap = PetscMax(nev, PetscMin(nev_max_, n_all));
  const PetscReal R       = 2 * PETSC_PI * fmax_;
  // The certificate below rests on shift-and-invert converging in order of |lambda - target|:
  // with the target moved (-pep_target) the converged disc is centred there, and the disc about 0
  // it contains has radius rho - |target|; another ST or selection gives no order to rely on, so
  // only the whole spectrum decides (a target of 3000 1/s on the 200-cell chain claimed
  // "complete up to 100 Hz" with every mode below 35 Hz missing).
  PetscScalar target;
  PEPWhich    which;
  PetscBool   sinvert;
  PetscCall(PEPGetTarget(pep_, &target));
  PetscCall(PEPGetWhichEigenpairs(pep_, &which));
  {
    ST st;
    PetscCall(PEPGetST(pep_, &st));
    PetscCall(PetscObjectTypeCompare((PetscObject)st, STSINVERT, &sinvert));
  }
  const bool      ordered = sinvert && which == PEP_TARGET_MAGNITUDE;
  const PetscReal tau     = PetscAbsScalar(target);
  res.fmin = fmin_;
  res.fmax = fmax_;
  res.n_r  = rp.n_r;
  res.solves = 0;
  std::vector<PetscReal> mods;
  for (;;) {
    PetscCall(PEPSetDimensions(pep_, nev, ncv_set ? ncv : PETSC_DEFAULT, PETSC_DEFAULT));
    PetscCall(PEPSolve(pep_));
    res.solves++;
    PEPConvergedReason reason;
    PetscCall(PEPGetConvergedReason(pep_, &reason));
    PetscCall(PEPGetConverged(pep_, &res.converged));
    res.requested = nev;
    PetscCheck(reason > 0 || res.converged > 0 || nev < nev_cap, comm_, PETSC_ERR_NOT_CONVERGED,
               "stability: the eigensolver converged no eigenvalue (reason %s); try -%spep_max_it or -%spep_ncv",
               PEPConvergedReasons[reason], prefix_.c_str(), prefix_.c_str());
    // The certificate (header): the nev-th smallest converged |lambda|; nothing if fewer converged.
    mods.clear();
    for (PetscInt i = 0; i < res.converged; ++i) {
      PetscScalar kr, ki;
      PetscCall(PEPGetEigenpair(pep_, i, &kr, &ki, nullptr, nullptr));
      mods.push_back(std::hypot(PetscRealPart(kr) - PetscRealPart(target), PetscRealPart(ki) - PetscImaginaryPart(target)));
    }
    std::sort(mods.begin(), mods.end());
    res.all_eigenvalues = res.converged >= n_all;
    res.complete_radius = res.all_eigenvalues ? kInf : (ordered && res.converged >= nev ? PetscMax(mods[nev - 1] - tau, 0.0) : 0.0);
    if (fmax_ == 0 || res.BandCovered() || nev >= nev_cap) break;
    // Grow in proportion to the missing part of the band (at least double): one or two solves.
    const PetscReal reached = mods.empty() || !ordered ? 0.0 : PetscMax(mods.back() - tau, 0.0);
    PetscInt        next    = 2 * nev;
    if (reached > 0) next = PetscMax(next, (PetscInt)std::ceil(1.2 * nev * R / reached));
    nev = PetscMin(next, nev_cap);
  }
  PetscCheck(res.converged > 0, comm_, PETSC_ERR_NOT_CONVERGED,
             "stability: the eigensolver converged no eigenvalue; try -%spep_max_it or -%spep_ncv", prefix_.c_str(), prefix_.c_str());

  VecH xr, xi;
  PetscCall(MatCreateVecs(rp.Kr, xr.out(), nullptr));
  PetscCall(VecDuplicate(xr, xi.out()));
  res.modes.clear();
  for (PetscInt i = 0; i < res.converged; ++i) {
    PetscScalar kr, ki;
    PetscCall(PEPGetEigenpair(pep_, i, &kr, &ki, xr, xi));
    const PetscReal re = PetscRealPart(kr), im = PetscRealPart(ki);
    if (im < 0) continue; // the conjugate of the previous one
    Mode m;
    m.sigma = re;
    m.omega = std::abs(im) <= 1e-12 * std::hypot(re, im) ? 0.0 : im;
    PetscCall(PEPComputeError(pep_, i, PEP_ERROR_BACKWARD, &m.error));
    if (modes_) {
      PetscCall(MatCreateVecs(rp.Q, nullptr, m.phi_re.out()));
      PetscCall(VecDuplicate(m.phi_re, m.phi_im.out()));
      PetscCall(MatMult(rp.Q, xr, m.phi_re));
      if (m.omega > 0) PetscCall(MatMult(rp.Q, xi, m.phi_im));
      else PetscCall(VecZeroEntries(m.phi_im));
      PetscCall(NormaliseMode(model, m));
    }
    res.modes.push_back(std::move(m));
  }
  SortModes(res);
  PetscFunctionReturn(0);
}

PetscErrorCode StabilitySolver::View(const StabilityResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscCall(PetscViewerASCIIPrintf(viewer, "linear stability: %" PetscInt_FMT " eigenvalue(s) converged, %zu unstable\n",
                                   res.converged, res.unstable.size()));
  PetscCall(ViewCompleteness(res, viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "  mode   sigma (1/s)  omega (rad/s)     f (Hz)       T (s)      zeta  status     backward err\n"));
  for (size_t i = 0; i < res.modes.size(); ++i) {
    const Mode &m      = res.modes[i];
    const bool  below  = m.Unstable() && m.Frequency() < res.fmin, above = m.Unstable() && !below && !res.InBand(m);
    const char *status = m.Unstable() ? (below ? "unst<fmin" : above ? "unst>fmax" : m.Oscillatory() ? "UNSTABLE" : "DIVERGENT") : "stable";
    if (m.Oscillatory())
      PetscCall(PetscViewerASCIIPrintf(viewer, "  %4zu  %12.5f  %13.5f  %9.4f  %10.7f  %8.5f  %-9s  %9.2e\n", i, (double)m.sigma,
                                       (double)m.omega, (double)m.Frequency(), (double)m.Period(), (double)m.DampingRatio(),
                                       status, (double)m.error));
    else
      PetscCall(PetscViewerASCIIPrintf(viewer, "  %4zu  %12.5f  %13.5f  %9s  %10s  %8s  %-9s  %9.2e\n", i, (double)m.sigma, 0.0,
                                       "-", "-", "-", status, (double)m.error));
  }
  if (const PetscInt nb = res.UnstableBelowBand()) {
    char fmin[32]; // PETSc's %g would print "200."
    std::snprintf(fmin, sizeof fmin, "%g", (double)res.fmin);
    PetscCall(PetscViewerASCIIPrintf(viewer, "  unst<fmin: %" PetscInt_FMT " unstable mode(s) below -%sfmin = %s Hz, outside the band: not reported\n",
                                     nb, prefix_.c_str(), fmin));
  }
  if (const PetscInt na = res.UnstableAboveBand()) {
    char fmax[32];
    std::snprintf(fmax, sizeof fmax, "%g", (double)res.fmax);
    PetscCall(PetscViewerASCIIPrintf(viewer, "  unst>fmax: %" PetscInt_FMT " unstable mode(s) above -%sfmax = %s Hz, outside the band: not reported (raise -%sfmax to include them)\n",
                                     na, prefix_.c_str(), fmax, prefix_.c_str()));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode StabilitySolver::ViewCompleteness(const StabilityResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  if (res.all_eigenvalues)
    PetscCall(PetscViewerASCIIPrintf(viewer, "complete: all %" PetscInt_FMT " eigenvalues of the reduced problem (n_r = %" PetscInt_FMT ")\n",
                                     2 * res.n_r, res.n_r));
  else
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "complete up to %.6g Hz: every eigenvalue with |lambda| < %.6g 1/s is in the table (nev = %" PetscInt_FMT
                                     " of %" PetscInt_FMT ", %" PetscInt_FMT " solve(s))\n",
                                     (double)res.CompleteUpTo(), (double)res.complete_radius, res.requested, 2 * res.n_r, res.solves));
  PetscScalar target = 0;
  if (pep_) PetscCall(PEPGetTarget(pep_, &target));
  if (res.fmax > 0 && !res.BandCovered() && PetscAbsScalar(target) > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  (measured about -%spep_target = %g: the disc of converged eigenvalues is centred there)\n", prefix_.c_str(),
                                     (double)PetscRealPart(target)));
  if (res.fmax > 0 && !res.BandCovered())
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "BAND NOT COVERED: asked up to %g Hz, complete only up to %.6g Hz; raise -%snev_max (now %" PetscInt_FMT
                                     ") or lower -%sfmax\n",
                                     (double)res.fmax, (double)res.CompleteUpTo(), prefix_.c_str(), nev_max_, prefix_.c_str()));
  PetscFunctionReturn(0);
}

PetscErrorCode StabilitySolver::ViewFromOptions(const StabilityResult &res) const
{
  PetscFunctionBeginUser;
  PetscCall(squeal::ViewFromOptions(comm_, prefix_, [&](PetscViewer v) { return View(res, v); }));
  PetscFunctionReturn(0);
}

} // namespace squeal

#include "squeal/io/h5.h"

namespace squeal {

PetscErrorCode WriteStability(const StabilityResult &res, io::H5Writer &out)
{
  const hsize_t k = res.modes.size();
  PetscFunctionBeginUser;
  std::vector<PetscReal> ev, f, T, zeta, err;
  for (const Mode &m : res.modes) {
    ev.insert(ev.end(), {m.sigma, m.omega});
    f.push_back(m.Frequency());
    T.push_back(m.Period());
    zeta.push_back(m.DampingRatio());
    err.push_back(m.error);
  }
  PetscCall(out.WriteArray("/stability/eigenvalues", {k, 2}, ev.data()));
  PetscCall(out.WriteArray("/stability/frequency", {k}, f.data()));
  PetscCall(out.WriteArray("/stability/period", {k}, T.data()));
  PetscCall(out.WriteArray("/stability/damping_ratio", {k}, zeta.data()));
  PetscCall(out.WriteArray("/stability/backward_error", {k}, err.data()));
  PetscCall(out.WriteIntArray("/stability/unstable", {(hsize_t)res.unstable.size()}, res.unstable.data()));
  PetscCall(out.WriteAttribute("/stability/eigenvalues", "units", "1/s"));
  PetscCall(out.WriteAttribute("/stability/eigenvalues", "columns", "sigma (re), omega (im); omega >= 0 member of each pair"));
  PetscCall(out.WriteAttribute("/stability/frequency", "units", "Hz"));
  PetscCall(out.WriteAttribute("/stability/period", "units", "s"));
  PetscCall(out.WriteAttribute("/stability/damping_ratio", "definition", "-sigma/|lambda|"));
  PetscCall(out.WriteAttribute("/stability/unstable", "order", "most unstable first (indices into eigenvalues)"));
  PetscCall(out.WriteAttribute("/stability", "fmax", res.fmax));
  PetscCall(out.WriteAttribute("/stability", "fmin", res.fmin));
  PetscCall(out.WriteAttribute("/stability", "complete_up_to", res.CompleteUpTo()));
  PetscCall(out.WriteAttribute("/stability", "all_eigenvalues", (PetscInt)res.all_eigenvalues));
  PetscCall(out.WriteAttribute("/stability", "band_covered", (PetscInt)res.BandCovered()));
  PetscCall(out.WriteAttribute("/stability", "complete_up_to_meaning",
                               "Hz; every eigenvalue with |lambda| < 2 pi complete_up_to is in the table (inf: all eigenvalues)"));
  if (k > 0 && res.modes[0].phi_re) {
    PetscInt N;
    PetscCall(VecGetSize(res.modes[0].phi_re, &N));
    std::vector<PetscReal> re(N * k), im(N * k), col;
    for (hsize_t j = 0; j < k; ++j) {
      PetscCall(GatherVector(res.modes[j].phi_re, false, col));
      for (size_t i = 0; i < col.size(); ++i) re[i * k + j] = col[i];
      PetscCall(GatherVector(res.modes[j].phi_im, false, col));
      for (size_t i = 0; i < col.size(); ++i) im[i * k + j] = col[i];
    }
    PetscCall(out.WriteArray("/stability/modes/re", {(hsize_t)N, k}, re.data()));
    PetscCall(out.WriteArray("/stability/modes/im", {(hsize_t)N, k}, im.data()));
    PetscCall(out.WriteAttribute("/stability/modes", "normalisation", "largest tangential contact component = 1"));
    PetscCall(out.WriteAttribute("/stability/modes", "layout", "[dof][mode]"));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode WriteEquilibrium(const Model &model, const SlidingEquilibrium &eq, io::H5Writer &out)
{
  const ContactSet &cs = model.contacts;
  PetscFunctionBeginUser;
  PetscCall(out.WriteVec("/equilibrium", eq.U));
  PetscCall(out.WriteVec("/equilibrium", eq.R));
  std::vector<PetscReal> r(3 * cs.Size());
  for (PetscInt c = 0; c < cs.Size(); ++c) {
    r[3 * c + kT] = eq.mu * eq.N[c];
    r[3 * c + kB] = 0;
    r[3 * c + kN] = eq.N[c];
  }
  PetscCall(out.WriteArray("/equilibrium/r", {(hsize_t)cs.Size(), 3}, r.data()));
  PetscCall(out.WriteArray("/equilibrium/N", {(hsize_t)cs.Size()}, eq.N.data()));
  PetscCall(out.WriteIntArray("/equilibrium/active", {(hsize_t)eq.active.size()}, eq.active.data()));
  PetscCall(out.WriteAttribute("/equilibrium/U", "units", "m"));
  PetscCall(out.WriteAttribute("/equilibrium/R", "units", "N"));
  PetscCall(out.WriteAttribute("/equilibrium/r", "units", "N"));
  PetscCall(out.WriteAttribute("/equilibrium/r", "columns", "t, b, n (local frame of each point)"));
  PetscCall(out.WriteAttribute("/equilibrium", "mu", eq.mu));
  PetscFunctionReturn(0);
}

} // namespace squeal
