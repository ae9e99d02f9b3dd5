#include "squeal/integration/transient.h"
#include "transient_ledger.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/io/start_state.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <type_traits>
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
  SquealOptionsReal("-settle_tol", "Settled: period, peak-to-peak and state change by less than this (relative) over the last cycles",
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
  PetscCall(io::StartOptions(PetscOptionsObject, "TransientAnalysis",
                             "Start from a state in a squeal results file (.h5): a transient's last record (go on from it), a "
                             "statistical steady state's end, a cycle's Z0, a reduced cycle's or steady state's on the full model "
                             "(/expanded/Z0, /expanded/Z_end), the energy estimate's Z0; replaces the mode start",
                             start_file, start_from));
  PetscCall(PetscOptionsInt("-monitor", "Print a monitor line every k steps (0: never)", "TransientAnalysis", monitor, &monitor,
                            nullptr));
  PetscCall(PetscOptionsBool("-progress", "Progress line with ETA on stderr (default: when stderr is a terminal)",
                             "TransientAnalysis", progress, &progress, &progress_set));
  PetscOptionsEnd();
  {
    PetscBool a, b;
    PetscCall(PetscOptionsHasName(nullptr, nullptr, "-transient_steps_per_period", &a));
    PetscCall(PetscOptionsHasName(nullptr, nullptr, "-transient_h", &b));
    steps_given = (PetscBool)(a || b);
  }
  PetscCall(checks.Run(comm_));
  PetscCheck(keep_every >= 1, comm_, kErrInput, "option -transient_keep_every = %" PetscInt_FMT ": expected >= 1", keep_every);
  PetscCheck(settle_periods >= 2, comm_, kErrInput, "option -transient_settle_periods = %" PetscInt_FMT ": expected >= 2", settle_periods);
  for (PetscReal x : u0) PetscCheck(std::isfinite(x), comm_, kErrInput, "option -transient_u0 has a NaN or infinite entry");
  for (PetscReal x : du0) PetscCheck(std::isfinite(x), comm_, kErrInput, "option -transient_du0 has a NaN or infinite entry");
  PetscCheck(start_file.empty() || u0.empty(), comm_, kErrInput, "options -transient_start and -transient_u0 both give the start: keep one");
  // A missing or foreign file fails here, before any model work.
  if (!start_file.empty()) PetscCall(io::CheckStartFile(comm_, start_file, "-transient_start"));
  PetscFunctionReturn(0);
}

namespace {

// A step whose contact solve hit its pass limit: counted, the first one reported.
PetscErrorCode Capped(MPI_Comm comm, const ThetaIntegrator &ti, const StepInfo &info, PetscInt i, PetscReal h, TransientSummary &s)
{
  PetscFunctionBeginUser;
  if (s.fp_capped++ == 0) {
    s.first_capped_step     = i;
    s.first_capped_residual = info.contact.residual;
    PetscCall(PetscFPrintf(comm, PETSC_STDERR,
                           "squeal: warning: contact fixed point hit its pass limit at step %" PetscInt_FMT
                           " (t = %g s, residual %.2e): reactions not converged; see -%sfp_max_it, -%srho_scale\n",
                           i, (double)(i * h), (double)info.contact.residual, ti.Prefix().c_str(), ti.Prefix().c_str()));
  }
  PetscFunctionReturn(0);
}

// The status of every point for reactions r, as LocalContactSolver::Status (open: r_n <= 0; stick:
// |r_T| < (1 - 1e-9) mu r_n; rectilinear: |r_t| for |r_T|), with |r_T|^2 in place of its hypot
// (~50 instructions, a tenth of a 3-DOF step) wherever that decides by more than the rounding
// of either form (a relative margin of 1e-12, where both are exact to a few 1e-16); the rare
// points inside the margin go to Status itself, so the result is Status's. Kept in this file with
// Event: the loop inlines both (StatusOf in the bookkeeping's file was a call per recorded step,
// ~50 instructions more per 3-DOF step, benchmarks/transient_instructions.sh).
class StatusOf {
public:
  // The law and mu as they are for the whole run (Run changes neither), read once.
  StatusOf(const ContactSet &cs, const LocalContactSolver &ls) : ls_(ls), rectilinear_(cs.law == FrictionLaw::Rectilinear), mu_(cs.Mu()) {}
  // NC: the number of points when known at compile time (Run's loop for the kernel's fixed sizes).
  template <int NC = Eigen::Dynamic, class Int>
  EIGEN_ALWAYS_INLINE void operator()(const Eigen::VectorXd &r, Int *status)
  {
    const Eigen::Index nc          = NC == Eigen::Dynamic ? r.size() / 3 : NC;
    const bool         rectilinear = rectilinear_;
    bool               unsure      = false;
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o  = 3 * c;
      const PetscReal    rn = r[o + kN];
      if (rn <= 0) {
        status[c] = kOpen;
        continue;
      }
      const PetscReal a = (1 - 1e-9) * mu_ * rn; // Status's bound, the same expression
      if (rectilinear) {
        status[c] = std::abs(r[o + kT]) < a ? kStick : kSlip;
        continue;
      }
      const PetscReal q = r[o + kT] * r[o + kT] + r[o + kB] * r[o + kB], a2 = a * a;
      if (q < (1 - 1e-12) * a2) status[c] = kStick;
      else if (q > (1 + 1e-12) * a2) status[c] = kSlip;
      else unsure = true, status[c] = -1;
    }
    if (!unsure) return;
    ls_.Status(r, all_);
    for (Eigen::Index c = 0; c < nc; ++c)
      if (status[c] < 0) status[c] = all_[c];
  }

private:
  const LocalContactSolver &ls_;
  const bool                rectilinear_;
  const PetscReal           mu_;
  std::vector<int>          all_;
};

// After a step that is recorded or monitored: the totals, the NaN test, the statuses, the record,
// the monitor line; *nan set when the energy is not finite (then nothing is recorded). A function of
// this file with one caller, so that it is inlined in the loop (with StatusOf's test).
PetscErrorCode Event(transient::Bookkeeping &book, StatusOf &status_of, PetscInt i, PetscReal h, bool rec, bool mon, PetscInt fp_its,
                     const Eigen::VectorXd &r, bool *nan)
{
  const PetscReal t = i * h;
  PetscFunctionBeginUser;
  PetscCall(book.Totals());
  *nan = !book.Finite();
  if (*nan) PetscFunctionReturn(0);
  status_of(r, book.Status());
  if (rec) PetscCall(book.Record(i, t, r));
  if (mon) PetscCall(book.Monitor(i, fp_its));
  PetscFunctionReturn(0);
}

// The progress line on stderr, at most every 0.5 s and at the last step.
class Progress {
public:
  Progress(PetscInt nsteps, PetscReal h) : nsteps_(nsteps), h_(h), start_(std::chrono::steady_clock::now()), last_(start_) {}
  void operator()(PetscInt i)
  {
    auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_).count() > 0.5 || i == nsteps_) {
      last_            = now;
      const double el  = std::chrono::duration<double>(now - start_).count();
      const double eta = el * (nsteps_ - i) / i;
      std::fprintf(stderr, "\rtransient: %5.1f%%  t = %.4g s  step %lld/%lld  ETA %.0f s   ", 100.0 * i / nsteps_, (double)(i * h_),
                   (long long)i, (long long)nsteps_, eta);
      if (i == nsteps_) std::fprintf(stderr, "\n");
    }
  }

private:
  const PetscInt                        nsteps_;
  const PetscReal                       h_;
  std::chrono::steady_clock::time_point start_, last_;
};


// What Run's loop reads and updates besides the state.
struct LoopContext {
  MPI_Comm                 comm;
  const ThetaIntegrator   &ti;
  TransientResult         &res;
  transient::Bookkeeping  &book;
  StatusOf                &status_of;
  Progress                &progress_line;
  const PetscInt           nsteps, monitor;
  const bool               show_prog;
  PetscInt                 fp_total = 0, nan_step = -1;
};

// The steps, with the works after each and the records and monitor lines. step(info) takes one step
// of the state (U, dU in u, du on one rank) and r. Dense: the dense ledger of the step kernel's
// fixed sizes on one rank, whose works and records are then inlined here (totals, statuses and
// stores into rank 0's record slots, as Event and Bookkeeping::Record would do them, in the same
// order of operations); null: the ledger's virtual calls and Event. Monitor lines take Event either way.
template <class Dense, class StepFn>
PetscErrorCode Loop(LoopContext &c, StepFn &&step, Dense dense, const PetscReal *u, const PetscReal *du, Eigen::VectorXd &r,
                    PetscErrorCode *ierr)
{
  constexpr bool     kDense = !std::is_same_v<Dense, std::nullptr_t>;
  const PetscInt     nsteps = c.nsteps, keep = c.res.keep_every, monitor = c.monitor;
  const PetscReal    h      = c.res.h;
  transient::Ledger *led    = c.book.GetLedger();
  bool               contact = r.size() > 0;
  if constexpr (kDense) contact = std::remove_pointer_t<Dense>::kNC > 0; // the same, known at compile time
  StepInfo           info;
  PetscInt           fp_total = 0, to_record = keep, to_monitor = monitor > 0 ? monitor : PETSC_MAX_INT, done = c.res.steps;
  // Dense: the next record's slots, moved on by a record's sizes after each (Next() again after a
  // record made by Event).
  transient::Bookkeeping::Slot slot{};
  if constexpr (kDense) slot = c.book.Next();
  PetscFunctionBeginUser;
  for (PetscInt i = 1; i <= nsteps; ++i) {
    if constexpr (kDense) step(info); // cannot fail: *ierr stays 0
    else {
      *ierr = step(info);
      if (*ierr) break;
    }
    if (contact) {
      if (std::isnan(info.contact.residual)) {
        c.nan_step = i;
        break;
      }
      if (!info.contact.converged) PetscCall(Capped(c.comm, c.ti, info, i, h, c.res.summary));
    }
    fp_total += info.contact.iterations;
    if constexpr (kDense) dense->WorkAt(u, r.data());
    else PetscCall(led->Work(r));
    const bool rec = --to_record == 0 || i == nsteps, mon = --to_monitor == 0;
    if (rec || mon) {
      bool nan = false;
      if constexpr (kDense) {
        using D                = std::remove_pointer_t<Dense>;
        constexpr int kN = D::kN, kNC = D::kNC;
        if (!mon) {
          PetscReal tot[5];
          dense->TotalsAt(u, du, tot);
          nan = !std::isfinite(tot[0] + tot[1]);
          if (!nan) {
            *slot.t = i * h;
            dense->CopyAt(u, du, r.data(), slot.U, slot.V, slot.R);
            c.status_of.template operator()<kNC>(r, slot.status);
            slot.energy[0] = tot[0] + tot[1], slot.energy[1] = tot[2], slot.energy[2] = tot[3], slot.energy[3] = tot[4];
            c.book.Commit();
            slot.t += 1, slot.U += kN, slot.V += kN, slot.R += 3 * kNC, slot.energy += 4, slot.status += kNC;
          }
        } else {
          PetscCall(Event(c.book, c.status_of, i, h, rec, mon, info.contact.iterations, r, &nan));
          slot = c.book.Next();
        }
      } else PetscCall(Event(c.book, c.status_of, i, h, rec, mon, info.contact.iterations, r, &nan));
      if (nan) {
        c.nan_step = i;
        break;
      }
      if (rec) to_record = keep;
      if (mon) to_monitor = monitor;
    }
    if constexpr (kDense) done = i; // c.res.steps when the loop ends (nothing in it reads it; an error return leaves it)
    else c.res.steps = i;
    if (c.show_prog && (i % 64 == 0 || i == nsteps)) c.progress_line(i); // the clock read every 64 steps only
    bool stop = false; // SIGINT/SIGTERM: leave, records so far are written (every 32 steps: a reduction on >1 rank)
    if (i % 32 == 0) {
      // Dense: one rank, where InterruptRequested is this test (without its call, ~2 instructions a 3-DOF step).
      if constexpr (kDense) stop = InterruptSignal() != 0;
      else PetscCall(InterruptRequested(c.comm, &stop));
    }
    if (stop) break;
  }
  c.fp_total = fp_total;
  if constexpr (kDense) c.res.steps = done;
  PetscFunctionReturn(0);
}

// Run's loop on one rank for the step kernel's fixed sizes (N, NC), if the kernel and the ledger are
// those: the kernel called directly on the state arrays (not through ThetaIntegrator::Step and the
// Vecs, whose state is increased once after the loop as VecRestoreArray would), the works and
// records inlined. *done: taken. Flattened: GCC otherwise calls the kernel's Step, whose call,
// frame and the loop's values kept across it cost ~35 of a 3-DOF step's ~640 instructions.
template <int N, int NC>
__attribute__((flatten)) PetscErrorCode DenseLoop(LoopContext &c, Vec U, Vec dU, PetscReal *u, PetscReal *du, Eigen::VectorXd &r, PetscErrorCode *ierr, bool *done)
{
  PetscFunctionBeginUser;
  auto *kern = dynamic_cast<DenseStepKernelT<N, NC> *>(c.ti.OneRankKernel());
  auto *led  = dynamic_cast<transient::DenseLedger<N, NC> *>(c.book.GetLedger());
  // Not when on_record takes the records (the steady state): its slots hold the last state only, and
  // the hook sees each record through Record.
  *done = kern && led && u && du && !c.res.streamed;
  if (!*done) PetscFunctionReturn(0);
  const auto step = [&](StepInfo &info) -> PetscErrorCode {
    kern->Step(u, du, r, &info.contact);
    return 0;
  };
  const PetscErrorCode e = Loop(c, step, led, u, du, r, ierr);
  for (Vec x : {U, dU}) { // the state increase of VecRestoreArray (public API)
    PetscScalar *a;
    PetscCall(VecGetArray(x, &a));
    PetscCall(VecRestoreArray(x, &a));
  }
  PetscCall(e);
  PetscFunctionReturn(0);
}

} // namespace

// Starting mode and reference period: the chosen mode, else the most unstable, else the first
// oscillatory one, else (overdamped model) the least damped real mode, which sets no period.
PetscErrorCode TransientAnalysis::StartMode(const StabilityResult &stab, const Mode **start) const
{
  PetscFunctionBeginUser;
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
  *start = &m;
  PetscFunctionReturn(0);
}

PetscErrorCode TransientAnalysis::RecordBudget(PetscReal *bytes) const
{
  PetscFunctionBeginUser;
  PetscReal budget = max_memory * 1048576.0;
  if (budget == 0) {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    budget           = pages > 0 && page > 0 ? 0.25 * (PetscReal)pages * (PetscReal)page : 4.0 * 1073741824.0;
  }
  PetscCallMPI(MPI_Bcast(&budget, 1, MPIU_REAL, 0, comm_)); // rank 0 holds the records: its memory counts
  *bytes = budget;
  PetscFunctionReturn(0);
}

// Streamed: t and the energies here, and what the consumer keeps (on_record_bytes).
static PetscReal StreamedRecordBytes(PetscReal on_record_bytes) { return 5 * sizeof(PetscReal) + on_record_bytes; }

PetscErrorCode TransientAnalysis::StreamedRecordsFit(PetscInt64 *records) const
{
  PetscReal budget;
  PetscFunctionBeginUser;
  PetscCall(RecordBudget(&budget));
  *records = (PetscInt64)(budget / StreamedRecordBytes(on_record_bytes));
  PetscFunctionReturn(0);
}

// Size of the records (all on rank 0, then in the file): refuse or thin before the run.
PetscErrorCode TransientAnalysis::RecordCount(PetscInt N, PetscInt nc, PetscInt nsteps, TransientResult &res, PetscInt *records) const
{
  PetscReal budget;
  PetscFunctionBeginUser;
  PetscCall(RecordBudget(&budget));
  const PetscReal per   = res.streamed ? StreamedRecordBytes(on_record_bytes) : RecordBytes(N, nc);
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
  *records = nsteps / res.keep_every + 2;
  if (res.streamed)
    PetscCall(PetscPrintf(comm_, "transient: %" PetscInt_FMT " steps, %" PetscInt_FMT " records analysed as they come: %.1f MiB kept (rank 0), no full states\n",
                          nsteps, *records, (double)(per * *records / 1048576.0)));
  else
    PetscCall(PetscPrintf(comm_, "transient: %" PetscInt_FMT " steps, %" PetscInt_FMT " records: %.1f MiB in memory (rank 0) and in the file\n",
                          nsteps, *records, (double)(per * *records / 1048576.0)));
  PetscFunctionReturn(0);
}

// The start: -transient_u0 and -transient_du0, else U_e + a Re(phi), dU = -a omega Im(phi).
PetscErrorCode TransientAnalysis::StartState(const SlidingEquilibrium &eq, const Mode &m, Vec U, Vec dU) const
{
  PetscFunctionBeginUser;
  if (!u0.empty()) {
    PetscCall(SetOwnedRows(u0.data(), U));
    if (!du0.empty()) PetscCall(SetOwnedRows(du0.data(), dU));
    else PetscCall(VecZeroEntries(dU));
  } else {
    PetscCall(VecWAXPY(U, amplitude, m.phi_re, eq.U));
    PetscCall(VecAXPBY(dU, -amplitude * m.omega, 0.0, m.phi_im));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode TransientAnalysis::Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab,
                                      ThetaIntegrator &ti, TransientResult &res)
{
  const PetscInt N = model.Size(), nc = model.contacts.Size();
  PetscMPIInt    rank, size;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  res = TransientResult{};
  transient::Bookkeeping book(comm_, res, N, nc, on_record, energy); // before anything that may return: the records are cut on the way out
  res.N  = N;
  res.nc = nc;

  const Mode *start;
  PetscCall(StartMode(stab, &start));
  const Mode &m = *start;
  res.T_ref     = m.Oscillatory() ? m.Period() : 0.0;
  res.h         = h > 0 ? h : res.T_ref / steps_per_period;
  res.theta     = ti.Theta();
  // Without a period, -transient_periods counts blocks of -transient_steps_per_period steps.
  const PetscReal tf     = t_final > 0 ? t_final : (res.T_ref > 0 ? periods * res.T_ref : periods * steps_per_period * res.h);
  const PetscInt  nsteps = (PetscInt)std::ceil(tf / res.h - 1e-9);
  res.steps_planned      = nsteps;
  PetscInt        records;
  PetscCall(RecordCount(N, nc, nsteps, res, &records));
  if (rank == 0) book.SizeRecords(records);

  io::StartState  from_file;
  Eigen::VectorXd r = Eigen::VectorXd::Zero(3 * nc); // the contact's warm start
  for (PetscInt c = 0; c < nc; ++c) {
    r[3 * c + kT] = model.contacts.Mu() * eq.N[c];
    r[3 * c + kN] = eq.N[c];
  }
  // A caller's u0 (the statistical steady state's chunks after the first) comes before the file.
  if (!u0.empty()) {
    PetscCheck((PetscInt)u0.size() == N, comm_, kErrInput, "option -transient_u0 has %zu values, the model has %" PetscInt_FMT " DOFs",
               u0.size(), N);
    PetscCheck(du0.empty() || (PetscInt)du0.size() == N, comm_, kErrInput,
               "option -transient_du0 has %zu values, the model has %" PetscInt_FMT " DOFs", du0.size(), N);
  } else if (!start_file.empty()) {
    PetscCall(io::ReadStartState(comm_, start_file, start_from, N, nc, "-transient_start", from_file));
    if (!from_file.R.empty()) r = Eigen::Map<const Eigen::VectorXd>(from_file.R.data(), 3 * nc);
    res.start = from_file.what;
    PetscCall(PetscPrintf(comm_, "transient: start from %s\n", res.start.c_str()));
  } else PetscCheck(m.phi_re, comm_, kErrInput, "transient: mode shapes are needed for the start (-stab_modes)");
  PetscCall(ti.SetUp(model, res.h));

  // The state. On one rank its Vecs are views of arrays of this function, which the integrator
  // updates in place: the bookkeeping and the records read them without a PETSc call per step.
  Eigen::VectorXd us, dus;
  VecH            U, dU;
  if (size == 1) {
    us.setZero(N), dus.setZero(N);
    PetscCall(VecCreateSeqWithArray(comm_, 1, N, us.data(), U.out()));
    PetscCall(VecCreateSeqWithArray(comm_, 1, N, dus.data(), dU.out()));
  } else {
    PetscCall(VecDuplicate(eq.U, U.out()));
    PetscCall(VecDuplicate(eq.U, dU.out()));
  }
  if (!from_file.U.empty()) {
    PetscCall(SetOwnedRows(from_file.U.data(), U));
    PetscCall(SetOwnedRows(from_file.dU.data(), dU));
  } else PetscCall(StartState(eq, m, U, dU));
  PetscCall(book.SetUp(model, size == 1 && ti.FixedSizeKernel(), U, dU, size == 1 ? us.data() : nullptr, size == 1 ? dus.data() : nullptr, r));
  StatusOf status_of(model.contacts, ti.Contact());

  const bool     show_prog = rank == 0 && (progress_set ? (bool)progress : isatty(STDERR_FILENO));
  Progress       progress_line(nsteps, res.h);
  PetscErrorCode ierr = 0;
  LoopContext    c{comm_, ti, res, book, status_of, progress_line, nsteps, monitor, show_prog};

  // The loop keeps to locals the compiler can hold in registers; everything else is in the
  // functions above and in the bookkeeping, called at the records, monitor lines and rare events only.
  bool done = false;
  if (size == 1) PetscCall(DenseLoop<3, 1>(c, U, dU, us.data(), dus.data(), r, &ierr, &done));
  if (size == 1 && !done) PetscCall(DenseLoop<12, 4>(c, U, dU, us.data(), dus.data(), r, &ierr, &done));
  if (!done) {
    Vec        Uv = U, dUv = dU;
    const auto step = [&](StepInfo &info) { return ti.Step(Uv, dUv, r, &info); };
    PetscCall(Loop(c, step, nullptr, nullptr, nullptr, r, &ierr));
  }
  const PetscInt fp_total = c.fp_total, nan_step = c.nan_step;
  book.Cut();
  res.summary.mean_fp_iterations = res.steps ? (PetscReal)fp_total / res.steps : 0;
  if (ti.Contact().FixedPointSingle()) res.summary.fp_refreshes = res.steps ? (PetscReal)ti.Contact().Refreshes() / res.steps : 0;
  if (rank == 0 && !res.streamed) Summarise(res, settle_tol, settle_periods);
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
  case Trend::Irregular: return "irregular";
  }
  return "?";
}

PetscReal TransientAnalysis::RecordBytes(PetscInt N, PetscInt nc)
{
  // t, U, dU, R (3 per point), energy (4) as reals; status as one integer per point.
  return (PetscReal)((1 + 2 * N + 3 * nc + 4) * sizeof(PetscReal) + nc * sizeof(PetscInt));
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
                                     "settled cycle period %.9g s (%.4f Hz): period, peak-to-peak and state change < %g over the last %" PetscInt_FMT
                                     " cycles (state return error %.1e%s)\n",
                                     (double)s.period, 1 / (double)s.period, (double)settle_tol, settle_periods + 1,
                                     (double)s.return_error,
                                     s.return_error >= settle_tol ? ", within the interpolation error between records: lower -transient_keep_every to check it closer" : ""));
  else if (s.trend == Trend::Growing || s.trend == Trend::Decaying || s.trend == Trend::Drifting)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "not settled: %s, peak-to-peak %+.3e per period (fitted over %" PetscInt_FMT
                                     " cycles, scatter %.1e); over the last %" PetscInt_FMT
                                     " cycles period spread %.3e, state return error %.2e (interpolation %.1e) (mean period %.9g s); run longer (-transient_periods)\n",
                                     TrendName(s.trend), (double)s.amplitude_rate, s.fit_cycles, (double)s.amplitude_scatter,
                                     settle_periods + 1, (double)s.period_change, (double)s.return_error, (double)s.return_floor,
                                     (double)s.period));
  else if (s.trend == Trend::Irregular)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "not settled: irregular, cycle-to-cycle scatter %.2e in peak-to-peak and %.2e in period with no trend "
                                     "(%+.1e per period over %" PetscInt_FMT " cycles); the state returns only within %.2e after a period "
                                     "(mean period over those cycles %.9g s): not a periodic cycle (quasi-periodic or chaotic motion)\n",
                                     (double)s.amplitude_scatter, (double)s.period_scatter, (double)s.amplitude_rate, s.fit_cycles,
                                     (double)s.return_error, (double)s.period));
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
  if (s.cycles > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "cycle read at the up-crossings of DOF %" PetscInt_FMT "'s mean (%" PetscInt_FMT
                                             " per period of the state), %" PetscInt_FMT " cycles, %.1f records per period\n",
                                     s.signal_dof, s.period_multiple, s.cycles, (double)s.records_per_period));
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
  if (s.fp_refreshes >= 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  passes on h W in float (-theta_fp_single): %.2f products with the double h W per step besides the first\n",
                                     (double)s.fp_refreshes));
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
  if (res.energy_kept) {
    PetscCall(out.WriteArray("/transient/energy", {n, 4}, res.energy.data()));
    PetscCall(out.WriteAttribute("/transient/energy", "columns", "E (kinetic + elastic), W_damping, W_reactions, W_load (cumulative, J)"));
  }
  PetscCall(out.WriteAttribute("/transient/status", "values", "0 separated, 1 stuck, 2 sliding"));
  PetscCall(out.WriteAttribute("/transient/R", "columns", "t, b, n (local frame, N)"));
  PetscCall(out.WriteAttribute("/transient", "h", res.h));
  PetscCall(out.WriteAttribute("/transient", "theta", res.theta));
  if (res.T_ref > 0) PetscCall(out.WriteAttribute("/transient", "steps_per_period", res.T_ref / res.h));
  PetscCall(out.WriteAttribute("/transient", "keep_every", res.keep_every));
  PetscCall(out.WriteAttribute("/transient", "complete", (PetscInt)res.complete));
  if (!res.start.empty()) PetscCall(out.WriteAttribute("/transient", "start", res.start.c_str()));
  const TransientSummary &S = res.summary;
  PetscReal summ[15] = {S.period,         S.mean_fp_iterations, S.frac_separated,    S.frac_stuck,        (PetscReal)S.trend,
                        S.amplitude_rate, S.period_change,      (PetscReal)settle_tol, S.return_error,    S.amplitude_change,
                        S.amplitude_scatter, S.period_scatter,  (PetscReal)S.signal_dof, (PetscReal)S.period_multiple,
                        S.return_floor};
  PetscCallMPI(MPI_Bcast(summ, 15, MPIU_REAL, 0, comm_));
  const Trend trend = (Trend)(int)summ[4];
  PetscCall(out.WriteAttribute("/transient", "settled", (PetscInt)(trend == Trend::Settled)));
  PetscCall(out.WriteAttribute("/transient", "trend", TrendName(trend)));
  PetscCall(out.WriteAttribute("/transient", "amplitude_rate", summ[5]));
  PetscCall(out.WriteAttribute("/transient", "period_change", summ[6]));
  PetscCall(out.WriteAttribute("/transient", "settle_tol", summ[7]));
  PetscCall(out.WriteAttribute("/transient", "settle_cycles", settle_periods + 1));
  PetscCall(out.WriteAttribute("/transient", "return_error", summ[8]));
  PetscCall(out.WriteAttribute("/transient", "amplitude_change", summ[9]));
  PetscCall(out.WriteAttribute("/transient", "amplitude_scatter", summ[10]));
  PetscCall(out.WriteAttribute("/transient", "period_scatter", summ[11]));
  PetscCall(out.WriteAttribute("/transient", "signal_dof", (PetscInt)summ[12]));
  PetscCall(out.WriteAttribute("/transient", "period_multiple", (PetscInt)summ[13]));
  PetscCall(out.WriteAttribute("/transient", "return_floor", summ[14]));
  PetscCall(out.WriteAttribute("/transient", "period", summ[0]));
  PetscCall(out.WriteAttribute("/transient", "mean_fp_iterations", summ[1]));
  PetscCall(out.WriteAttribute("/transient", "fraction_separated", summ[2]));
  PetscCall(out.WriteAttribute("/transient", "fraction_stuck", summ[3]));
  PetscFunctionReturn(0);
}

} // namespace squeal
