// The statistical steady state (docs/steady-state.md; issue 19 items 1 and 3): what a transient
// without a periodic orbit settles to, as levels with a confidence interval and a line spectrum.
// Options prefix "steady_".
//
// From a uniformly sampled signal x_i = x(t_0 + i dt) (the transient's signal DOF, and the total
// normal reaction sum_c r_n,c):
//   start-up  MSER (White 1997) on the local power p_j = mean over batch j of (x - xbar)^2, batches
//             of one period of the strongest line: the cut d minimises var(p_d..)/(n - d - 1),
//             d <= n/2;
//   levels    RMS about the mean and peak |x - xbar| of what remains; the 95 % interval of the mean
//             square from B batch means b_k of (x - xbar)^2, mean(b) +- t_{0.975, B-1} s_b / sqrt(B)
//             (Student t, the largest tabulated degree of freedom not above B - 1: conservative),
//             its square roots bracketing the RMS; converged when (hi - lo) / (2 RMS) < rtol and
//             the RMS's drift (the least-squares trend of the batch means over the record,
//             relative) < rtol, for both signals;
//   spectrum  Welch's PSD: Hann window (numpy's symmetric one), 50 % overlap, segments of
//             L = max(16, 2n/9) records, one-sided;
//   lines     the PSD's local maxima above 100x its median, each refined on the whole record's
//             4x zero-padded Hann spectrum (parabola on the log), then every frequency by
//             Gauss-Newton on the least-squares fit of sum_k a_k cos 2 pi f_k t + b_k sin 2 pi f_k t;
//   verdict   periodic (every line a harmonic k f1 of the strongest), quasi-periodic (every line
//             m f1 + n f2, |m|, |n| <= 4, with a second base f2), broadband (lines carry less than
//             half the power, or some are unexplained); unresolved, in place of the first two,
//             when the names could be chance: within the tolerance (3 resolutions of the record)
//             more than a quarter of the band would be named (the brake after 50 periods: +-1164 Hz).
// The same steps as scripts/steady_state.py, which reads the records after the run; here the
// transient runs on in chunks of -steady_chunk_periods (later ones a quarter of the record so far) until the levels converge or
// -steady_max_periods is reached. FFTs of any length: radix 2, Bluestein's chirp-z otherwise.
#pragma once

#include "squeal/integration/transient.h"
#include "squeal/io/h5.h"

#include <Eigen/Dense>

#include <complex>
#include <string>
#include <vector>

namespace squeal {

namespace steady {

// X_k = sum_j x_j exp(-2 pi i j k / nfft), k = 0..nfft/2, x zero-padded to nfft >= x.size().
std::vector<std::complex<double>> RealFFT(const std::vector<double> &x, size_t nfft);
// Two-sided 95 % Student t quantile for dof degrees of freedom (>= 1).
double StudentT975(long dof);
// Records of the start-up to drop: MSER on the power of batches of `batch` records.
size_t MserCut(const std::vector<double> &x, size_t batch);
// Records per period of the strongest line of the whole record (at least 5).
size_t DominantPeriodRecords(const std::vector<double> &x);

struct Levels {
  double mean = 0, rms = 0, peak = 0, rms_lo = 0, rms_hi = 0, rel_halfwidth = 0;
  // The RMS's relative change over the record from the least-squares line through the batch means
  // of the square: |slope| B / mean / 2. The interval assumes a stationary record; a slow trend
  // (a start-up longer than MSER's half) narrows it without making it right.
  double drift = 0;
};
Levels BatchLevels(const std::vector<double> &x, long batches);

// One-sided Welch PSD (Hann, 50 % overlap); freq[k] = k / (L dt).
void Welch(const std::vector<double> &x, double dt, int segments, std::vector<double> &freq, std::vector<double> &psd);
// Local maxima of psd above floor_factor x its median (psd[1:]), strongest first, at most max_lines.
std::vector<size_t> FindLines(const std::vector<double> &psd, double floor_factor, size_t max_lines, double *floor);
// Least-squares sinusoids with frequencies refined from f0 by Gauss-Newton: f and amplitudes.
void FitLines(const std::vector<double> &x, double dt, const std::vector<double> &f0, std::vector<double> &f, std::vector<double> &amp);

struct Classification {
  std::string              verdict, evidence;
  std::vector<double>      bases;
  std::vector<std::string> names; // per line, in the order of f
};
Classification Classify(const std::vector<double> &f, const std::vector<double> &amp, double power_in_lines, double total_power,
                        double df_res);

// Everything above for one signal sampled every dt.
struct Analysis {
  size_t              cut = 0;
  Levels              levels;
  std::vector<double> freq, psd, lines, amplitudes;
  Classification      cls;
};
Analysis Analyse(const std::vector<double> &x, double dt, long batches);

// Empty, or why the stability band misses the motion: its base frequency (the first base, else the
// strongest line) lies more than 2 % above `band_hz` (the band's upper edge; <= 0 or inf: none).
std::string BandNote(const Analysis &a, double band_hz);

// Steps per period of a transient whose levels and lines are wanted, not the phase of one period
// to 1e-6: an N-DOF model above 200 DOFs takes at most 200 (a period error (2 pi / 200)^2 / 12 =
// 8e-5), unless the step was given (-transient_steps_per_period or -transient_h). The statistical
// steady state and the torus's start-up transient take it.
PetscReal StatisticsStepsPerPeriod(PetscInt N, PetscReal steps, bool steps_given);

// Which linear modes carry the motion: the least-squares fit of the state records u_i (mean over
// the window removed) on the real basis B = [Re phi_1, Im phi_1, ..., Re phi_k, Im phi_k] (one
// column for a real mode), u_i - ubar ~ sum_j Re phi_j a_ji + Im phi_j b_ji = Re(phi_j q_ji) with
// q_j = a_j - i b_j the complex modal coordinate (phi normalised as the stability analysis does).
// Least squares rather than left eigenvectors: the coordinates are the unique best fit whenever
// the shapes are independent, however non-normal the system; the adjoint eigenvectors would give
// each mode's coefficient in the expansion over all 2N modes, but they are not computed (on a
// reduced model they are another PEP), and truncated to the k unstable modes that projection
// leaves a residual that is not the smallest. The same fit as scripts/steady_state.py's.
//
// The records stream through (Add, a record or a chunk at a time), none kept: per record only Q^T (u_i - u_ref) (B = Q R,
// thin Householder QR) and |u_i - u_ref|^2, plus the running sum of u_i - u_ref every `every`
// records, so that the mean and the variance come out exactly over a window that starts at such a
// checkpoint (the first one at or after the start-up cut).
class ModalProjection {
public:
  // modes_re[j], modes_im[j]: the N values of mode j (modes_im[j] empty: a real mode, one column).
  // False with `why` when the shapes are (nearly) dependent: no coordinates are then defined.
  bool SetUp(const std::vector<std::vector<double>> &modes_re, const std::vector<std::vector<double>> &modes_im, size_t every,
             std::string *why);
  // Records u_i = u[i N .. (i+1) N), i = first..n-1 (n = u.size() / N).
  void   Add(const double *u, size_t n, size_t first = 0);
  size_t Records() const { return e_.size(); }
  size_t Modes() const { return cols_.size(); }
  size_t Size() const { return N_; }
  // Bytes held per record (the values, not the vectors' spare capacity): (columns + 1) reals.
  size_t RecordBytes() const { return N_ ? (size_t)(Q_.cols() + 1) * sizeof(double) : 0; }
  // Bytes held in all: the basis and the checkpoints (N each), and the records'.
  size_t Bytes() const
  {
    return (size_t)(Q_.size() + R_.size() + ref_.size() + sum_.size() + (Eigen::Index)checkpoints_.size() * sum_.size()) * sizeof(double) +
           Records() * RecordBytes();
  }

  struct Result {
    size_t              from = 0, records = 0; // the window: records from..from+records-1
    std::vector<double> rms;                   // per mode: sqrt(mean |q_j - qbar_j|^2)
    // Per mode: mean |Re(phi_j q_j)|^2 / mean |u - ubar|^2 (the modes' parts are not orthogonal: the
    // shares need not add up to `explained`).
    std::vector<double> share;
    double              explained = 0; // 1 - |residual|^2 / |u - ubar|^2 over the window (all modes together)
    double              variance  = 0; // mean |u - ubar|^2
    double              cond      = 0; // condition number of B's R factor
    Eigen::MatrixXd     q;             // records x 2k: a_j (column 2j) and b_j (2j + 1), mean removed
  };
  // Over the records from the first checkpoint at or after `cut` (from `cut` itself if that leaves
  // fewer than 2 records, or from the last checkpoint before it).
  Result Analyse(size_t cut) const;

private:
  size_t                           N_ = 0, every_ = 1;
  double                           cond_ = 0;
  Eigen::MatrixXd                  Q_, R_;
  std::vector<std::vector<size_t>> cols_;
  Eigen::VectorXd                  ref_, sum_;
  std::vector<Eigen::VectorXd>     checkpoints_; // sum of u_i - u_ref over records < c every
  std::vector<double>              e_;           // |u_i - u_ref|^2
  std::vector<double>              z_;           // Q^T (u_i - u_ref), Q_.cols() values per record
  Eigen::Map<const Eigen::VectorXd> Z(size_t i) const { return {z_.data() + i * (size_t)Q_.cols(), Q_.cols()}; }
};

} // namespace steady

struct SteadyStateResult {
  // The analysed records (rank 0): t, the signal DOF, the total normal reaction (empty: no contact).
  std::vector<PetscReal> t, x, rn;
  PetscInt               dof = -1, chunks = 0;
  PetscReal              T_ref = 0, periods = 0; // the starting mode's period, and the run's length in it
  steady::Analysis       signal;
  steady::Levels         normal; // over the same records as the signal's levels
  // The unstable modes' share (rank 0): stability's unstable indices, their frequency and growth
  // rate; `modal` empty with `modal_note` saying why (no unstable mode, no shapes, dependent shapes).
  std::vector<PetscInt>             mode_index;
  std::vector<PetscReal>            mode_frequency, mode_growth;
  steady::ModalProjection           projection;
  steady::ModalProjection::Result   modal;
  std::string                       modal_note;
  // Non-empty (rank 0) when the motion's base frequency lies above the stability band: the unstable
  // modes that carry it are then not among those projected on, and the note names the option.
  std::string                       band_note;
  bool                   converged = false, complete = false;
  std::string            interrupted; // non-empty: a signal stopped the run, and where
  // Memory (rank 0): per analysed record, the bytes of t, x, rn and the projection's values; and the
  // most the first chunk held of full states (displacements of every record, velocities of its
  // last 20 %) to find the signal DOF when -steady_dof is not given (0 when it is).
  size_t                 record_bytes = 0, first_chunk_state_bytes = 0;
  PetscReal              seconds = 0;
  std::string            start; // where the run started (the mode, or the pre-periods' end state)
  std::vector<PetscReal> U_end, dU_end; // the last chunk's end state, all N values on every rank
};

class SteadyState {
public:
  explicit SteadyState(MPI_Comm comm) : comm_(comm) {}
  ~SteadyState();
  SteadyState(const SteadyState &)            = delete;
  SteadyState &operator=(const SteadyState &) = delete;
  // -steady_rtol, -steady_batches, -steady_chunk_periods, -steady_max_periods, -steady_dof,
  // -steady_monitor [viewer], -steady_view [viewer] (after the run).
  PetscErrorCode SetFromOptions();
  // The transient (its own options, -transient_*) in chunks from (u0, du0), all N values on every
  // rank in the model's order (empty: the transient's own start, from the mode), until the
  // levels converge or max_periods of the starting mode have run. `start` says where from.
  PetscErrorCode Run(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, ThetaIntegrator &ti,
                     TransientAnalysis &transient, const std::vector<PetscReal> &u0, const std::vector<PetscReal> &du0,
                     const std::string &start, SteadyStateResult &res);
  // The statistics of res.t, res.x, res.rn (rank 0); broadcasts `converged`.
  PetscErrorCode Analyse(SteadyStateResult &res) const;
  PetscErrorCode View(const SteadyStateResult &res, PetscViewer viewer) const;
  PetscErrorCode ViewFromOptions(const SteadyStateResult &res) const;
  // /steady_state, with scripts/steady_state.py --write's names.
  PetscErrorCode Write(const SteadyStateResult &res, io::H5Writer &out) const;

  // max_periods 4000: the half-size brake at mu = 0.4, V = 5 m/s (full model) is broadband for its
  // first 1 660 periods and converges at 3 400; stopped at 1000 its levels were 30 % off (docs/steady-state.md).
  PetscReal rtol = 0.05, chunk_periods = 50, max_periods = 4000;
  PetscInt  batches = 20, dof = -1;
  // -steady_from_mode: after -analyses auto chose this route, start from the mode (as -analyses
  // steady) rather than the pre-periods' end state. Off since the energy estimate counts impact
  // losses: from the end state the small pad at V = 10 m/s converges in 650 periods (850 from the
  // mode) and the 2625-DOF pad at mu = 0.3 in 400 (not in 1000 from the mode), on the same motion.
  // It was on while the estimate put the start at 82 q_sep: that end state still fell by 18 %
  // after 1000 periods (docs/steady-state.md).
  PetscBool from_mode = PETSC_FALSE;

private:
  MPI_Comm    comm_;
  PetscViewer monitor_ = nullptr;
  PetscViewerFormat monitor_format_ = PETSC_VIEWER_DEFAULT;
};

} // namespace squeal
