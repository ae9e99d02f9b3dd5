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
  PetscReal buf[1024] = {0};
  PetscBool help;
  PetscFunctionBeginUser;
  // -help prints the array's first n entries as the default: show one 0 (none given), not 1024.
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  OptionChecks checks;
  PetscOptionsBegin(comm_, "transient_", "Transient run to the limit cycle", "TransientAnalysis");
  SquealOptionsReal("-periods", "Duration in periods of the starting mode", "TransientAnalysis", &periods, Range::Positive(), checks);
  SquealOptionsReal("-t_final", "Duration (s); overrides -transient_periods when > 0", "TransientAnalysis", &t_final,
                    Range::NonNegative(), checks);
  SquealOptionsReal("-steps_per_period", "Steps per period of the starting mode: h = T / steps", "TransientAnalysis",
                    &steps_per_period, Range::Positive(), checks);
  SquealOptionsReal("-h", "Time step (s); overrides -transient_steps_per_period when > 0", "TransientAnalysis", &h,
                    Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-keep_every", "Record every k-th step (default: 1, raised when the records exceed -transient_max_memory)",
                            "TransientAnalysis", keep_every, &keep_every, &keep_every_set));
  SquealOptionsReal("-max_memory", "Budget for the records on rank 0 and in the file (MiB; 0: a quarter of physical memory)",
                    "TransientAnalysis", &max_memory, Range::NonNegative(), checks);
  SquealOptionsReal("-settle_tol", "Settled: period and peak-to-peak change by less than this (relative) over the last cycles",
                    "TransientAnalysis", &settle_tol, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-settle_periods", "Cycles over which the settled test looks", "TransientAnalysis", settle_periods,
                            &settle_periods, nullptr));
  SquealOptionsReal("-amplitude", "Start: U_e + a Re(phi), dU = -a omega Im(phi), phi's largest tangential component 1 (m)",
                    "TransientAnalysis", &amplitude, Range::Any(), checks);
  PetscCall(PetscOptionsInt("-mode", "Index of the starting mode in the eigenvalue table (-1: most unstable)", "TransientAnalysis",
                            mode, &mode, nullptr));
  n = help ? 1 : 1024;
  PetscCall(PetscOptionsRealArray("-u0", "Initial displacement (all N values; replaces the mode start; default: none)", "TransientAnalysis", buf,
                                  &n, nullptr));
  u0.assign(buf, buf + n);
  if (help) n = 0;
  nd = help ? 1 : 1024;
  PetscCall(PetscOptionsRealArray("-du0", "Initial velocity (all N values; default 0 with -transient_u0)", "TransientAnalysis",
                                  buf, &nd, nullptr));
  if (help) nd = 0;
  du0.assign(buf, buf + nd);
  PetscCall(PetscOptionsInt("-monitor", "Print a monitor line every k steps (0: never)", "TransientAnalysis", monitor, &monitor,
                            nullptr));
  PetscCall(PetscOptionsBool("-progress", "Progress line with ETA on stderr (default: when stderr is a terminal)",
                             "TransientAnalysis", progress, &progress, &progress_set));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(keep_every >= 1, comm_, kErrInput, "option -transient_keep_every = %" PetscInt_FMT ": expected >= 1", keep_every);
  PetscCheck(settle_periods >= 2, comm_, kErrInput, "option -transient_settle_periods = %" PetscInt_FMT ": expected >= 2", settle_periods);
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

  // Starting mode and reference period: the chosen mode, else the most unstable, else the first
  // oscillatory one, else (overdamped model) the least damped real mode, which sets no period.
  PetscInt which = mode;
  if (which < 0) which = stab.unstable.empty() ? -1 : stab.unstable[0];
  if (which < 0)
    for (size_t i = 0; i < stab.modes.size() && which < 0; ++i)
      if (stab.modes[i].Oscillatory()) which = (PetscInt)i;
  if (which < 0 && mode < 0)
    for (size_t i = 0; i < stab.modes.size(); ++i)
      if (which < 0 || stab.modes[i].sigma > stab.modes[which].sigma) which = (PetscInt)i;
  PetscCheck(which >= 0 && which < (PetscInt)stab.modes.size(), comm_, kErrInput,
             "transient: no mode %" PetscInt_FMT " in the eigenvalue table to start from (-transient_mode)", mode);
  const Mode &m = stab.modes[which];
  PetscCheck(m.Oscillatory() || h > 0, comm_, kErrInput,
             "transient: mode %" PetscInt_FMT " is not oscillatory (overdamped model): no period sets the time step; give -transient_h "
             "(and -transient_t_final)",
             which);
  res.T_ref     = m.Oscillatory() ? m.Period() : 0.0;
  res.h         = h > 0 ? h : res.T_ref / steps_per_period;
  res.theta     = ti.Theta();
  // Without a period, -transient_periods counts blocks of -transient_steps_per_period steps.
  const PetscReal tf     = t_final > 0 ? t_final : (res.T_ref > 0 ? periods * res.T_ref : periods * steps_per_period * res.h);
  const PetscInt  nsteps = (PetscInt)std::ceil(tf / res.h - 1e-9);

  // Size of the records (all on rank 0, then in the file): refuse or thin before the run.
  {
    PetscReal budget = max_memory * 1048576.0;
    if (budget == 0) {
      const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
      budget           = pages > 0 && page > 0 ? 0.25 * (PetscReal)pages * (PetscReal)page : 4.0 * 1073741824.0;
    }
    PetscCallMPI(MPI_Bcast(&budget, 1, MPIU_REAL, 0, comm_)); // rank 0 holds the records: its memory counts
    const PetscReal per   = RecordBytes(N, nc);
    const PetscReal need  = per * (PetscReal)(nsteps / keep_every + 2);
    if (need > budget) {
      PetscCheck(!keep_every_set, comm_, kErrInput,
                 "transient: %" PetscInt_FMT " records of %.0f bytes need %.0f MiB, over the budget %.0f MiB (-transient_max_memory); "
                 "raise -transient_keep_every to %.0f, or -transient_max_memory, or shorten -transient_periods",
                 nsteps / keep_every + 2, (double)per, (double)(need / 1048576.0), (double)(budget / 1048576.0),
                 std::ceil((double)keep_every * need / budget));
      const PetscInt k = (PetscInt)std::ceil((PetscReal)keep_every * need / budget);
      PetscCall(PetscPrintf(comm_,
                            "transient: keeping every %" PetscInt_FMT "-th step: all %" PetscInt_FMT " records would need %.0f MiB, over the "
                            "budget %.0f MiB (-transient_max_memory)\n",
                            k, nsteps / keep_every + 2, (double)(need / 1048576.0), (double)(budget / 1048576.0)));
      res.keep_every = k;
    } else res.keep_every = keep_every;
    const PetscInt records = nsteps / res.keep_every + 2;
    PetscCall(PetscPrintf(comm_, "transient: %" PetscInt_FMT " steps, %" PetscInt_FMT " records: %.1f MiB in memory (rank 0) and in the file\n",
                          nsteps, records, (double)(per * records / 1048576.0)));
    if (rank == 0) { // exact reservations: no doubling of the vectors' capacity
      res.t.reserve(records);
      res.U.reserve(records * N);
      res.V.reserve(records * N);
      res.R.reserve(records * 3 * nc);
      res.status.reserve(records * nc);
      res.energy.reserve(records * 4);
    }
  }

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
    if (i % res.keep_every == 0 || i == nsteps || (monitor > 0 && i % monitor == 0)) {
      PetscCall(ti.Energy(U, dU, &Ek, &Ee));
      if (!std::isfinite(Ek + Ee)) {
        nan_step = i;
        break;
      }
      ti.Contact().Status(r, status);
    }
    if (i % res.keep_every == 0 || i == nsteps) PetscCall(record(t));
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
    bool stop = false; // SIGINT/SIGTERM: leave, records so far are written (every 32 steps: a reduction on >1 rank)
    if (i % 32 == 0) PetscCall(InterruptRequested(comm_, &stop));
    if (stop) break;
  }
  PetscCall(VecDestroy(&z));
  PetscCall(VecScatterDestroy(&sc));
  res.summary.mean_fp_iterations = res.steps ? (PetscReal)fp_total / res.steps : 0;
  if (rank == 0) Summarise(res, settle_tol, settle_periods);
  res.complete = !ierr && nan_step < 0 && res.steps == nsteps;
  PetscCall(ierr);
  PetscCheck(nan_step < 0, comm_, PETSC_ERR_FP, "transient: NaN or overflow at step %" PetscInt_FMT ", t = %g s (h = %g s); %zu records kept",
             nan_step, (double)(nan_step * res.h), (double)res.h, res.t.size());
  PetscFunctionReturn(0);
}

const char *TrendName(Trend t)
{
  switch (t) {
  case Trend::Settled: return "settled";
  case Trend::Growing: return "growing";
  case Trend::Decaying: return "decaying";
  case Trend::Drifting: return "drifting";
  case Trend::Aliased: return "aliased";
  case Trend::TooShort: return "too few cycles";
  case Trend::NoOscillation: return "no oscillation";
  }
  return "?";
}

PetscReal TransientAnalysis::RecordBytes(PetscInt N, PetscInt nc)
{
  // t, U, dU, R (3 per point), energy (4) as reals; status as one integer per point.
  return (PetscReal)((1 + 2 * N + 3 * nc + 4) * sizeof(PetscReal) + nc * sizeof(PetscInt));
}

void TransientAnalysis::Summarise(TransientResult &res, PetscReal settle_tol, PetscInt settle_periods)
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
  // Period: mean spacing of up-crossings of the median, linearly interpolated in time. (The median
  // stays at the centre of a growing or decaying oscillation, where the mid-range follows the
  // largest cycle and the small ones never cross it.)
  PetscReal              lo = PETSC_INFINITY, hi = PETSC_NINFINITY;
  std::vector<PetscReal> w;
  for (size_t k = from; k < nr; ++k) {
    lo = std::min(lo, res.U[k * N + best]), hi = std::max(hi, res.U[k * N + best]);
    w.push_back(res.U[k * N + best]);
  }
  std::nth_element(w.begin(), w.begin() + w.size() / 2, w.end());
  const PetscReal mid = w[w.size() / 2];
  std::vector<PetscReal> cross;
  std::vector<size_t>    at; // record index after each crossing
  for (size_t k = from + 1; k < nr; ++k) {
    const PetscReal a = res.U[(k - 1) * N + best] - mid, b = res.U[k * N + best] - mid;
    if (a < 0 && b >= 0) {
      cross.push_back(res.t[k - 1] + (res.t[k] - res.t[k - 1]) * (-a) / (b - a));
      at.push_back(k);
    }
  }
  s.period = cross.size() >= 2 ? (cross.back() - cross.front()) / (cross.size() - 1) : 0.0;
  s.cycles = cross.size() >= 2 ? (PetscInt)cross.size() - 1 : 0;

  // Settled? Per cycle: period and peak-to-peak; the last settle_periods + 1 cycles must agree.
  const PetscReal dt = res.t[nr - 1] - res.t[nr - 2];
  s.records_per_period = s.period > 0 && dt > 0 ? s.period / dt : 0;
  s.settled            = false;
  s.amplitude_rate = s.period_change = 0;
  if (!(hi - lo > 0)) s.trend = Trend::NoOscillation;
  else if (s.cycles == 0) s.trend = res.T_ref > 0 && dt > res.T_ref / 8 ? Trend::Aliased : Trend::TooShort;
  else if (s.records_per_period < 8 || (res.T_ref > 0 && dt > res.T_ref / 8)) s.trend = Trend::Aliased;
  else if (s.cycles < settle_periods + 1) s.trend = Trend::TooShort;
  else {
    std::vector<PetscReal> T, A;
    for (size_t c = cross.size() - settle_periods - 2; c + 1 < cross.size(); ++c) {
      T.push_back(cross[c + 1] - cross[c]);
      PetscReal a = PETSC_INFINITY, b = PETSC_NINFINITY;
      for (size_t k = at[c] - 1; k <= at[c + 1]; ++k) a = std::min(a, res.U[k * N + best]), b = std::max(b, res.U[k * N + best]);
      A.push_back(b - a);
    }
    const PetscReal Tmin = *std::min_element(T.begin(), T.end()), Tmax = *std::max_element(T.begin(), T.end());
    PetscReal       Tmean = 0;
    for (PetscReal x : T) Tmean += x / T.size();
    s.period_change  = (Tmax - Tmin) / Tmean;
    // Geometric mean growth per period of the envelope, first to last of the cycles looked at.
    s.amplitude_rate = A.front() > 0 && A.back() > 0 ? std::expm1(std::log(A.back() / A.front()) / (A.size() - 1)) : 0;
    PetscReal Amin = *std::min_element(A.begin(), A.end()), Amax = *std::max_element(A.begin(), A.end());
    const PetscReal Aspread = Amax > 0 ? (Amax - Amin) / Amax : 0;
    if (s.period_change < settle_tol && Aspread < settle_tol) s.trend = Trend::Settled, s.settled = true;
    else if (s.amplitude_rate > settle_tol / settle_periods) s.trend = Trend::Growing;
    else if (s.amplitude_rate < -settle_tol / settle_periods) s.trend = Trend::Decaying;
    else s.trend = Trend::Drifting;
  }
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
  if (s.settled)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "settled cycle period %.7f s (%.4f Hz): period and peak-to-peak change < %g over the last %" PetscInt_FMT
                                     " cycles\n",
                                     (double)s.period, 1 / (double)s.period, (double)settle_tol, settle_periods + 1));
  else if (s.trend == Trend::Growing || s.trend == Trend::Decaying || s.trend == Trend::Drifting)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "not settled: %s, peak-to-peak %+.3e per period, period spread %.3e over the last %" PetscInt_FMT
                                     " cycles (mean period %.7f s); run longer (-transient_periods)\n",
                                     TrendName(s.trend), (double)s.amplitude_rate, (double)s.period_change, settle_periods + 1,
                                     (double)s.period));
  else if (s.trend == Trend::Aliased)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "not settled: aliased, %.1f records per period (record spacing %g s, linear period %g s): lower "
                                     "-transient_keep_every or -transient_h\n",
                                     (double)s.records_per_period, (double)(res.h * res.keep_every), (double)res.T_ref));
  else if (s.trend == Trend::TooShort)
    PetscCall(PetscViewerASCIIPrintf(viewer, "not settled: only %" PetscInt_FMT " cycle(s) in the last 20 %% of the run, %" PetscInt_FMT
                                             " needed (-transient_settle_periods); run longer\n",
                                     s.cycles, settle_periods + 1));
  else PetscCall(PetscViewerASCIIPrintf(viewer, "not settled: no oscillation in the last 20 %% of the run (decayed to rest or too short)\n"));
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
  if (res.T_ref > 0) PetscCall(out.WriteAttribute("/transient", "steps_per_period", res.T_ref / res.h));
  PetscCall(out.WriteAttribute("/transient", "keep_every", res.keep_every));
  PetscCall(out.WriteAttribute("/transient", "complete", (PetscInt)res.complete));
  PetscReal summ[8] = {res.summary.period,         res.summary.mean_fp_iterations, res.summary.frac_separated,
                       res.summary.frac_stuck,     (PetscReal)res.summary.trend,   res.summary.amplitude_rate,
                       res.summary.period_change,  (PetscReal)settle_tol};
  PetscCallMPI(MPI_Bcast(summ, 8, MPIU_REAL, 0, comm_));
  const Trend trend = (Trend)(int)summ[4];
  PetscCall(out.WriteAttribute("/transient", "settled", (PetscInt)(trend == Trend::Settled)));
  PetscCall(out.WriteAttribute("/transient", "trend", TrendName(trend)));
  PetscCall(out.WriteAttribute("/transient", "amplitude_rate", summ[5]));
  PetscCall(out.WriteAttribute("/transient", "period_change", summ[6]));
  PetscCall(out.WriteAttribute("/transient", "settle_tol", summ[7]));
  PetscCall(out.WriteAttribute("/transient", "settle_cycles", settle_periods + 1));
  PetscCall(out.WriteAttribute("/transient", "period", summ[0]));
  PetscCall(out.WriteAttribute("/transient", "mean_fp_iterations", summ[1]));
  PetscCall(out.WriteAttribute("/transient", "fraction_separated", summ[2]));
  PetscCall(out.WriteAttribute("/transient", "fraction_stuck", summ[3]));
  PetscFunctionReturn(0);
}

} // namespace squeal
