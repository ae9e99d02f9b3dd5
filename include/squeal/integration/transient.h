// Analysis "transient": a long run of the theta-method from the sliding equilibrium plus a small
// multiple of a mode (default: the most unstable one), or from a given state, to the settled
// limit cycle. Options prefix "transient_"; the integrator keeps its own ("theta_").
// A model without an oscillatory mode (overdamped) runs when -transient_h is given.
// Before the run the records' size (records x RecordBytes) is checked against
// -transient_max_memory: over it, keep_every is raised automatically (and said), or, when the user
// set -transient_keep_every, the run is refused with the numbers.
//
// Recorded every -transient_keep_every steps: t, U, dU, local reactions, contact status, and the
// energy balance  E(t) - E(0) = W_reactions + W_load - W_damping  (E kinetic + elastic; every
// work term summed step by step from the discrete velocities), whose defect measures the
// discretisation error (exactly zero at theta = 1/2 without impacts).
#pragma once

#include "squeal/integration/theta.h"
#include "squeal/io/h5.h"
#include "squeal/stability/stability.h"

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace squeal {

// Settled means settled. The cycle is read off the last 20 % of the records on the DOF that moves
// most: a Poincare section at the up-crossings of its mean, counted with hysteresis (a crossing
// counts only after the DOF went below mean - 0.5 x the previous cycle's depth, so harmonics that
// wiggle across the mean are not cycles), timed by the cubic Hermite interpolant of (U, dU)
// between records. The state's period is the section spacing, or 2 or 3 spacings when the whole
// state (U, dU / omega) returns only after that many. Per cycle: period, peak-to-peak, and the
// state's return error. Settled: over the last -transient_settle_periods + 1 cycles the period
// and the peak-to-peak change and the state returns by less than -transient_settle_tol
// (relative; the return, by less than its interpolation error between records when that is
// larger). Otherwise the trend: growing / decaying when the peak-to-peak's fitted change per
// period dominates its cycle-to-cycle scatter, irregular when the scatter (peak-to-peak or
// period) exceeds the tolerance without such a trend, drifting otherwise. Records coarser than
// 1/8 of the period (or of the linear period) cannot resolve the cycle: "aliased".
enum class Trend { Settled = 0, Growing, Decaying, Drifting, Aliased, TooShort, NoOscillation, Irregular };
const char *TrendName(Trend t);

struct TransientSummary {
  PetscReal              period = 0;     // mean cycle period over the last settle_periods + 1 cycles (else all); 0 if none
  Trend                  trend = Trend::NoOscillation;
  bool                   settled = false;
  PetscReal              amplitude_rate = 0; // relative change of the peak-to-peak per period (fit over the cycles in the last 20 %)
  PetscReal              period_change = 0;  // (max - min) / mean of the cycle periods (last settle_periods + 1 cycles)
  PetscReal              amplitude_change = 0; // (max - min) / max of the peak-to-peak per cycle (same cycles)
  PetscReal              return_error = 0;     // max over the same cycles of |Z(t + T) - Z(t)| / mean |Z|, Z = (U - mean, dU / omega)
  PetscReal              return_floor = 0;     // its interpolation error between records (estimate): the check's resolution
  PetscReal              amplitude_scatter = 0; // std of log(peak-to-peak) about its fitted trend, cycles in the last 20 %
  PetscReal              period_scatter = 0;    // std / mean of the cycle periods, cycles in the last 20 %
  PetscInt               cycles = 0;         // complete cycles in the last 20 %
  PetscInt               fit_cycles = 0;     // cycles the trend was fitted on
  PetscInt               signal_dof = -1;    // DOF whose crossings define the section
  PetscInt               period_multiple = 1; // section crossings per period of the state (1, 2 or 3)
  PetscReal              records_per_period = 0;
  std::vector<PetscReal> peak_to_peak;   // per DOF, over the last 20 % of the run (extrema refined between records)
  PetscReal              frac_separated = 0, frac_stuck = 0, frac_sliding = 0; // over the last 20 %, all points
  PetscReal              mean_fp_iterations = 0;
  PetscReal              fp_refreshes = -1; // h W read in float: v remade with the double h W, per step (-1: double passes)
  PetscInt               fp_capped = 0, first_capped_step = -1;
  PetscReal              first_capped_residual = 0;
  PetscReal              energy_defect = 0; // max |balance| / max E over the run
};

// std::allocator, except that growing a vector leaves the new elements uninitialised: Run sizes the
// records for the whole run before it starts and writes each value once, where a zero fill would
// write every record twice (a third of the bookkeeping of a 3-DOF step recorded at every step).
template <class T>
struct RecordAllocator : std::allocator<T> {
  using std::allocator<T>::allocator;
  template <class U>
  struct rebind {
    using other = RecordAllocator<U>;
  };
  template <class U>
  void construct(U *p) noexcept
  {
    ::new (static_cast<void *>(p)) U;
  }
  template <class U, class... Args>
  void construct(U *p, Args &&...args)
  {
    ::new (static_cast<void *>(p)) U(std::forward<Args>(args)...);
  }
};
template <class T>
using RecordVector = std::vector<T, RecordAllocator<T>>;

struct TransientResult {
  PetscReal               h = 0, theta = 0, T_ref = 0;
  std::string             start; // -transient_start: the state the run started from, else empty
  PetscInt                steps = 0, N = 0, nc = 0, keep_every = 1;
  PetscInt                steps_planned = 0; // the run's step count (steps: those done)
  RecordVector<PetscReal> t, U, V, R, energy; // energy: [E, W_damping, W_reactions, W_load] per record
  RecordVector<PetscInt>  status;
  // Set when TransientAnalysis::on_record took the records as they came: t and energy are every
  // record's, U, V, R and status the last record's only (the end state), and there is no summary.
  bool                   streamed = false;
  bool                   complete = false;
  bool                   energy_kept = true; // false: TransientAnalysis::energy was off, energy holds NaN

  TransientSummary       summary;
};

// One record as TransientAnalysis::Run hands it to on_record (rank 0): the state after `step`
// steps, valid during the call only.
struct TransientRecord {
  size_t           index = 0; // 0 for the start state
  PetscInt         step  = 0;
  PetscReal        t     = 0;
  const PetscReal *U = nullptr, *V = nullptr, *R = nullptr, *energy = nullptr; // N, N, 3 n_c, 4 values
  const PetscInt  *status = nullptr;                                           // n_c values
};

class TransientAnalysis {
public:
  explicit TransientAnalysis(MPI_Comm comm) : comm_(comm) {}
  // -transient_periods, -transient_t_final, -transient_steps_per_period, -transient_h,
  // -transient_keep_every, -transient_amplitude, -transient_mode, -transient_u0, -transient_du0,
  // -transient_start, -transient_start_from, -transient_monitor, -transient_progress,
  // -transient_settle_tol, -transient_settle_periods, -transient_max_memory.
  PetscErrorCode SetFromOptions();
  // Runs; on failure (NaN, solver error) res holds everything recorded so far.
  PetscErrorCode Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, ThetaIntegrator &ti,
                     TransientResult &res);
  PetscErrorCode View(const TransientResult &res, PetscViewer viewer) const;
  PetscErrorCode Write(const TransientResult &res, io::H5Writer &out) const;
  // The cycle summary from res.t, U, V (rank 0's records) and, when present, energy and status;
  // callable on synthetic records (energy and status empty).
  static void    Summarise(TransientResult &res, PetscReal settle_tol = 1e-3, PetscInt settle_periods = 5);
  // Bytes one record takes in memory on rank 0 and in the results file.
  static PetscReal RecordBytes(PetscInt N, PetscInt nc);
  // The DOF the cycle summary reads (TransientSummary::signal_dof, the one with the largest refined
  // peak-to-peak) over all the records of `window` (t, U and, for the refinement, V), where
  // Summarise reads the last 20 % of a run's: records nr - max(nr / 5, 2) .. nr - 1.
  static PetscInt SignalDof(const TransientResult &window);

  PetscReal periods = 200, t_final = 0, steps_per_period = 1000, h = 0, amplitude = 1e-5;
  PetscReal settle_tol = 1e-3, max_memory = 0; // max_memory: MiB of records; 0: a quarter of physical memory
  PetscInt  keep_every = 1, mode = -1, monitor = 0, settle_periods = 5;
  PetscBool keep_every_set = PETSC_FALSE;
  PetscBool steps_given    = PETSC_FALSE; // -transient_steps_per_period or -transient_h on the command line or in the scene
  PetscBool progress = PETSC_FALSE, progress_set = PETSC_FALSE;
  std::vector<PetscReal> u0, du0;
  // -transient_start FILE: the start state read from a results file, -transient_start_from which of
  // its states (auto: the first of transient, shooting, expanded, energy of the model's size).
  std::string start_file, start_from = "auto";
  // Not an option: a caller that analyses the records as they come (the statistical steady state)
  // sets it, and the run then keeps no full state per record (TransientResult::streamed). Called on
  // rank 0 at every record with the result's header (h, T_ref, keep_every, steps_planned) set.
  // on_record_bytes: what it keeps per record, for -transient_max_memory.
  std::function<PetscErrorCode(const TransientResult &, const TransientRecord &)> on_record;
  PetscReal                                                                       on_record_bytes = 0;
  // Not an option: a caller that reads no energy (the statistical steady state) sets it false, and
  // the run computes no works and energies (three products with M, C, K per step), only the NaN test.
  bool energy = true;
  // The records' memory budget in bytes (-transient_max_memory, or a quarter of rank 0's physical
  // memory), the same on every rank; and how many streamed records fit in it. Collective.
  PetscErrorCode RecordBudget(PetscReal *bytes) const;
  PetscErrorCode StreamedRecordsFit(PetscInt64 *records) const;

private:
  // Run's steps: the mode to start from, the records' number (keep_every raised, or the run refused,
  // over -transient_max_memory), the start state.
  PetscErrorCode StartMode(const StabilityResult &stab, const Mode **start) const;
  PetscErrorCode RecordCount(PetscInt N, PetscInt nc, PetscInt nsteps, TransientResult &res, PetscInt *records) const;
  PetscErrorCode StartState(const SlidingEquilibrium &eq, const Mode &m, Vec U, Vec dU) const;

  MPI_Comm comm_;
};

} // namespace squeal
