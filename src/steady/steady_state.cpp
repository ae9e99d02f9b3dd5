#include "squeal/steady/steady_state.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"

#include <Eigen/Dense>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numeric>

namespace squeal {

SteadyState::~SteadyState()
{
  if (monitor_) PetscCallAbort(comm_, PetscViewerDestroy(&monitor_));
}

PetscErrorCode SteadyState::SetFromOptions()
{
  OptionChecks checks;
  PetscBool    mon = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, "steady_", "Statistical steady state (levels and spectrum of a transient without a periodic orbit)", "SteadyState");
  SquealOptionsReal("-rtol", "Converged: the 95 % interval of the RMS has a half-width, and the RMS a drift over the record, below this (relative; signal DOF and total normal reaction)",
                    "SteadyState", &rtol, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-batches", "Batches for the batch-means interval (Student t)", "SteadyState", batches, &batches, nullptr));
  SquealOptionsReal("-chunk_periods", "The transient runs on in chunks of this many periods of the starting mode (or a quarter of the record so far, if longer) until converged",
                    "SteadyState", &chunk_periods, Range::Positive(), checks);
  SquealOptionsReal("-max_periods", "Budget: at most this many periods of the starting mode in all", "SteadyState", &max_periods,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-dof", "DOF whose levels and spectrum are computed (-1: the one the transient's cycle summary reads, "
                                    "the DOF that moves most, for which the first chunk keeps its displacements; given: no state is kept)",
                            "SteadyState", dof, &dof, nullptr));
  PetscCall(PetscOptionsBool("-from_mode",
                             "-analyses auto's statistical route starts from the mode (as the transient) instead of the pre-periods' end state",
                             "SteadyState", from_mode, &from_mode, nullptr));
  PetscCall(PetscOptionsName("-monitor", "After each chunk: the start-up cut, levels, lines and verdict so far ([viewer], default stdout)",
                             "SteadyState", &mon));
  PetscCall(PetscOptionsName("-view", "The result after the run ([viewer])", "SteadyState", nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(batches >= 2, comm_, kErrInput, "option -steady_batches = %" PetscInt_FMT ": expected >= 2", batches);
  PetscCheck(dof >= -1, comm_, kErrInput, "option -steady_dof = %" PetscInt_FMT ": expected a DOF index >= 0 (or -1)", dof);
  PetscCheck(max_periods >= chunk_periods, comm_, kErrInput,
             "option -steady_max_periods = %g is below -steady_chunk_periods = %g: expected at least one chunk", (double)max_periods,
             (double)chunk_periods);
  if (monitor_) PetscCall(PetscViewerDestroy(&monitor_));
  if (mon) {
    PetscBool flg;
    PetscCall(PetscOptionsGetViewer(comm_, nullptr, "steady_", "-monitor", &monitor_, &monitor_format_, &flg));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::Analyse(SteadyStateResult &res) const
{
  static PetscLogEvent ev = 0; // the statistics after each chunk, in -log_view
  PetscMPIInt          rank;
  PetscFunctionBeginUser;
  if (!ev) PetscCall(PetscLogEventRegister("SteadyAnalyse", PETSC_OBJECT_CLASSID, &ev));
  PetscCall(PetscLogEventBegin(ev, 0, 0, 0, 0));
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  int conv = 0;
  if (rank == 0 && res.t.size() >= 2) {
    PetscCallCXX(res.signal = steady::Analyse(res.x, res.t[1] - res.t[0], batches));
    if (!res.rn.empty()) {
      const std::vector<double> r(res.rn.begin() + (long)res.signal.cut, res.rn.end());
      res.normal = steady::BatchLevels(r, batches);
    }
    if (res.projection.Modes()) res.modal = res.projection.Analyse(res.signal.cut);
    const steady::Levels &L = res.signal.levels, &R = res.normal;
    conv = L.rms > 0 && L.rel_halfwidth < rtol && L.drift < rtol && (res.rn.empty() || (R.rel_halfwidth < rtol && R.drift < rtol));
  }
  PetscCallMPI(MPI_Bcast(&conv, 1, MPI_INT, 0, comm_));
  PetscCall(PetscLogEventEnd(ev, 0, 0, 0, 0));
  res.converged = conv;
  PetscFunctionReturn(0);
}

namespace {
// Chunks after the first ones: this fraction of the record so far (SteadyState::Run).
constexpr PetscReal kChunkGrowth = 0.25;
// Above this many DOFs the statistical steady state takes kFeStepsPerPeriod steps per period.
constexpr PetscInt  kDenseStepsMaxDofs = 200;
constexpr PetscReal kFeStepsPerPeriod  = 200;
} // namespace

PetscReal steady::StatisticsStepsPerPeriod(PetscInt N, PetscReal steps, bool steps_given)
{
  return !steps_given && N > kDenseStepsMaxDofs && steps > kFeStepsPerPeriod ? kFeStepsPerPeriod : steps;
}

PetscErrorCode SteadyState::Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, ThetaIntegrator &ti,
                                TransientAnalysis &transient, const std::vector<PetscReal> &u0, const std::vector<PetscReal> &du0,
                                const std::string &start, SteadyStateResult &res)
{
  const PetscInt N = model.Size(), nc = model.contacts.Size();
  PetscMPIInt    rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCheck(dof < N, comm_, kErrInput, "option -steady_dof = %" PetscInt_FMT ": the model has %" PetscInt_FMT " DOFs", dof, N);
  const auto t0 = std::chrono::steady_clock::now();
  res           = SteadyStateResult{};
  res.start     = start;
  // The transient's settings, put back on the way out: each chunk starts where the last ended.
  struct Restore {
    TransientAnalysis     &tr;
    std::vector<PetscReal> u0, du0;
    PetscReal              periods, t_final, h, steps;
    ~Restore()
    {
      tr.u0 = u0, tr.du0 = du0, tr.periods = periods, tr.t_final = t_final, tr.h = h, tr.steps_per_period = steps;
      tr.on_record = nullptr, tr.on_record_bytes = 0, tr.energy = true;
    }
  } restore{transient, transient.u0, transient.du0, transient.periods, transient.t_final, transient.h, transient.steps_per_period};
  if (!u0.empty()) transient.u0 = u0, transient.du0 = du0;
  transient.energy = false; // the statistics read the state and the reactions only
  // Steps per period from the model unless given: the statistics of an FE model need its levels and
  // lines, not the phase of one period to 1e-6, and at the transient's 1000 a 50-period chunk of
  // the 2625-DOF pad (807 DOFs) took 10.5 min, of the brake (1267 DOFs) 15 min, loaded. 200, as
  // shooting above 99 DOFs: a period error (2 pi / 200)^2 / 12 = 8e-5.
  if (steady::StatisticsStepsPerPeriod(N, transient.steps_per_period, transient.steps_given) != transient.steps_per_period) {
    transient.steps_per_period = kFeStepsPerPeriod;
    PetscCall(PetscPrintf(comm_, "steady state: %d steps per period for N = %" PetscInt_FMT " DOFs (-transient_steps_per_period: chosen from the model unless given)\n",
                          (int)kFeStepsPerPeriod, N));
  }
  // The unstable modes' shapes on rank 0, for the modal projection of the records.
  std::vector<std::vector<double>> modes_re, modes_im;
  for (PetscInt m : stab.unstable) {
    const Mode &md = stab.modes[(size_t)m];
    if (!md.phi_re) {
      res.modal_note = "the stability analysis kept no mode shapes";
      modes_re.clear(), modes_im.clear(), res.mode_index.clear(), res.mode_frequency.clear(), res.mode_growth.clear();
      break;
    }
    std::vector<PetscReal> re, im;
    PetscCall(GatherVector(md.phi_re, false, re));
    if (md.Oscillatory() && md.phi_im) PetscCall(GatherVector(md.phi_im, false, im));
    modes_re.push_back(re), modes_im.push_back(im);
    res.mode_index.push_back(m), res.mode_frequency.push_back(md.Frequency()), res.mode_growth.push_back(md.sigma);
  }
  if (stab.unstable.empty()) res.modal_note = "no unstable mode in the band";
  if (rank != 0) modes_re.clear(), modes_im.clear();
  // Chunks of a whole number of records: the records of successive chunks lie on one grid.
  // The first chunk's transient may thin its records for its memory budget (-transient_max_memory:
  // the size-2 brake's first chunk keeps 1.25 N doubles a record for the signal DOF's choice, 12 GB
  // at every step): the grid is then its, and the later chunks are run on it.
  PetscInt       keep = transient.keep_every;
  struct RestoreKeep {
    TransientAnalysis &t;
    const PetscInt     kept;
    ~RestoreKeep() { t.keep_every = kept; }
  } restore_keep{transient, transient.keep_every};
  PetscInt       chunk_steps = 0, max_chunks = 0;
  PetscInt64     rest = 0, rest_done = 0; // steps after the first chunk: the budget's, those run
  PetscReal      h = 0, elapsed = 0;
  // The records as the transient hands them over (rank 0), none kept whole: t, the signal DOF, the
  // total normal reaction and the modal projection's values. A later chunk's first record is the
  // last one's end state; the first chunk's tail record may lie off the grid (its step count from
  // -steady_chunk_periods): both are left out, and the next chunk starts from the tail all the same.
  // Without -steady_dof the signal DOF is the one the first chunk's cycle summary reads, known at
  // its end only: until then that chunk's displacements are kept, and the velocities of the last
  // 20 % the summary reads (of the planned records: an interrupted chunk's summary window starts
  // earlier, and its DOF is then chosen on the chord between records, without the velocities).
  PetscInt                chunk = 0;
  const bool              auto_dof = dof < 0;
  RecordVector<PetscReal> first_u, first_v;
  size_t                  v_from = 0;
  res.dof                        = dof;
  transient.on_record = [&](const TransientResult &tr, const TransientRecord &rec) -> PetscErrorCode {
    PetscFunctionBeginUser;
    if (chunk == 0 && rec.index == 0) {
      keep = tr.keep_every;
      // The modal sums' checkpoints about once per period of the starting mode, at most ~512 in
      // the budget: the modal window starts within a period of the start-up cut.
      if (!modes_re.empty()) {
        const size_t per_period = std::max<size_t>(1, (size_t)std::llround(tr.T_ref / (tr.h * keep)));
        const size_t every      = per_period * std::max<size_t>(1, (size_t)std::ceil(max_periods / 512.0));
        (void)res.projection.SetUp(modes_re, modes_im, every, &res.modal_note); // false: the note says why
      }
      if (auto_dof) {
        const size_t nr = 1 + (size_t)(tr.steps_planned / tr.keep_every) + (tr.steps_planned % tr.keep_every ? 1 : 0);
        v_from          = nr - std::max<size_t>(nr / 5, 2);
        PetscCallCXX(first_u.reserve(nr * N));
        PetscCallCXX(first_v.reserve((nr - v_from) * N));
      }
    }
    if (chunk > 0 && rec.index == 0) PetscFunctionReturn(0);
    if (chunk == 0 && auto_dof) {
      PetscCallCXX(first_u.insert(first_u.end(), rec.U, rec.U + N));
      if (rec.index >= v_from) PetscCallCXX(first_v.insert(first_v.end(), rec.V, rec.V + N));
    }
    if (chunk == 0 && rec.step % keep) PetscFunctionReturn(0);
    PetscCallCXX(res.t.push_back(elapsed + rec.t));
    if (res.dof >= 0) PetscCallCXX(res.x.push_back(rec.U[res.dof]));
    if (nc > 0) {
      PetscReal s = 0;
      for (PetscInt c = 0; c < nc; ++c) s += rec.R[3 * c + 2];
      PetscCallCXX(res.rn.push_back(s));
    }
    PetscCallCXX(res.projection.Add(rec.U, 1));
    PetscFunctionReturn(0);
  };
  transient.on_record_bytes = (PetscReal)(3 + 2 * modes_re.size() + 1) * sizeof(PetscReal) + (auto_dof ? 1.25 * N * sizeof(PetscReal) : 0);
  for (PetscInt k = 0; !res.converged; ++k) {
    TransientResult tr;
    chunk = k;
    if (k == 0) {
      transient.periods = chunk_periods, transient.t_final = 0;
    } else {
      // Chunks grow with the record (kChunkGrowth of it, on the record grid): the statistics after each
      // chunk read the whole record, so with chunks of a fixed length their cost grew as the square
      // of the run (35 s of 108 s in 1000 periods of the 782-DOF brake, 20 chunks). Growing, the
      // statistics cost a bounded multiple of the last one; the first chunks keep their length.
      const PetscInt64 grow  = (PetscInt64)std::llround(kChunkGrowth * elapsed / h / keep) * keep;
      transient.on_record_bytes = (PetscReal)(3 + 2 * modes_re.size() + 1) * sizeof(PetscReal);
      // ... but no longer than the records' memory budget holds on the first chunk's grid (else the
      // transient would thin this chunk's records onto another grid).
      PetscInt64 fit;
      PetscCall(transient.StreamedRecordsFit(&fit));
      const PetscInt64 cap   = std::max<PetscInt64>(1, fit - 2) * keep;
      const PetscInt64 steps = std::min<PetscInt64>({std::max<PetscInt64>(chunk_steps, grow), cap, rest - rest_done});
      transient.h = h, transient.t_final = (PetscReal)steps * h;
    }
    const double chunk_start = MPI_Wtime();
    PetscCall(transient.Run(model, eq, stab, ti, tr));
    const double chunk_seconds = MPI_Wtime() - chunk_start;
    // Stopped by a signal (the transient leaves on nothing else without an error): the records so
    // far, this chunk's too, are analysed, and complete stays false.
    const bool         stopped = !tr.complete;
    unsigned long long have    = rank == 0 ? (unsigned long long)tr.t.size() : 0;
    PetscCallMPI(MPI_Bcast(&have, 1, MPI_UNSIGNED_LONG_LONG, 0, comm_));
    if (stopped) {
      char b[256];
      std::snprintf(b, sizeof b, "interrupted by %s during chunk %" PetscInt_FMT " after %" PetscInt_FMT " of its steps%s",
                    InterruptSignal() ? InterruptSignalName() : "a signal", k + 1, tr.steps,
                    have < 2 || (k == 0 && have < 4) ? ", before enough records for the statistics" : "");
      res.interrupted = b;
      if (have < 2 || (k == 0 && have < 4)) {
        if (k == 0) res.t.clear(), res.rn.clear(); // no signal DOF chosen: nothing analysed
        break;
      }
    }
    PetscCheck(k == 0 || stopped || tr.keep_every == keep, comm_, kErrInput,
               "steady state: chunk %" PetscInt_FMT " recorded every %" PetscInt_FMT "-th step for its memory budget, not every %" PetscInt_FMT
               "-th as the first: raise -transient_max_memory or lower -steady_chunk_periods",
               k + 1, tr.keep_every, keep);
    if (k == 0) {
      res.T_ref = tr.T_ref;
      h         = tr.h;
      if (keep != transient.keep_every) {
        PetscCall(PetscPrintf(comm_, "steady state: every chunk records every %" PetscInt_FMT "-th step, as the first (thinned for its memory budget)\n", keep));
        transient.keep_every = keep;
      }
      // Later chunks: a whole number of records, about chunk_periods each.
      chunk_steps = std::max<PetscInt>(keep, (PetscInt)std::llround(chunk_periods * tr.T_ref / h / keep) * keep);
      max_chunks  = 1 + (PetscInt)std::ceil((max_periods - chunk_periods) * tr.T_ref / (chunk_steps * h) - 1e-9);
      rest        = (PetscInt64)(max_chunks - 1) * chunk_steps;
      if (auto_dof) {
        // The DOF the transient's summary reads over the last 20 % of this chunk's records.
        if (rank == 0) {
          const size_t nr = tr.t.size(), from = nr - std::max<size_t>(nr / 5, 2);
          TransientResult w;
          w.N = N, w.T_ref = tr.T_ref;
          PetscCallCXX(w.t.assign(tr.t.begin() + (long)from, tr.t.end()));
          PetscCallCXX(w.U.assign(first_u.begin() + (long)(from * N), first_u.end()));
          if (from >= v_from && first_v.size() == (nr - v_from) * N) PetscCallCXX(w.V.assign(first_v.begin() + (long)((from - v_from) * N), first_v.end()));
          res.first_chunk_state_bytes = (first_u.size() + first_v.size()) * sizeof(PetscReal);
          res.dof = std::max<PetscInt>(0, TransientAnalysis::SignalDof(w));
          for (size_t i = 0; i < res.t.size(); ++i) PetscCallCXX(res.x.push_back(first_u[i * N + res.dof]));
          RecordVector<PetscReal>().swap(first_u), RecordVector<PetscReal>().swap(first_v);
        }
        PetscCallMPI(MPI_Bcast(&res.dof, 1, MPIU_INT, 0, comm_));
      }
    }
    // The end state (the transient keeps the last record's), where the next chunk starts.
    std::vector<PetscReal> endU(N), endV(N);
    if (rank == 0) {
      PetscCheck(tr.t.size() >= 2 && (k == 0 || stopped || (tr.steps % keep) == 0), PETSC_COMM_SELF, PETSC_ERR_PLIB,
                 "steady state: chunk %" PetscInt_FMT " off the record grid", k);
      std::copy(tr.U.end() - N, tr.U.end(), endU.begin());
      std::copy(tr.V.end() - N, tr.V.end(), endV.begin());
    }
    elapsed += tr.steps * h;
    if (k > 0) rest_done += tr.steps;
    const bool last = rest_done >= rest;
    PetscCallMPI(MPI_Bcast(endU.data(), (int)N, MPIU_REAL, 0, comm_));
    PetscCallMPI(MPI_Bcast(endV.data(), (int)N, MPIU_REAL, 0, comm_));
    transient.u0 = endU, transient.du0 = endV;
    res.U_end = endU, res.dU_end = endV;
    res.chunks  = k + 1;
    res.periods = elapsed / res.T_ref;
    PetscCall(Analyse(res));
    if (stopped) break;
    const steady::Levels &L = res.signal.levels;
    char nr[64] = "";
    if (!res.rn.empty())
      std::snprintf(nr, sizeof nr, "; normal reaction's +- %.1f %%, drift %.1f %%", 100 * (double)res.normal.rel_halfwidth,
                    100 * (double)res.normal.drift);
    PetscCall(PetscPrintf(comm_,
                          "steady state: chunk %" PetscInt_FMT ", %.0f periods (t = %.4g s; %.3g s, %.1f contact passes a step): RMS of DOF %" PetscInt_FMT
                          " %.4e +- %.1f %%, drift %.1f %%%s: %s\n",
                          k + 1, (double)res.periods, (double)elapsed, chunk_seconds, (double)tr.summary.mean_fp_iterations, res.dof, (double)L.rms, 100 * (double)L.rel_halfwidth,
                          100 * (double)L.drift, nr,
                          res.converged ? "converged" : (last ? "budget reached" : "running on")));
    if (monitor_) {
      PetscCall(PetscViewerPushFormat(monitor_, monitor_format_));
      PetscCall(View(res, monitor_));
      PetscCall(PetscViewerPopFormat(monitor_));
    }
    if (last) {
      res.complete = true;
      break;
    }
    res.complete = res.converged;
  }
  res.record_bytes = (1 + !res.x.empty() + !res.rn.empty()) * sizeof(PetscReal) + res.projection.RecordBytes();
  // The 807-DOF pad at mu = 0.3, V = 10 m/s (CB 30 kHz, -stab_fmax 12000) settled at 22.1 kHz, a
  // cluster of unstable modes of the lining above the band: the band's modes explained 0.3 % of it.
  if (rank == 0) PetscCallCXX(res.band_note = steady::BandNote(res.signal, stab.fmax > 0 ? (double)stab.fmax : (double)stab.CompleteUpTo()));
  res.seconds      = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::View(const SteadyStateResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  const steady::Analysis &a = res.signal;
  const steady::Levels   &L = a.levels;
  const double            tcut = res.t.size() > a.cut ? res.t[a.cut] : 0.0;
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "statistical steady state of DOF %" PetscInt_FMT " from %s: %.0f periods of %.6g s in %" PetscInt_FMT
                                   " chunk(s), %zu records, start-up dropped before t = %.6g s (MSER on the power per period)\n",
                                   res.dof, res.start.c_str(), (double)res.periods, (double)res.T_ref, res.chunks, res.t.size(), tcut));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "RMS %.4e (95 %% interval %.4e to %.4e, half-width %.1f %%, drift over the record %.1f %%), peak %.4e: %s\n",
                                   L.rms, L.rms_lo, L.rms_hi, 100 * L.rel_halfwidth, 100 * L.drift, L.peak,
                                   res.converged ? "converged" : "NOT converged (raise -steady_max_periods)"));
  if (!res.rn.empty())
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "total normal reaction: mean %.6g N, RMS about it %.4e N (95 %% interval %.4e to %.4e, drift %.1f %%), peak %.4e N\n",
                                     res.normal.mean, res.normal.rms, res.normal.rms_lo, res.normal.rms_hi, 100 * res.normal.drift, res.normal.peak));
  std::vector<size_t> order(a.lines.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t p, size_t q) { return a.amplitudes[p] > a.amplitudes[q]; });
  for (size_t i : order)
    PetscCall(PetscViewerASCIIPrintf(viewer, "line %14.6f Hz  amplitude %.4e  %s\n", a.lines[i], a.amplitudes[i], a.cls.names[i].c_str()));
  PetscCall(PetscViewerASCIIPrintf(viewer, "verdict: %s (%s)\n", a.cls.verdict.c_str(), a.cls.evidence.c_str()));
  const steady::ModalProjection::Result &q = res.modal;
  if (!q.rms.empty() && q.rms.size() == res.mode_index.size()) {
    const double tq = res.t.size() > q.from ? res.t[q.from] : 0.0;
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "unstable modes (least-squares fit of the states on Re phi, Im phi from t = %.6g s, %zu records; shapes' "
                                     "condition number %.3g):\n",
                                     tq, q.records, q.cond));
    PetscCall(PetscViewerASCIIPushTab(viewer));
    for (size_t j = 0; j < q.rms.size(); ++j)
      PetscCall(PetscViewerASCIIPrintf(viewer, "mode %" PetscInt_FMT " (%.2f Hz, growth rate %.4g 1/s): modal RMS %.4e, share of the motion %.1f %%\n",
                                       res.mode_index[j], (double)res.mode_frequency[j], (double)res.mode_growth[j], q.rms[j], 100 * q.share[j]));
    PetscCall(PetscViewerASCIIPrintf(viewer, "together they explain %.1f %% of the motion's variance; residual %.1f %%\n", 100 * q.explained,
                                     100 * (1 - q.explained)));
    PetscCall(PetscViewerASCIIPopTab(viewer));
  } else if (!res.modal_note.empty())
    PetscCall(PetscViewerASCIIPrintf(viewer, "unstable modes: no projection (%s)\n", res.modal_note.c_str()));
  if (!res.band_note.empty()) PetscCall(PetscViewerASCIIPrintf(viewer, "note: %s\n", res.band_note.c_str()));
  if (!res.interrupted.empty()) PetscCall(PetscViewerASCIIPrintf(viewer, "%s\n", res.interrupted.c_str()));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::ViewFromOptions(const SteadyStateResult &res) const
{
  PetscFunctionBeginUser;
  PetscCall(squeal::ViewFromOptions(comm_, "steady_", [&](PetscViewer v) { return View(res, v); }));
  PetscFunctionReturn(0);
}

PetscErrorCode SteadyState::Write(const SteadyStateResult &res, io::H5Writer &out) const
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  const steady::Analysis &a = res.signal;
  const steady::Levels   &L = a.levels;
  // Sizes from rank 0 (the records and the analysis are there).
  unsigned long long n[4] = {a.freq.size(), a.lines.size(), res.t.size() - std::min(res.t.size(), a.cut), res.rn.empty() ? 0ull : 1ull};
  PetscCallMPI(MPI_Bcast(n, 4, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  // The end state, every rank's copy the same: a run goes on from it (-transient_start, -shoot_start).
  if (!res.U_end.empty() && res.U_end.size() == res.dU_end.size()) {
    std::vector<PetscReal> z(res.U_end);
    PetscCallCXX(z.insert(z.end(), res.dU_end.begin(), res.dU_end.end()));
    PetscCall(out.WriteArray("/steady_state/Z_end", {(hsize_t)z.size()}, z.data()));
    PetscCall(out.WriteAttribute("/steady_state/Z_end", "layout", "(U, dU) at the end of the last chunk"));
  }
  PetscCall(out.WriteArray("/steady_state/psd_frequency", {n[0]}, a.freq.data()));
  PetscCall(out.WriteArray("/steady_state/psd", {n[0]}, a.psd.data()));
  PetscCall(out.WriteArray("/steady_state/lines", {n[1]}, a.lines.data()));
  PetscCall(out.WriteArray("/steady_state/line_amplitudes", {n[1]}, a.amplitudes.data()));
  // The analysed records after the cut: plotted without the transient's records.
  PetscCall(out.WriteArray("/steady_state/t", {n[2]}, rank == 0 ? res.t.data() + a.cut : nullptr));
  PetscCall(out.WriteArray("/steady_state/signal", {n[2]}, rank == 0 ? res.x.data() + a.cut : nullptr));
  if (n[3]) PetscCall(out.WriteArray("/steady_state/normal_reaction", {n[2]}, rank == 0 ? res.rn.data() + a.cut : nullptr));
  const char *g = "/steady_state";
  std::string names;
  for (size_t i = 0; i < a.cls.names.size(); ++i) names += (i ? "; " : "") + a.cls.names[i];
  PetscCall(out.WriteAttribute(g, "line_names", names.c_str()));
  PetscCall(out.WriteAttribute(g, "dof", res.dof));
  PetscCall(out.WriteAttribute(g, "t_cut", (PetscReal)(res.t.size() > a.cut ? res.t[a.cut] : 0.0)));
  PetscCall(out.WriteAttribute(g, "rms", (PetscReal)L.rms));
  PetscCall(out.WriteAttribute(g, "rms_lo", (PetscReal)L.rms_lo));
  PetscCall(out.WriteAttribute(g, "rms_hi", (PetscReal)L.rms_hi));
  PetscCall(out.WriteAttribute(g, "peak", (PetscReal)L.peak));
  PetscCall(out.WriteAttribute(g, "converged", (PetscInt)res.converged));
  PetscCall(out.WriteAttribute(g, "drift", (PetscReal)L.drift));
  PetscCall(out.WriteAttribute(g, "verdict", a.cls.verdict.c_str()));
  PetscCall(out.WriteAttribute(g, "evidence", a.cls.evidence.c_str()));
  PetscCall(out.WriteAttribute(g, "bases", std::vector<PetscReal>(a.cls.bases.begin(), a.cls.bases.end())));
  PetscCall(out.WriteAttribute(g, "rtol", rtol));
  PetscCall(out.WriteAttribute(g, "batches", batches));
  PetscCall(out.WriteAttribute(g, "chunks", res.chunks));
  PetscCall(out.WriteAttribute(g, "periods", res.periods));
  PetscCall(out.WriteAttribute(g, "T_ref", res.T_ref));
  PetscCall(out.WriteAttribute(g, "start", res.start.c_str()));
  if (n[3]) {
    PetscCall(out.WriteAttribute(g, "normal_mean", (PetscReal)res.normal.mean));
    PetscCall(out.WriteAttribute(g, "normal_rms", (PetscReal)res.normal.rms));
    PetscCall(out.WriteAttribute(g, "normal_rms_lo", (PetscReal)res.normal.rms_lo));
    PetscCall(out.WriteAttribute(g, "normal_rms_hi", (PetscReal)res.normal.rms_hi));
    PetscCall(out.WriteAttribute(g, "normal_peak", (PetscReal)res.normal.peak));
  }
  // The modal projection: per unstable mode (the script's mode_rms, and more).
  unsigned long long nm[2] = {res.modal.rms.size(), (unsigned long long)res.modal.q.rows()};
  PetscCallMPI(MPI_Bcast(nm, 2, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  if (nm[0]) {
    std::vector<PetscReal> idx(res.mode_index.begin(), res.mode_index.end());
    PetscCall(out.WriteArray("/steady_state/mode_index", {nm[0]}, idx.data()));
    PetscCall(out.WriteArray("/steady_state/mode_frequency", {nm[0]}, res.mode_frequency.data()));
    PetscCall(out.WriteArray("/steady_state/mode_growth_rate", {nm[0]}, res.mode_growth.data()));
    PetscCall(out.WriteArray("/steady_state/mode_rms", {nm[0]}, res.modal.rms.data()));
    PetscCall(out.WriteArray("/steady_state/mode_share", {nm[0]}, res.modal.share.data()));
    // Row-major records x 2k (a_j, b_j): Eigen's default is column-major.
    std::vector<PetscReal> qrow;
    if (rank == 0) {
      const Eigen::MatrixXd &Q = res.modal.q;
      qrow.resize((size_t)Q.size());
      for (Eigen::Index i = 0; i < Q.rows(); ++i)
        for (Eigen::Index c = 0; c < Q.cols(); ++c) qrow[(size_t)(i * Q.cols() + c)] = Q(i, c);
    }
    PetscCall(out.WriteArray("/steady_state/modal_coordinates", {nm[1], 2 * nm[0]}, qrow.data()));
    PetscCall(out.WriteAttribute(g, "modes_explained", (PetscReal)res.modal.explained));
    PetscCall(out.WriteAttribute(g, "modes_residual", (PetscReal)(1 - res.modal.explained)));
    PetscCall(out.WriteAttribute(g, "modes_variance", (PetscReal)res.modal.variance));
    PetscCall(out.WriteAttribute(g, "modes_condition", (PetscReal)res.modal.cond));
    PetscCall(out.WriteAttribute(g, "modes_from", (PetscInt)res.modal.from));
    PetscCall(out.WriteAttribute(g, "modes_t_from", (PetscReal)(res.t.size() > res.modal.from ? res.t[res.modal.from] : 0.0)));
    PetscCall(out.WriteAttribute(g, "modes_method",
                                 "least-squares fit of the state records (window mean removed) on Re phi_j, Im phi_j of /stability/modes: "
                                 "u - mean ~ sum_j Re(phi_j q_j), q_j = a_j - i b_j; mode_rms = sqrt(mean |q_j|^2); mode_share = mean "
                                 "|Re(phi_j q_j)|^2 / mean |u - mean|^2; the window from the first checkpoint at or after the start-up cut"));
  } else {
    std::string note = rank == 0 ? res.modal_note : std::string();
    if (rank == 0 && note.empty()) note = "no records to project";
    PetscCall(out.WriteAttribute(g, "modes_note", note.c_str()));
  }
  if (!res.interrupted.empty()) PetscCall(out.WriteAttribute(g, "interrupted", res.interrupted.c_str()));
  {
    int has = rank == 0 && !res.band_note.empty();
    PetscCallMPI(MPI_Bcast(&has, 1, MPI_INT, 0, comm_));
    if (has) PetscCall(out.WriteAttribute(g, "band_note", rank == 0 ? res.band_note.c_str() : ""));
  }
  PetscCall(out.WriteAttribute(g, "method",
                               "squeal SteadyState (C++): MSER start-up cut on the power per period; batch-means 95 % interval; Welch PSD "
                               "(Hann, 50 % overlap); lines refined by least-squares sinusoids; transient run on in chunks until converged"));
  PetscFunctionReturn(0);
}

} // namespace squeal
