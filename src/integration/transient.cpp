#include "squeal/integration/transient.h"
#include "squeal/core/errors.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <unistd.h>

namespace squeal {

PetscErrorCode TransientAnalysis::SetFromOptions()
{
  PetscInt  n = 0, nd = 0;
  PetscReal buf[1024];
  PetscFunctionBeginUser;
  OptionChecks checks;
  PetscOptionsBegin(comm_, "transient_", "Transient run to the limit cycle", "TransientAnalysis");
  SquealOptionsReal("-periods", "Duration in periods of the starting mode", "TransientAnalysis", &periods, Range::Positive(), checks);
  SquealOptionsReal("-t_final", "Duration (s); overrides -transient_periods when > 0", "TransientAnalysis", &t_final,
                    Range::NonNegative(), checks);
  SquealOptionsReal("-steps_per_period", "Steps per period of the starting mode: h = T / steps", "TransientAnalysis",
                    &steps_per_period, Range::Positive(), checks);
  SquealOptionsReal("-h", "Time step (s); overrides -transient_steps_per_period when > 0", "TransientAnalysis", &h,
                    Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-keep_every", "Record every k-th step", "TransientAnalysis", keep_every, &keep_every, nullptr));
  SquealOptionsReal("-amplitude", "Start: U_e + a Re(phi), dU = -a omega Im(phi), phi's largest tangential component 1 (m)",
                    "TransientAnalysis", &amplitude, Range::Any(), checks);
  PetscCall(PetscOptionsInt("-mode", "Index of the starting mode in the eigenvalue table (-1: most unstable)", "TransientAnalysis",
                            mode, &mode, nullptr));
  n = 1024;
  PetscCall(PetscOptionsRealArray("-u0", "Initial displacement (all N values; replaces the mode start)", "TransientAnalysis", buf,
                                  &n, nullptr));
  u0.assign(buf, buf + n);
  nd = 1024;
  PetscCall(PetscOptionsRealArray("-du0", "Initial velocity (all N values; default 0 with -transient_u0)", "TransientAnalysis",
                                  buf, &nd, nullptr));
  du0.assign(buf, buf + nd);
  PetscCall(PetscOptionsInt("-monitor", "Print a monitor line every k steps (0: never)", "TransientAnalysis", monitor, &monitor,
                            nullptr));
  PetscCall(PetscOptionsBool("-progress", "Progress line with ETA on stderr (default: when stderr is a terminal)",
                             "TransientAnalysis", progress, &progress, &progress_set));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(keep_every >= 1, comm_, kErrInput, "option -transient_keep_every = %" PetscInt_FMT ": expected >= 1", keep_every);
  for (PetscReal x : u0) PetscCheck(std::isfinite(x), comm_, kErrInput, "option -transient_u0 has a NaN or infinite entry");
  for (PetscReal x : du0) PetscCheck(std::isfinite(x), comm_, kErrInput, "option -transient_du0 has a NaN or infinite entry");
  PetscFunctionReturn(0);
}

namespace {

PetscErrorCode SetFromArray(Vec v, const std::vector<PetscReal> &a)
{
  PetscInt     lo, hi;
  PetscScalar *x;
  PetscFunctionBeginUser;
  PetscCall(VecGetOwnershipRange(v, &lo, &hi));
  PetscCall(VecGetArray(v, &x));
  for (PetscInt i = lo; i < hi; ++i) x[i - lo] = a[i];
  PetscCall(VecRestoreArray(v, &x));
  PetscFunctionReturn(0);
}

// Appends the values of v, gathered on rank 0, to out (rank 0 only).
PetscErrorCode Record(VecScatter sc, Vec v, Vec z, std::vector<PetscReal> &out)
{
  PetscInt           n;
  const PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(sc, v, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, v, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetLocalSize(z, &n));
  PetscCall(VecGetArrayRead(z, &a));
  for (PetscInt i = 0; i < n; ++i) out.push_back(PetscRealPart(a[i]));
  PetscCall(VecRestoreArrayRead(z, &a));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode TransientAnalysis::Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab,
                                      ThetaIntegrator &ti, TransientResult &res)
{
  const PetscInt N = model.Size(), nc = model.contacts.Size();
  PetscMPIInt    rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  res    = TransientResult{};
  res.N  = N;
  res.nc = nc;

  // Starting mode and reference period.
  PetscInt which = mode;
  if (which < 0) which = stab.unstable.empty() ? -1 : stab.unstable[0];
  if (which < 0)
    for (size_t i = 0; i < stab.modes.size() && which < 0; ++i)
      if (stab.modes[i].Oscillatory()) which = (PetscInt)i;
  PetscCheck(which >= 0 && which < (PetscInt)stab.modes.size() && stab.modes[which].Oscillatory(), comm_, kErrInput,
             "transient: no oscillatory mode %" PetscInt_FMT " to start from and set the time step", mode);
  const Mode &m = stab.modes[which];
  res.T_ref     = m.Period();
  res.h         = h > 0 ? h : res.T_ref / steps_per_period;
  res.theta     = ti.Theta();
  const PetscReal tf     = t_final > 0 ? t_final : periods * res.T_ref;
  const PetscInt  nsteps = (PetscInt)std::ceil(tf / res.h - 1e-9);

  VecH U, dU, U0;
  PetscCall(VecDuplicate(eq.U, U.out()));
  PetscCall(VecDuplicate(eq.U, dU.out()));
  PetscCall(VecDuplicate(eq.U, U0.out()));
  if (!u0.empty()) {
    PetscCheck((PetscInt)u0.size() == N, comm_, kErrInput, "option -transient_u0 has %zu values, the model has %" PetscInt_FMT " DOFs",
               u0.size(), N);
    PetscCheck(du0.empty() || (PetscInt)du0.size() == N, comm_, kErrInput,
               "option -transient_du0 has %zu values, the model has %" PetscInt_FMT " DOFs", du0.size(), N);
    PetscCall(SetFromArray(U, u0));
    if (!du0.empty()) PetscCall(SetFromArray(dU, du0));
    else PetscCall(VecZeroEntries(dU));
  } else {
    PetscCheck(m.phi_re, comm_, kErrInput, "transient: mode shapes are needed for the start (-stab_modes)");
    PetscCall(VecWAXPY(U, amplitude, m.phi_re, eq.U));
    PetscCall(VecAXPBY(dU, -amplitude * m.omega, 0.0, m.phi_im));
  }

  PetscCall(ti.SetUp(model, res.h));
  // Warm start: the steady-sliding reactions.
  Eigen::VectorXd r = Eigen::VectorXd::Zero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) {
    r[3 * c + kT] = model.contacts.mu * eq.N[c];
    r[3 * c + kN] = eq.N[c];
  }
  VecScatter sc;
  Vec        z;
  PetscCall(VecScatterCreateToZero(U, &sc, &z));
  std::vector<int> status(nc, kSlip);
  PetscReal        E0 = 0, Ek, Ee, Wc = 0, WR = 0, WF = 0;
  PetscCall(ti.Energy(U, dU, &Ek, &Ee));
  E0 = Ek + Ee;
  auto record = [&](PetscReal t) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(Record(sc, U, z, res.U));
    PetscCall(Record(sc, dU, z, res.V));
    if (rank == 0) {
      res.t.push_back(t);
      res.R.insert(res.R.end(), r.data(), r.data() + r.size());
      res.status.insert(res.status.end(), status.begin(), status.end());
      res.energy.insert(res.energy.end(), {Ek + Ee, Wc, WR, WF});
    }
    PetscFunctionReturn(0);
  };
  PetscCall(record(0.0));

  const bool tty       = isatty(STDERR_FILENO);
  const bool show_prog = rank == 0 && (progress_set ? (bool)progress : tty);
  auto       start     = std::chrono::steady_clock::now();
  auto       last      = start;
  PetscInt   fp_total  = 0;
  StepInfo   info;
  PetscErrorCode ierr = 0;
  PetscInt       nan_step = -1;
  for (PetscInt i = 1; i <= nsteps; ++i) {
    const PetscReal t = i * res.h;
    PetscCall(VecCopy(U, U0));
    ierr = ti.Step(U, dU, r, &info);
    if (ierr) break;
    if (nc > 0 && std::isnan(info.contact.residual)) {
      nan_step = i;
      break;
    }
    fp_total += info.contact.iterations;
    if (nc > 0 && !info.contact.converged) {
      if (res.summary.fp_capped++ == 0) {
        res.summary.first_capped_step     = i;
        res.summary.first_capped_residual = info.contact.residual;
        PetscCall(PetscFPrintf(comm_, PETSC_STDERR,
                               "squeal: warning: contact fixed point hit its pass limit at step %" PetscInt_FMT
                               " (t = %g s, residual %.2e): reactions not converged; see -%sfp_max_it, -%srho_scale\n",
                               i, (double)t, (double)info.contact.residual, ti.Prefix().c_str(), ti.Prefix().c_str()));
      }
    }
    PetscReal dwc, dwr, dwf;
    PetscCall(ti.Work(U0, U, r, &dwc, &dwr, &dwf));
    Wc += dwc, WR += dwr, WF += dwf;
    if (i % keep_every == 0 || i == nsteps || (monitor > 0 && i % monitor == 0)) {
      PetscCall(ti.Energy(U, dU, &Ek, &Ee));
      if (!std::isfinite(Ek + Ee)) {
        nan_step = i;
        break;
      }
      ti.Contact().Status(r, status);
    }
    if (i % keep_every == 0 || i == nsteps) PetscCall(record(t));
    res.steps = i;
    if (monitor > 0 && i % monitor == 0) {
      PetscInt cnt[3] = {0, 0, 0};
      for (int s : status) cnt[s]++;
      const PetscReal bal = (Ek + Ee - E0) - (WR + WF - Wc);
      PetscCall(PetscPrintf(comm_,
                            "  step %8" PetscInt_FMT " t = %.6e s  open/stick/slip %" PetscInt_FMT "/%" PetscInt_FMT "/%" PetscInt_FMT
                            "  fp its %3" PetscInt_FMT "  E = %.6e J  balance %.3e J\n",
                            i, (double)t, cnt[0], cnt[1], cnt[2], info.contact.iterations, (double)(Ek + Ee), (double)bal));
    }
    if (show_prog) {
      auto now = std::chrono::steady_clock::now();
      if (std::chrono::duration<double>(now - last).count() > 0.5 || i == nsteps) {
        last             = now;
        const double el  = std::chrono::duration<double>(now - start).count();
        const double eta = el * (nsteps - i) / i;
        std::fprintf(stderr, "\rtransient: %5.1f%%  t = %.4g s  step %lld/%lld  ETA %.0f s   ", 100.0 * i / nsteps, (double)t,
                     (long long)i, (long long)nsteps, eta);
        if (i == nsteps) std::fprintf(stderr, "\n");
      }
    }
    bool stop; // SIGINT/SIGTERM: leave after this step; the records so far are written
    PetscCall(InterruptRequested(comm_, &stop));
    if (stop) break;
  }
  PetscCall(VecDestroy(&z));
  PetscCall(VecScatterDestroy(&sc));
  res.summary.mean_fp_iterations = res.steps ? (PetscReal)fp_total / res.steps : 0;
  if (rank == 0) Summarise(res);
  res.complete = !ierr && nan_step < 0 && res.steps == nsteps;
  PetscCall(ierr);
  PetscCheck(nan_step < 0, comm_, PETSC_ERR_FP, "transient: NaN or overflow at step %" PetscInt_FMT ", t = %g s (h = %g s); %zu records kept",
             nan_step, (double)(nan_step * res.h), (double)res.h, res.t.size());
  PetscFunctionReturn(0);
}

void TransientAnalysis::Summarise(TransientResult &res)
{
  TransientSummary &s  = res.summary;
  const size_t      nr = res.t.size();
  const PetscInt    N = res.N, nc = res.nc;
  if (nr < 4) return;
  const size_t from = nr - std::max<size_t>(nr / 5, 2);
  s.peak_to_peak.assign(N, 0.0);
  PetscInt best = 0;
  for (PetscInt j = 0; j < N; ++j) {
    PetscReal lo = PETSC_INFINITY, hi = PETSC_NINFINITY;
    for (size_t k = from; k < nr; ++k) lo = std::min(lo, res.U[k * N + j]), hi = std::max(hi, res.U[k * N + j]);
    s.peak_to_peak[j] = hi - lo;
    if (s.peak_to_peak[j] > s.peak_to_peak[best]) best = j;
  }
  // Period: mean spacing of up-crossings of the mid-range, linearly interpolated in time.
  PetscReal lo = PETSC_INFINITY, hi = PETSC_NINFINITY;
  for (size_t k = from; k < nr; ++k) lo = std::min(lo, res.U[k * N + best]), hi = std::max(hi, res.U[k * N + best]);
  const PetscReal        mid = 0.5 * (lo + hi);
  std::vector<PetscReal> cross;
  for (size_t k = from + 1; k < nr; ++k) {
    const PetscReal a = res.U[(k - 1) * N + best] - mid, b = res.U[k * N + best] - mid;
    if (a < 0 && b >= 0) cross.push_back(res.t[k - 1] + (res.t[k] - res.t[k - 1]) * (-a) / (b - a));
  }
  s.period = cross.size() >= 2 ? (cross.back() - cross.front()) / (cross.size() - 1) : 0.0;
  if (nc > 0) {
    PetscInt cnt[3] = {0, 0, 0};
    for (size_t k = from; k < nr; ++k)
      for (PetscInt c = 0; c < nc; ++c) cnt[res.status[k * nc + c]]++;
    const PetscReal tot = (PetscReal)((nr - from) * nc);
    s.frac_separated    = cnt[kOpen] / tot;
    s.frac_stuck        = cnt[kStick] / tot;
    s.frac_sliding      = cnt[kSlip] / tot;
  }
  PetscReal emax = 0, defect = 0;
  const PetscReal E0 = res.energy[0];
  for (size_t k = 0; k < nr; ++k) {
    const PetscReal *e = &res.energy[4 * k];
    emax               = std::max(emax, std::abs(e[0]));
    defect             = std::max(defect, std::abs((e[0] - E0) - (e[2] + e[3] - e[1])));
  }
  s.energy_defect = emax > 0 ? defect / emax : 0;
}

PetscErrorCode TransientAnalysis::View(const TransientResult &res, PetscViewer viewer) const
{
  const TransientSummary &s = res.summary;
  PetscBool               ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "transient: %" PetscInt_FMT " steps of h = %.6g s (T_lin / %.0f), theta = %g, t = %.6g s%s\n",
                                   res.steps, (double)res.h, (double)(res.T_ref / res.h), (double)res.theta,
                                   (double)(res.steps * res.h), res.complete ? "" : " (INCOMPLETE)"));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  if (s.period > 0) PetscCall(PetscViewerASCIIPrintf(viewer, "settled cycle period %.7f s (%.4f Hz)\n", (double)s.period, 1 / (double)s.period));
  else PetscCall(PetscViewerASCIIPrintf(viewer, "no settled oscillation detected (decayed or too short a run)\n"));
  std::string p2p;
  for (size_t j = 0; j < s.peak_to_peak.size() && j < 12; ++j) {
    char b[32];
    std::snprintf(b, sizeof b, "%s%.4e", j ? ", " : "", (double)s.peak_to_peak[j]);
    p2p += b;
  }
  if (s.peak_to_peak.size() > 12) p2p += ", ...";
  PetscCall(PetscViewerASCIIPrintf(viewer, "peak-to-peak (m), last 20 %%: %s\n", p2p.c_str()));
  if (res.nc > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "contact, last 20 %%: separated %.1f %%, stuck %.1f %%, sliding %.1f %% (%s)\n",
                                     100 * (double)s.frac_separated, 100 * (double)s.frac_stuck, 100 * (double)s.frac_sliding,
                                     s.frac_separated > 0 && s.frac_stuck > 0 ? "separation/stick/slip"
                                     : s.frac_separated > 0                   ? "separation/slip"
                                     : s.frac_stuck > 0                       ? "stick/slip"
                                                                              : "pure sliding"));
  if (s.fp_capped)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "mean fixed-point passes per step %.2f; pass limit hit in %" PetscInt_FMT
                                     " step(s), first at step %" PetscInt_FMT " (residual %.2e)\n",
                                     (double)s.mean_fp_iterations, s.fp_capped, s.first_capped_step,
                                     (double)s.first_capped_residual));
  else PetscCall(PetscViewerASCIIPrintf(viewer, "mean fixed-point passes per step %.2f\n", (double)s.mean_fp_iterations));
  PetscCall(PetscViewerASCIIPrintf(viewer, "energy balance defect %.2e of max energy\n", (double)s.energy_defect));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode TransientAnalysis::Write(const TransientResult &res, io::H5Writer &out) const
{
  const hsize_t nr = res.t.size(), N = res.N, nc = res.nc;
  PetscFunctionBeginUser;
  // Ranks other than 0 hold no records; sizes must agree for the collective dataset creation.
  hsize_t n = nr;
  PetscCallMPI(MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  PetscCall(out.WriteArray("/transient/t", {n}, res.t.data()));
  PetscCall(out.WriteArray("/transient/U", {n, N}, res.U.data()));
  PetscCall(out.WriteArray("/transient/V", {n, N}, res.V.data()));
  PetscCall(out.WriteArray("/transient/R", {n, nc, 3}, res.R.data()));
  PetscCall(out.WriteIntArray("/transient/status", {n, nc}, res.status.data()));
  PetscCall(out.WriteArray("/transient/energy", {n, 4}, res.energy.data()));
  PetscCall(out.WriteAttribute("/transient/energy", "columns", "E (kinetic + elastic), W_damping, W_reactions, W_load (cumulative, J)"));
  PetscCall(out.WriteAttribute("/transient/status", "values", "0 separated, 1 stuck, 2 sliding"));
  PetscCall(out.WriteAttribute("/transient/R", "columns", "t, b, n (local frame, N)"));
  PetscCall(out.WriteAttribute("/transient", "h", res.h));
  PetscCall(out.WriteAttribute("/transient", "theta", res.theta));
  PetscCall(out.WriteAttribute("/transient", "steps_per_period", res.T_ref / res.h));
  PetscCall(out.WriteAttribute("/transient", "complete", (PetscInt)res.complete));
  PetscReal summ[4] = {res.summary.period, res.summary.mean_fp_iterations, res.summary.frac_separated, res.summary.frac_stuck};
  PetscCallMPI(MPI_Bcast(summ, 4, MPIU_REAL, 0, comm_));
  PetscCall(out.WriteAttribute("/transient", "period", summ[0]));
  PetscCall(out.WriteAttribute("/transient", "mean_fp_iterations", summ[1]));
  PetscCall(out.WriteAttribute("/transient", "fraction_separated", summ[2]));
  PetscCall(out.WriteAttribute("/transient", "fraction_stuck", summ[3]));
  PetscFunctionReturn(0);
}

} // namespace squeal
