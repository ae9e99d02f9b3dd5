#include "squeal/floquet/floquet.h"
#include "squeal/core/dense_blas.h"
#include "squeal/core/errors.h"
#include "squeal/core/inf.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/shooting/shooting.h"

#include <Eigen/Eigenvalues>
#include <petscblaslapack.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

namespace squeal {

namespace {
// Sorted by modulus; the one closest to 1 is the trivial one; `others` the largest of the rest.
void Classify(std::vector<std::complex<PetscReal>> &m, PetscInt &trivial, PetscReal &others)
{
  std::sort(m.begin(), m.end(), [](auto a, auto b) { return std::abs(a) > std::abs(b); });
  PetscReal best = kInf;
  others         = 0;
  for (size_t i = 0; i < m.size(); ++i)
    if (std::abs(m[i] - 1.0) < best) best = std::abs(m[i] - 1.0), trivial = (PetscInt)i;
  for (size_t i = 0; i < m.size(); ++i)
    if ((PetscInt)i != trivial) others = std::max(others, std::abs(m[i]));
}
} // namespace

namespace {
// The former names -shoot_floquet (the switch) and -shoot_floquet_* (the settings and the
// eigensolver's -shoot_floquet_eps_*), each renamed to its name under `prefix` with PETSc's
// deprecation warning, before the options are read under the new names.
PetscErrorCode RenameDeprecated(MPI_Comm comm, const std::string &prefix)
{
  const std::string old = "-shoot_floquet";
  char             *all = nullptr;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsGetAll(nullptr, &all));
  std::vector<std::string> names;
  for (const char *p = all; p && *p;) {
    while (*p == ' ') ++p;
    const char *e = p;
    while (*e && *e != ' ') ++e;
    const std::string tok(p, e);
    if (tok == old || tok.rfind(old + "_", 0) == 0) names.push_back(tok);
    p = e;
  }
  PetscCall(PetscFree(all));
  if (names.empty()) PetscFunctionReturn(0);
  PetscOptionsBegin(comm, nullptr, "Deprecated Floquet options", "FloquetSolver");
  for (const std::string &o : names) {
    const std::string n = "-" + prefix + (o == old ? std::string("compute") : o.substr(old.size() + 1));
    PetscCall(PetscOptionsDeprecated(o.c_str(), n.c_str(), "0.1.0", nullptr));
  }
  PetscOptionsEnd();
  PetscFunctionReturn(0);
}
} // namespace

PetscErrorCode FloquetSolver::SetFromOptions()
{
  const MPI_Comm comm = sh_.comm_;
  OptionChecks   checks;
  PetscFunctionBeginUser;
  PetscCall(RenameDeprecated(comm, prefix_));
  PetscOptionsBegin(comm, prefix_.c_str(), "Floquet multipliers of the limit cycle", "FloquetSolver");
  PetscCall(PetscOptionsBool("-compute", "Compute Floquet multipliers at convergence of shooting", "FloquetSolver", compute, &compute, nullptr));
  PetscCall(PetscOptionsInt("-dense_max", "Largest 2N for the dense monodromy (2N flows); above: SLEPc, matrix-free",
                            "FloquetSolver", dense_max, &dense_max, nullptr));
  PetscCall(PetscOptionsBool("-exact", "Monodromy from exact step tangents (dense theta back end; else finite differences)",
                             "FloquetSolver", exact, &exact, nullptr));
  PetscCall(PetscOptionsInt("-phases",
                            "Average the monodromy over this many starting points within one step of the orbit "
                            "(0: Gauss points on each piece where the contact statuses do not change, 1: none, K > 1: K midpoints; "
                            "default 0 for the dense monodromy, 1 for the matrix-free one)",
                            "FloquetSolver", phases, &phases, nullptr));
  SquealOptionsReal("-bisect_interp",
                    "Phase average: bisection intervals of the phase at most this wide start their flows from the mean of the "
                    "two ends' states before their first differing status change (0: every flow from the start of the period)",
                    "FloquetSolver", &bisect_interp, Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-nev", "Multipliers computed by the matrix-free route (its eigensolver: -floquet_eps_*)", "FloquetSolver",
                            nev, &nev, nullptr));
  PetscCall(PetscOptionsInt("-block",
                            "Matrix-free route on exact tangents: block Arnoldi with this many columns per tangent integration "
                            "(0: SLEPc Krylov-Schur, one column per integration)",
                            "FloquetSolver", block, &block, nullptr));
  PetscCall(PetscOptionsBool("-monitor", "Print the block Arnoldi's progress", "FloquetSolver", monitor, &monitor, nullptr));
  PetscCall(PetscOptionsInt("-max_dim", "Block Arnoldi: largest Krylov basis (columns)", "FloquetSolver", max_dim, &max_dim, nullptr));
  SquealOptionsReal("-max_dim_extend",
                    "Block Arnoldi: past -floquet_max_dim, go on up to this fraction more columns where the residuals, falling "
                    "geometrically as between the last two checks, reach the tolerance within them (0: a hard cap)",
                    "FloquetSolver", &max_dim_extend, Range::NonNegative(), checks);
  SquealOptionsReal("-tol", "Block Arnoldi: relative residual of the -floquet_nev largest multipliers", "FloquetSolver", &tol,
                    Range::Positive(), checks);
  SquealOptionsReal("-tol_error",
                    "Block Arnoldi: or this fraction of the trivial multiplier's distance from 1 (the step's own error on the "
                    "multipliers, the verdict's error bar), if larger than -floquet_tol, at most 1e-4 (0: -floquet_tol only)",
                    "FloquetSolver", &tol_error, Range::NonNegative(), checks);
  PetscOptionsEnd();
  PetscCall(checks.Run(comm));
  PetscCheck(phases == PETSC_DECIDE || phases >= 0, comm, kErrInput, "option -%sphases = %" PetscInt_FMT ": expected >= 0",
             prefix_.c_str(), phases);
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::View(const ShootingResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii || res.floquet.empty()) PetscFunctionReturn(0);
  std::string verdict = res.floquet_verdict == "undecided" ? "UNDECIDED" : res.stable_cycle ? "STABLE" : "UNSTABLE";
  char        why[160];
  std::snprintf(why, sizeof why, " (margin 1 - max |L| = %.2e %s error %.2e)", (double)res.floquet_margin,
                res.floquet_verdict == "undecided" ? "within the" : "beyond the", (double)res.floquet_error);
  PetscCall(PetscViewerASCIIPrintf(viewer, "Floquet multipliers (%s, %" PetscInt_FMT " phase(s) in one step): trivial one %.6f%+.6fi, |L - 1| = %.2e; cycle %s%s\n",
                                   res.floquet_method.c_str(), res.floquet_phases,
                                   res.floquet[res.trivial].real(), res.floquet[res.trivial].imag(),
                                   std::abs(res.floquet[res.trivial] - 1.0), verdict.c_str(), why));
  // A multiplier that far from 1 is not the trivial one, badly computed: that one is not among those
  // computed. Lightly damped structures put many multipliers just inside the unit circle (the half
  // brake's interface-reduced cycle: 4 of modulus 0.9997-0.9998 above it), so the largest few may
  // all be non-trivial.
  const bool missing = std::abs(res.floquet[res.trivial] - 1.0) > 0.1;
  if (missing)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "  WARNING: no multiplier within 0.1 of 1 among the %zu computed: the trivial one lies below them; "
                                     "raise -floquet_nev (and -floquet_max_dim, until block Arnoldi converges) before trusting the verdict\n",
                                     res.floquet.size()));
  else if (res.floquet_verdict == "undecided")
    PetscCall(PetscViewerASCIIPrintf(viewer, "  the multipliers' error is as large as the margin: refine -shoot_steps (the trivial "
                                             "multiplier's distance from 1 falls with the step) before trusting the verdict; "
                                             "-shoot_start with this run's results file starts Newton from this cycle\n"));
  for (size_t i = 0; i < res.floquet.size() && i < 8; ++i)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  %2zu  %+.6f %+.6fi  |L| = %.6f%s\n", i, res.floquet[i].real(), res.floquet[i].imag(),
                                     std::abs(res.floquet[i]), (PetscInt)i == res.trivial ? "  (trivial)" : ""));
  if (!res.floquet_at_z0.empty()) {
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "  without the phase average (Jacobian at Z0): largest non-trivial |L| = %.6f, trivial |L - 1| = %.2e\n",
                                     res.largest_at_z0, std::abs(res.floquet_at_z0[res.trivial_at_z0] - 1.0)));
    if ((res.largest_at_z0 < 1) != res.stable_cycle)
      PetscCall(PetscViewerASCIIPrintf(viewer, "  WARNING: the two verdicts differ: the stability of this cycle depends on where the "
                                               "status changes fall in their steps; refine -shoot_steps\n"));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::Compute(Vec U0, Vec dU0, PetscReal T, ShootingResult &res)
{
  PetscInt N;
  PetscFunctionBeginUser;
  PetscCall(VecGetSize(U0, &N));
  if (2 * N <= dense_max) {
    Eigen::MatrixXd Mono;
    const bool      tangents = exact && sh_.ti_->Dense();
    if (exact && !sh_.ti_->Dense())
      PetscCall(PetscPrintf(sh_.comm_, "shooting: exact monodromy needs the dense theta back end (N <= -theta_dense_max); "
                                       "using finite differences\n"));
    res.floquet_method = tangents ? "exact step tangents" : "finite differences";

    if (tangents) PetscCall(MonodromyExact(U0, dU0, T, phases, Mono));
    else PetscCall(Monodromy(U0, dU0, T, phases, Mono));
    res.floquet_phases = (PetscInt)phase_s_.size();
    Eigen::EigenSolver<Eigen::MatrixXd> es(Mono, false);
    for (Eigen::Index i = 0; i < es.eigenvalues().size(); ++i) res.floquet.push_back(es.eigenvalues()(i));
    if (res.floquet_phases > 1) {
      // The discrete map's own Jacobian at Z0 as well: where the two disagree on stability, the
      // step is too coarse for the verdict.
      if (tangents) PetscCall(MonodromyExact(U0, dU0, T, 1, Mono));
      else PetscCall(Monodromy(U0, dU0, T, 1, Mono));
      Eigen::EigenSolver<Eigen::MatrixXd> e0(Mono, false);
      for (Eigen::Index i = 0; i < e0.eigenvalues().size(); ++i) res.floquet_at_z0.push_back(e0.eigenvalues()(i));
    }
  } else {
    PetscCall(MatrixFree(U0, dU0, T, res.floquet));
    res.floquet_method = !mono_exact_ ? "SLEPc, matrix-free finite differences"
                         : block > 0  ? "block Arnoldi on exact step tangents"
                                      : "SLEPc, matrix-free exact step tangents";
    res.floquet_phases = (PetscInt)phase_s_.size();
  }
  PetscReal others = 0;
  if (!res.floquet.empty()) {
    Classify(res.floquet, res.trivial, others);
    res.stable_cycle = others < 1;
  }
  if (!res.floquet_at_z0.empty()) Classify(res.floquet_at_z0, res.trivial_at_z0, res.largest_at_z0);
  if (!res.floquet.empty()) {
    const FloquetVerdictResult v = FloquetVerdict(others, std::abs(res.floquet[res.trivial] - 1.0),
                                                  res.floquet_at_z0.empty() ? 0.0 : std::abs(res.largest_at_z0 - others));
    res.floquet_verdict = v.word;
    res.floquet_margin  = v.margin;
    res.floquet_error   = v.error;
  }
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::Monodromy(Vec U0, Vec dU0, PetscReal T, PetscInt phases, Eigen::MatrixXd &Mono)
{
  PetscInt    N, lo, hi;
  PetscReal   nU, ndU;
  PetscMPIInt rank;
  Shooting   &s = sh_;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(s.comm_, &rank));
  PetscCall(VecGetSize(U0, &N));
  PetscCall(VecGetOwnershipRange(U0, &lo, &hi));
  PetscCall(VecNorm(U0, NORM_2, &nU));
  PetscCall(VecNorm(dU0, NORM_2, &ndU));
  VecH bU, bdU;
  PetscCall(VecDuplicate(U0, bU.out()));
  PetscCall(VecDuplicate(U0, bdU.out()));
  Mono.setZero(2 * N, 2 * N);
  AllGather gather;
  PetscCall(gather.SetUp(U0));
  Eigen::VectorXd base(2 * N), col(2 * N);
  PetscCall(SetUpPhases(U0, dU0, T, phases, true));
  for (size_t k = 0; k < phase_s_.size(); ++k) {
    PetscCall(PhaseStart(U0, dU0, phase_s_[k], bU, bdU));
    PetscCall(s.Flow(bU, bdU, T, s.U1_, s.dU1_));
    PetscCall(gather(s.U1_, base.head(N)));
    PetscCall(gather(s.dU1_, base.tail(N)));
    for (PetscInt j = 0; j < 2 * N; ++j) {
      const bool     disp = j < N;
      const PetscInt i    = disp ? j : j - N;
      // Forward (+delta) steps: a closed point pushed into the surface is projected back at once.
      const PetscReal delta = s.fd_step * (disp ? (nU > 0 ? nU : 1.0) : (ndU > 0 ? ndU : 1.0));
      PetscCall(VecCopy(bU, s.U_));
      PetscCall(VecCopy(bdU, s.dU_));
      if (i >= lo && i < hi) PetscCall(VecSetValue(disp ? s.U_ : s.dU_, i, delta, ADD_VALUES));
      PetscCall(VecAssemblyBegin(disp ? s.U_ : s.dU_));
      PetscCall(VecAssemblyEnd(disp ? s.U_ : s.dU_));
      PetscCall(s.Flow(s.U_, s.dU_, T, s.U1_, s.dU1_));
      PetscCall(gather(s.U1_, col.head(N)));
      PetscCall(gather(s.dU1_, col.tail(N)));
      Mono.col(j) += phase_w_[k] * (col - base) / delta;
    }
  }
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::MonodromyExact(Vec U0, Vec dU0, PetscReal T, PetscInt phases, Eigen::MatrixXd &Mono)
{
  PetscInt        N;
  Eigen::VectorXd r, vloc;
  StepInfo        info;
  Shooting       &s  = sh_;
  ThetaIntegrator &ti = *s.ti_;
  PetscFunctionBeginUser;
  PetscCall(VecGetSize(U0, &N));
  PetscCheck(ti.Dense(), s.comm_, PETSC_ERR_SUP, "the exact monodromy needs the dense theta back end (N <= -theta_dense_max)");
  PetscCall(SetUpPhases(U0, dU0, T, phases, true));
  Mono.setZero(2 * N, 2 * N);
  Eigen::MatrixXd dU, ddU;
  for (size_t k = 0; k < phase_s_.size(); ++k) {
    PetscCall(PhaseStart(U0, dU0, phase_s_[k], s.U1_, s.dU1_));
    r = s.r_init_;
    dU.setZero(N, 2 * N), ddU.setZero(N, 2 * N);
    dU.leftCols(N).setIdentity();
    ddU.rightCols(N).setIdentity();
    // 2N tangent columns a step (3.4 ms a step on the reduced small pad, 26 s for its 15 phases);
    // the dense back end is replicated, so every rank polls here.
    InterruptPacer pacer(s.comm_, "the Floquet monodromy");
    for (PetscInt i = 0; i < s.steps; ++i) {
      if (s.interruptible) PetscCall(pacer.Step());
      PetscCall(ti.Step(s.U1_, s.dU1_, r, &info));
      if (r.size()) PetscCall(ti.Local(s.dU1_, vloc));
      PetscCall(ti.StepTangent(r, vloc, dU, ddU));
    }
    Mono.topRows(N) += phase_w_[k] * dU;
    Mono.bottomRows(N) += phase_w_[k] * ddU;
    s.CountSteps(s.steps);
  }
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::ShiftAlongOrbit(Vec U0, Vec dU0, PetscReal T)
{
  Eigen::VectorXd r = sh_.r_init_;
  StepInfo        info;
  PetscFunctionBeginUser;
  PetscCall(sh_.SetUpAt(T));
  if (!shiftU_) {
    PetscCall(VecDuplicate(U0, shiftU_.out()));
    PetscCall(VecDuplicate(U0, shiftdU_.out()));
  }
  PetscCall(VecCopy(U0, shiftU_));
  PetscCall(VecCopy(dU0, shiftdU_));
  PetscCall(sh_.ti_->Step(shiftU_, shiftdU_, r, &info));
  PetscCall(VecAXPY(shiftU_, -1.0, U0));
  PetscCall(VecAXPY(shiftdU_, -1.0, dU0));
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::PhaseStart(Vec U0, Vec dU0, PetscReal s, Vec U, Vec dU)
{
  PetscFunctionBeginUser;
  PetscCall(VecWAXPY(U, s, shiftU_, U0));
  PetscCall(VecWAXPY(dU, s, shiftdU_, dU0));
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::SetUpPhases(Vec U0, Vec dU0, PetscReal T, PetscInt K, bool adaptive_default)
{
  PetscFunctionBeginUser;
  PetscCall(ShiftAlongOrbit(U0, dU0, T));
  phase_s_.clear(), phase_w_.clear();
  if (K == PETSC_DECIDE) K = adaptive_default ? 0 : 1;
  if (K == 1) {
    phase_s_ = {0.0}, phase_w_ = {1.0};
    PetscFunctionReturn(0);
  }
  if (K >= 2) { // midpoint rule
    for (PetscInt k = 0; k < K; ++k) phase_s_.push_back((k + 0.5) / K), phase_w_.push_back(1.0 / K);
    PetscFunctionReturn(0);
  }
  // K = 0: the phase s in [0, 1] moves every status change of the flow by one step. Between the
  // values of s where one moves, the flow is smooth in s: find them (PhaseBreaks), then 3-point
  // Gauss-Legendre on each smooth piece.
  std::vector<PetscReal> breaks;
  PetscCall(PhaseBreaks(U0, dU0, T, breaks));
  if (breaks.size() > 64) {
    // Too many status changes to resolve one by one (large contact sets): 64 midpoints.
    PetscCall(PetscInfo(nullptr, "%zu status changes move with the phase: midpoint rule over 64 phases\n", breaks.size()));
    for (PetscInt k = 0; k < 64; ++k) phase_s_.push_back((k + 0.5) / 64), phase_w_.push_back(1.0 / 64);
    PetscFunctionReturn(0);
  }
  std::sort(breaks.begin(), breaks.end());
  for (PetscReal b : breaks) PetscCall(PetscInfo(nullptr, "shooting: a status change moves to another step at phase s = %.9f\n", (double)b));
  std::vector<PetscReal> ends{0.0};
  for (PetscReal b : breaks) ends.push_back(b);
  ends.push_back(1.0);
  const PetscReal x[3] = {-std::sqrt(0.6), 0.0, std::sqrt(0.6)}, w[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  for (size_t p = 0; p + 1 < ends.size(); ++p) {
    const PetscReal a = ends[p], b = ends[p + 1];
    if (b - a < 1e-8) continue;
    for (int q = 0; q < 3; ++q) phase_s_.push_back(0.5 * (a + b) + 0.5 * (b - a) * x[q]), phase_w_.push_back(0.5 * (b - a) * w[q]);
  }
  PetscFunctionReturn(0);
}

// The search for the phases where a status change moves to another step, by bisection on the list
// of transitions. A probe is the flow from Z0 + s d with its transitions and, over the steps it
// ran, its states and the reactions entering each step. Two probes a < b whose transitions agree
// before step j0 have states at j0 that are smooth in s on [a, b]: once b - a <=
// -floquet_bisect_interp (W), the flow from the midpoint starts at j0 from the mean of theirs
// and stops after the last differing transition, so a bisection level costs the steps between the
// two, not a period. All deeper probes are then linear interpolants along the first such [a, b]:
// state error O(W^2). Measured (3-DOF cases, planar and rectilinear, 500-4000 steps): the same
// pieces as flows from t = 0 at W = 1/32 and 1/16; at W = 1/4 a stick onset moved by 7.6e-6 of a step.
class FloquetSolver::PhaseBisection {
public:
  struct Probe {
    std::vector<PetscInt> sig;    // (step, point, new status) of every transition
    PetscInt              lo = 0; // column k of Z (this rank's rows of U, dU) and R (reaction entering the step) is step lo + k
    Eigen::MatrixXd       Z, R;
    std::vector<int>      st_lo; // statuses entering step lo (R's first column may be a mean, not a status)
  };
  std::vector<PetscReal> breaks;

  PhaseBisection(FloquetSolver &f, Vec U0, Vec dU0, PetscReal T) : f_(f), s_(f.sh_), ti_(*f.sh_.ti_), U0_(U0), dU0_(dU0), T_(T) {}
  PetscErrorCode SetUp()
  {
    PetscInt lo, hi;
    PetscFunctionBeginUser;
    nc_ = s_.model_->contacts.Size();
    for (VecH *v : {&sU_, &sdU_}) PetscCall(VecDuplicate(U0_, v->out()));
    PetscCall(VecGetOwnershipRange(U0_, &lo, &hi));
    lo_ = lo, nl_ = hi - lo; // states are kept by rows, on their rank: no gathers per step
    ti_.Contact().Status(s_.r_init_, st0_); // ShiftAlongOrbit has set the integrator up at T
    PetscFunctionReturn(0);
  }
  // s = 0 is the flow of the last residual evaluation when that was at (Z0, T): reuse it.
  PetscErrorCode FromStoredFlow(Probe &P, bool *have)
  {
    const PetscInt steps = s_.steps;
    PetscFunctionBeginUser;
    *have = false;
    if (!(s_.tr_valid_ && s_.trT_ == T_ && s_.trU_.cols() == steps + 1 && s_.trR_.rows() == 3 * nc_)) PetscFunctionReturn(0);
    PetscCall(s_.Pack(U0_, dU0_, T_, s_.xp_));
    PetscBool same;
    PetscCall(VecEqual(s_.xp_, s_.trx_, &same));
    if (!same) PetscFunctionReturn(0);
    P.lo = 0;
    P.Z.resize(2 * nl_, steps + 1), P.R.resize(3 * nc_, steps + 1);
    P.Z.topRows(nl_) = s_.trU_.middleRows(lo_, nl_), P.Z.bottomRows(nl_) = s_.trdU_.middleRows(lo_, nl_);
    P.R.col(0) = s_.r_init_;
    if (nc_) P.R.rightCols(steps) = s_.trR_;
    P.st_lo = prev_ = st0_;
    for (PetscInt i = 0; i < steps; ++i) {
      ti_.Contact().Status(P.R.col(i + 1), cur_);
      for (size_t c = 0; c < cur_.size(); ++c)
        if (cur_[c] != prev_[c]) P.sig.insert(P.sig.end(), {i, (PetscInt)c, (PetscInt)cur_[c]});
      std::swap(prev_, cur_);
    }
    *have = true;
    PetscFunctionReturn(0);
  }
  // The probe at s: flow from Z0 + s d over steps [0, j1).
  PetscErrorCode Exact(Probe &P, PetscReal s, PetscInt j1)
  {
    Eigen::VectorXd z(2 * nl_);
    PetscFunctionBeginUser;
    PetscCall(f_.PhaseStart(U0_, dU0_, s, sU_, sdU_));
    PetscCall(GetState(z));
    P.sig.clear();
    PetscCall(Run(P, 0, j1, z, s_.r_init_, st0_));
    PetscFunctionReturn(0);
  }
  // Adds to `breaks` the phases in (a, b) where the transitions of pa and pb part.
  PetscErrorCode Bisect(PetscReal a, PetscReal b, const Probe &pa, const Probe &pb)
  {
    PetscFunctionBeginUser;
    if (b - a < 1e-5 || breaks.size() > 64) {
      breaks.push_back(0.5 * (a + b));
      PetscFunctionReturn(0);
    }
    const std::vector<PetscInt> &sa = pa.sig, &sb = pb.sig;
    const PetscReal              m  = 0.5 * (a + b);
    // sa and sb agree before step `first` and after their last differing transition (step `last`).
    size_t ka = sa.size(), kb = sb.size(), p = 0;
    while (ka >= 3 && kb >= 3 && std::equal(sa.begin() + ka - 3, sa.begin() + ka, sb.begin() + kb - 3)) ka -= 3, kb -= 3;
    while (p + 3 <= ka && p + 3 <= kb && std::equal(sa.begin() + p, sa.begin() + p + 3, sb.begin() + p)) p += 3;
    PetscInt last = -1, first = s_.steps;
    for (size_t j = p; j < ka; j += 3) last = std::max(last, sa[j]), first = std::min(first, sa[j]);
    for (size_t j = p; j < kb; j += 3) last = std::max(last, sb[j]), first = std::min(first, sb[j]);
    Probe      pm;
    const auto has = [](const Probe &q, PetscInt j) { return j >= q.lo && j < q.lo + q.Z.cols(); };
    if (b - a <= f_.bisect_interp && has(pa, first) && has(pb, first)) {
      for (size_t j = 0; j < p; j += 3)
        if (sa[j] < first) pm.sig.insert(pm.sig.end(), sa.begin() + j, sa.begin() + j + 3);
      const Eigen::VectorXd z  = 0.5 * (pa.Z.col(first - pa.lo) + pb.Z.col(first - pb.lo));
      const Eigen::VectorXd r0 = pa.R.col(first - pa.lo); // a warm start only
      std::vector<int>      st = pa.st_lo;
      if (first > pa.lo) ti_.Contact().Status(r0, st);
      PetscCall(Run(pm, first, last + 1, z, r0, st));
    } else PetscCall(Exact(pm, m, last + 1));
    // The flow from m takes the common tail.
    for (size_t j = 0; j < sa.size(); j += 3)
      if (sa[j] > last) pm.sig.insert(pm.sig.end(), sa.begin() + j, sa.begin() + j + 3);
    if (pm.sig != sa) PetscCall(Bisect(a, m, pa, pm));
    if (pm.sig != sb) PetscCall(Bisect(m, b, pm, pb));
    PetscFunctionReturn(0);
  }

private:
  FloquetSolver    &f_;
  Shooting         &s_;
  ThetaIntegrator  &ti_;
  Vec               U0_, dU0_;
  PetscReal         T_;
  PetscInt          nc_ = 0, lo_ = 0, nl_ = 0;
  VecH              sU_, sdU_;
  StepInfo          info_;
  std::vector<int>  st0_, prev_, cur_;

  PetscErrorCode SetState(const Eigen::VectorXd &z)
  {
    PetscScalar *u, *du;
    PetscFunctionBeginUser;
    PetscCall(VecGetArray(sU_, &u));
    PetscCall(VecGetArray(sdU_, &du));
    for (PetscInt i = 0; i < nl_; ++i) u[i] = z[i], du[i] = z[nl_ + i];
    PetscCall(VecRestoreArray(sdU_, &du));
    PetscCall(VecRestoreArray(sU_, &u));
    PetscFunctionReturn(0);
  }
  PetscErrorCode GetState(Eigen::Ref<Eigen::VectorXd> z)
  {
    const PetscScalar *u, *du;
    PetscFunctionBeginUser;
    PetscCall(VecGetArrayRead(sU_, &u));
    PetscCall(VecGetArrayRead(sdU_, &du));
    for (PetscInt i = 0; i < nl_; ++i) z[i] = PetscRealPart(u[i]), z[nl_ + i] = PetscRealPart(du[i]);
    PetscCall(VecRestoreArrayRead(sdU_, &du));
    PetscCall(VecRestoreArrayRead(sU_, &u));
    PetscFunctionReturn(0);
  }
  // Steps [j0, j1) from state z before step j0, warm start r0, statuses st before it; transitions appended to P.sig.
  PetscErrorCode Run(Probe &P, PetscInt j0, PetscInt j1, const Eigen::VectorXd &z, const Eigen::VectorXd &r0, const std::vector<int> &st)
  {
    PetscFunctionBeginUser;
    P.lo = j0;
    P.Z.resize(2 * nl_, j1 - j0 + 1), P.R.resize(3 * nc_, j1 - j0 + 1);
    P.Z.col(0) = z, P.R.col(0) = r0, P.st_lo = st;
    PetscCall(SetState(z));
    Eigen::VectorXd r = r0;
    prev_             = st;
    for (PetscInt i = j0; i < j1; ++i) {
      PetscCall(ti_.Step(sU_, sdU_, r, &info_));
      PetscCheck(r.size() == 0 || !std::isnan(info_.contact.residual), s_.comm_, PETSC_ERR_FP,
                 "shooting: NaN in the flow at step %" PetscInt_FMT " of %" PetscInt_FMT " (T = %g s)", i + 1, s_.steps, (double)T_);
      PetscCall(GetState(P.Z.col(i - j0 + 1)));
      P.R.col(i - j0 + 1) = r;
      ti_.Contact().Status(r, cur_);
      for (size_t c = 0; c < cur_.size(); ++c)
        if (cur_[c] != prev_[c]) P.sig.insert(P.sig.end(), {i, (PetscInt)c, (PetscInt)cur_[c]});
      std::swap(prev_, cur_);
    }
    s_.CountSteps(j1 - j0);
    PetscFunctionReturn(0);
  }
};

PetscErrorCode FloquetSolver::PhaseBreaks(Vec U0, Vec dU0, PetscReal T, std::vector<PetscReal> &breaks)
{
  using Probe = PhaseBisection::Probe;
  PhaseBisection search(*this, U0, dU0, T);
  PetscFunctionBeginUser;
  PetscCall(search.SetUp());
  // Probes on a grid of G + 1 phases, then bisection between neighbours whose transitions differ.
  const PetscInt     G = 4;
  std::vector<Probe> grid(G + 1);
  bool               have0 = false;
  PetscCall(search.FromStoredFlow(grid[0], &have0));
  for (PetscInt j = have0 ? 1 : 0; j <= G; ++j) PetscCall(search.Exact(grid[j], (PetscReal)j / G, sh_.steps));
  for (PetscInt j = 0; j < G; ++j)
    if (grid[j].sig != grid[j + 1].sig) PetscCall(search.Bisect((PetscReal)j / G, (PetscReal)(j + 1) / G, grid[j], grid[j + 1]));
  breaks = std::move(search.breaks);
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::MonodromyMult(Mat A, Vec v, Vec y)
{
  FloquetSolver *f;
  PetscFunctionBeginUser;
  PetscCall(MatShellGetContext(A, &f));
  Shooting *s = &f->sh_;
  if (f->mono_exact_) {
    // The exact tangent along the stored flow from Z0: no difference noise, no extra factorisation.
    const PetscInt     N = s->N_;
    Eigen::MatrixXd    dZ0(2 * N, 1), dZ1;
    Eigen::VectorXd    part(N), out(2 * N + 1);
    Eigen::RowVectorXd dT = Eigen::RowVectorXd::Zero(1);
    PetscCall(s->Unpack(v, s->wU_, s->wdU_, nullptr));
    PetscCall(s->Full(s->wU_, part));
    dZ0.col(0).head(N) = part;
    PetscCall(s->Full(s->wdU_, part));
    dZ0.col(0).tail(N) = part;
    PetscCall(s->TangentFlow(f->mono_x_, dZ0, dT, dZ1));
    out.head(2 * N) = dZ1.col(0);
    out[2 * N]      = 0;
    PetscCall(s->FromNatural(out, y));
    PetscFunctionReturn(0);
  }
  // Forward differences of the flow, displacement and velocity parts of v perturbed separately
  // with steps scaled by ||U0|| and ||dU0||, as the dense columns are: one scale for both would
  // shift impacts by far more than the displacements allow.
  PetscCall(VecZeroEntries(s->aU_));
  PetscCall(VecZeroEntries(s->adU_));
  const PetscInt K = (PetscInt)f->mono_start_.size();
  for (PetscInt k = 0; k < K; ++k) {
    const auto &st = f->mono_start_[k];
    const auto &bs = f->mono_base_[k];
    for (int part = 0; part < 2; ++part) {
      PetscReal nv, nz;
      PetscCall(s->Unpack(v, s->wU_, s->wdU_, nullptr));
      Vec moved = part == 0 ? s->wU_ : s->wdU_, fixed = part == 0 ? s->wdU_ : s->wU_;
      PetscCall(VecNorm(moved, NORM_2, &nv));
      if (nv == 0) continue;
      PetscCall(VecNorm(part == 0 ? f->mono_U0_ : f->mono_dU0_, NORM_2, &nz));
      const PetscReal eps = s->fd_step * (nz > 0 ? nz : 1.0) / nv;
      PetscCall(VecZeroEntries(fixed));
      PetscCall(VecAYPX(s->wU_, eps, st.first));
      PetscCall(VecAYPX(s->wdU_, eps, st.second));
      PetscCall(s->Flow(s->wU_, s->wdU_, f->mono_T_, s->U1_, s->dU1_));
      PetscCall(VecAXPY(s->U1_, -1.0, bs.first));
      PetscCall(VecAXPY(s->dU1_, -1.0, bs.second));
      PetscCall(VecAXPY(s->aU_, f->phase_w_[k] / eps, s->U1_));
      PetscCall(VecAXPY(s->adU_, f->phase_w_[k] / eps, s->dU1_));
    }
  }
  PetscCall(s->Pack(s->aU_, s->adU_, 0.0, y));
  PetscFunctionReturn(0);
}

PetscErrorCode FloquetSolver::MatrixFree(Vec U0, Vec dU0, PetscReal T, std::vector<std::complex<PetscReal>> &mult)
{
  PetscInt  N, nconv;
  MatH      A;
  EPSH      eps;
  VecH      z;
  Shooting &s = sh_;
  PetscFunctionBeginUser;
  PetscCall(VecGetSize(U0, &N));
  for (VecH *v : {&mono_U0_, &mono_dU0_}) PetscCall(VecDuplicate(U0, v->out()));
  PetscCall(VecCopy(U0, mono_U0_));
  PetscCall(VecCopy(dU0, mono_dU0_));
  mono_T_ = T;
  // Starting points within one step of the orbit, and their flows (the bases of the differences).
  PetscCall(SetUpPhases(U0, dU0, T, phases, false));
  const size_t K = phase_s_.size();
  mono_start_.clear(), mono_base_.clear();
  mono_start_.resize(K), mono_base_.resize(K);
  for (size_t k = 0; k < K; ++k) {
    for (VecH *v : {&mono_start_[k].first, &mono_start_[k].second, &mono_base_[k].first, &mono_base_[k].second})
      PetscCall(VecDuplicate(U0, v->out()));
    PetscCall(PhaseStart(U0, dU0, phase_s_[k], mono_start_[k].first, mono_start_[k].second));
    PetscCall(s.Flow(mono_start_[k].first, mono_start_[k].second, T, mono_base_[k].first, mono_base_[k].second));
  }
  // One phase on the dense back end: exact tangent products along the flow from Z0.
  mono_exact_ = exact && s.ExactJacobian() && K == 1 && phase_s_[0] == 0;
  if (mono_exact_) {
    if (!mono_x_) PetscCall(s.CreateState(mono_x_.out()));
    PetscCall(s.Pack(U0, dU0, T, mono_x_));
  }
  if (mono_exact_ && block > 0) {
    PetscCall(BlockArnoldi(mult));
    PetscFunctionReturn(0);
  }
  // Z-space vectors: the shooting packing without T.
  PetscCall(VecCreateMPI(s.comm_, 2 * s.nloc_, PETSC_DETERMINE, z.out()));
  PetscCall(MatCreateShell(s.comm_, 2 * s.nloc_, 2 * s.nloc_, 2 * N, 2 * N, this, A.out()));
  PetscCall(MatShellSetOperation(A, MATOP_MULT, (void (*)(void))MonodromyMult));
  PetscCall(EPSCreate(s.comm_, eps.out()));
  PetscCall(EPSSetOptionsPrefix(eps, prefix_.c_str()));
  PetscCall(EPSSetOperators(eps, A, nullptr));
  PetscCall(EPSSetProblemType(eps, EPS_NHEP));
  PetscCall(EPSSetType(eps, EPSKRYLOVSCHUR));
  PetscCall(EPSSetWhichEigenpairs(eps, EPS_LARGEST_MAGNITUDE));
  PetscCall(EPSSetDimensions(eps, PetscMin(nev, 2 * N - 2), PETSC_DEFAULT, PETSC_DEFAULT));
  // Difference products carry ~fd_step relative noise: ask for no more than that allows.
  PetscCall(EPSSetTolerances(eps, mono_exact_ ? 1e-8 : 1e-6, 200));
  PetscCall(EPSSetFromOptions(eps));
  PetscCall(EPSMonitorSet(
    eps,
    [](EPS e, PetscInt, PetscInt, PetscScalar *, PetscScalar *, PetscReal *, PetscInt, void *ctx) -> PetscErrorCode {
      return *static_cast<const bool *>(ctx) ? InterruptPoint(PetscObjectComm((PetscObject)e), "the Floquet eigensolve") : 0;
    },
    (void *)&s.interruptible, nullptr));
  PetscCall(EPSSolve(eps));
  PetscCall(EPSGetConverged(eps, &nconv));
  mult.clear();
  for (PetscInt i = 0; i < nconv; ++i) {
    PetscScalar kr, ki;
    PetscCall(EPSGetEigenvalue(eps, i, &kr, &ki));
    mult.emplace_back(PetscRealPart(kr), PetscRealPart(ki));
  }
  PetscFunctionReturn(0);
}

namespace {
// The nev Ritz values of largest modulus of the k x k block Hessenberg matrix Hk, and the worst
// relative residual |R y_last| / |theta| of their Ritz vectors (y of unit norm, y_last its last b
// entries). LAPACK's dgeev, not Eigen's EigenSolver: this is solved after every block, and on the
// 562-DOF pad's 29 blocks (k up to 464) Eigen took 2.5 times as long.
PetscLogEvent ev_ritz = 0; // -log_view: the Ritz values of every block (the rest of ShootFloquet is the tangent flows)

PetscErrorCode LargestRitz(const Eigen::MatrixXd &Hk, const Eigen::MatrixXd &R, Eigen::Index nev,
                           std::vector<std::complex<PetscReal>> &ritz, PetscReal &worst)
{
  using Eigen::Index;
  const Index     k = Hk.rows(), b = R.rows();
  Eigen::MatrixXd A = Hk, VR(k, k);
  std::vector<PetscReal> wr(k), wi(k), work(1);
  PetscBLASInt           n, lwork = -1, info = 0, one = 1;
  PetscReal              vl = 0;
  PetscFunctionBeginUser;
  if (!ev_ritz) PetscCall(PetscLogEventRegister("ShootFloquetRitz", SNES_CLASSID, &ev_ritz));
  PetscCall(PetscLogEventBegin(ev_ritz, 0, 0, 0, 0));
  PetscCall(PetscBLASIntCast(k, &n));
  PetscCallBLAS("LAPACKgeev", LAPACKgeev_("N", "V", &n, A.data(), &n, wr.data(), wi.data(), &vl, &one, VR.data(), &n, work.data(), &lwork, &info));
  PetscCall(PetscBLASIntCast((PetscInt)work[0], &lwork));
  work.resize((size_t)lwork);
  PetscCallBLAS("LAPACKgeev", LAPACKgeev_("N", "V", &n, A.data(), &n, wr.data(), wi.data(), &vl, &one, VR.data(), &n, work.data(), &lwork, &info));
  PetscCheck(info == 0, PETSC_COMM_SELF, PETSC_ERR_LIB, "Floquet block Arnoldi: LAPACK dgeev failed on the %d x %d Hessenberg matrix (info %d)",
             (int)k, (int)k, (int)info);
  std::vector<Index> order(k);
  for (Index i = 0; i < k; ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](Index a, Index c) { return std::hypot(wr[a], wi[a]) > std::hypot(wr[c], wi[c]); });
  ritz.clear();
  worst = 0;
  for (Index i = 0; i < std::min(nev, k); ++i) {
    const Index                   j = order[i];
    const std::complex<PetscReal> th(wr[j], wi[j]);
    // dgeev stores a complex pair's vector as two real columns, re in the first of the pair.
    Eigen::VectorXd yr = VR.col(j), yi = Eigen::VectorXd::Zero(k);
    if (wi[j] > 0) yi = VR.col(j + 1);
    else if (wi[j] < 0) yr = VR.col(j - 1), yi = -VR.col(j);
    const PetscReal nrm = std::sqrt(yr.squaredNorm() + yi.squaredNorm());
    const PetscReal res = std::sqrt((R * yr.tail(b)).squaredNorm() + (R * yi.tail(b)).squaredNorm()) / nrm;
    worst               = std::max(worst, res / std::max(std::abs(th), PETSC_SMALL));
    ritz.push_back(th);
  }
  PetscCall(PetscLogEventEnd(ev_ritz, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}
} // namespace

PetscErrorCode FloquetSolver::BlockArnoldi(std::vector<std::complex<PetscReal>> &mult)
{
  using Eigen::Index;
  using Eigen::MatrixXd;
  Shooting   &s = sh_;
  const Index N = s.N_, n = 2 * N, b = block;
  const Index nev = std::min<Index>(this->nev, n - 2);
  const bool  mon = monitor;
  PetscFunctionBeginUser;
  if (n <= 4 * b) {
    // A few blocks would span the space: the whole monodromy in one integration of n columns.
    MatrixXd Mono;
    PetscCall(s.TangentFlow(mono_x_, MatrixXd::Identity(n, n), Eigen::RowVectorXd::Zero(n), Mono));
    Eigen::EigenSolver<MatrixXd> es(Mono, false);
    mult.clear();
    for (Index i = 0; i < n; ++i) mult.push_back(es.eigenvalues()(i));
    std::sort(mult.begin(), mult.end(), [](auto a, auto c) { return std::abs(a) > std::abs(c); });
    mult.resize(nev);
    products_ = 1;
    PetscFunctionReturn(0);
  }
  // Blocks of the Krylov basis: up to -floquet_max_dim columns, and never past the space; past the
  // cap up to mext blocks only where the residuals are about to reach the tolerance.
  const Index mmax = std::max<Index>(1, std::min<Index>(max_dim / b, n / b - 1));
  const Index mext = std::max(mmax, std::min<Index>((Index)std::floor((1 + max_dim_extend) * (PetscReal)max_dim / (PetscReal)b), n / b - 1));
  Index       mlimit = mmax;
  MatrixXd    V(n, (mext + 1) * b), H = MatrixXd::Zero((mext + 1) * b, mext * b), W, C;
  {
    // The same pseudo-random start on every rank (every rank holds the whole basis).
    std::mt19937                     gen(2027);
    std::normal_distribution<double> nd;
    MatrixXd                         R0(n, b);
    for (Index j = 0; j < b; ++j)
      for (Index i = 0; i < n; ++i) R0(i, j) = nd(gen);
    Eigen::HouseholderQR<MatrixXd> qr(R0);
    V.leftCols(b) = qr.householderQ() * MatrixXd::Identity(n, b);
  }
  const Eigen::RowVectorXd dT = Eigen::RowVectorXd::Zero(b);
  const PetscReal          w  = 2 * PETSC_PI / mono_T_;
  std::vector<std::complex<PetscReal>> ritz;
  PetscInt                             used = 0;
  Index                                last_check = 0, prev_check = 0, next_check = 1; // in blocks
  PetscReal                            stop = tol, last_worst = 0, prev_worst = 0;
  for (Index j = 0; j < mlimit; ++j) {
    // On D M D^-1, D = diag(w I, I), w = 2 pi / T: same multipliers, but displacement and velocity
    // columns of one size (M itself mixes them by factors of w ~ 1e3-1e5), which is far closer to
    // normal, and Arnoldi's residuals then mean what they say.
    C = V.middleCols(j * b, b);
    C.topRows(N) /= w;
    PetscCall(s.TangentFlow(mono_x_, C, dT, W));
    W.topRows(N) *= w;
    ++used;
    const Index k = (j + 1) * b;
    // Block Gram-Schmidt, twice (one pass loses orthogonality on the clustered multipliers).
    for (int pass = 0; pass < 2; ++pass) {
      C.resize(k, b);
      Gemm(V.leftCols(k), true, W, C);
      Gemm(V.leftCols(k), false, C, W, -1.0, 1.0);
      H.block(0, j * b, k, b) += C;
    }
    Eigen::HouseholderQR<MatrixXd> qr(W);
    const MatrixXd                 R = qr.matrixQR().topRows(b).triangularView<Eigen::Upper>();
    V.middleCols(k, b)               = qr.householderQ() * MatrixXd::Identity(n, b);
    H.block(k, j * b, b, b)          = R;
    // Ritz values of the block Hessenberg matrix and their residuals |R y_last| (y of unit norm):
    // O(k^3), after every block while the basis has at most 8 blocks, then after every
    // ceil(blocks / 8)-th (at most 1/8 more blocks than needed). After every block, they took 11 of
    // the 17 s of the reduced brake's 40 blocks once its tangents were modal (records.md). Sooner
    // where the last two checks' residuals, falling geometrically, reach the tolerance sooner: on
    // pad_cycle.yaml 7.0e-5 at 22 blocks and 6.7e-7 at 26, with 1.5e-5 asked.
    // An invariant subspace: the Ritz values are exact (and the next block would not be orthogonal).
    const bool invariant = R.diagonal().cwiseAbs().minCoeff() <= 1e-13 * H.topLeftCorner(k, k).norm();
    if (!invariant && j + 1 < mlimit && j + 1 > 8 && j + 1 < next_check) continue;
    prev_check = last_check, prev_worst = last_worst;
    last_check      = j + 1;
    PetscReal worst = 0;
    PetscCall(LargestRitz(H.topLeftCorner(k, k), R, nev, ritz, worst));
    last_worst = worst;
    if (mon)
      PetscCall(PetscPrintf(s.comm_, "  Floquet block Arnoldi: %" PetscInt_FMT " x %" PetscInt_FMT " columns, largest |L| = %.6f, worst relative residual of the %" PetscInt_FMT " largest %.2e\n",
                            (PetscInt)(j + 1), (PetscInt)b, ritz.empty() ? 0.0 : (double)std::abs(ritz[0]), (PetscInt)nev, (double)worst));
    // The step puts an error of about |L_trivial - 1| on every multiplier (the trivial one is 1
    // exactly for the flow), and the verdict counts it: Arnoldi's own error need only be a small
    // fraction of it. On the reduced 31119-DOF pad (|L - 1| = 2.4e-4) that is 22 blocks, not 26.
    stop = FloquetArnoldiTolerance(tol, tol_error, ritz);
    if ((k >= nev && worst <= stop) || invariant) break;
    next_check = FloquetNextCheck(j + 1, prev_check, prev_worst, worst, stop);
    if (j + 1 == mmax && mext > mmax) {
      // At the cap: on only if the residuals' decay reaches the tolerance within the extension.
      const Index reach = FloquetBlocksToReach(j + 1, prev_check, prev_worst, worst, stop);
      if (reach > j + 1 && reach <= mext) {
        mlimit = reach;
        if (mon)
          PetscCall(PetscPrintf(s.comm_, "  Floquet block Arnoldi: past -floquet_max_dim %" PetscInt_FMT ": the residuals reach %.1e at %" PetscInt_FMT " blocks (-floquet_max_dim_extend)\n",
                                max_dim, (double)stop, (PetscInt)reach));
        continue;
      }
    }
    if (j + 1 == mlimit) {
      char msg[200];
      std::snprintf(msg, sizeof msg, "Floquet block Arnoldi: the %d largest multipliers reached a relative residual of %.1e, not %.1e, "
                    "in %d columns (-floquet_max_dim%s)", (int)nev, (double)worst, (double)stop, (int)k, mlimit > mmax ? ", -floquet_max_dim_extend" : "");
      PetscCall(PetscPrintf(s.comm_, "shooting: warning: %s\n", msg));
    }
  }
  products_ = used;
  mult      = ritz;
  PetscFunctionReturn(0);
}

Eigen::Index FloquetNextCheck(Eigen::Index blocks, Eigen::Index prev_blocks, PetscReal prev_worst, PetscReal worst, PetscReal stop)
{
  // The cadence: the first c blocks with c - blocks >= ceil(c / 8), and every block up to 8.
  Eigen::Index cadence = 1;
  while (blocks + cadence > 8 && cadence < (blocks + cadence + 7) / 8) ++cadence;
  if (prev_blocks <= 0 || prev_blocks >= blocks || !(worst > stop) || !(prev_worst > worst)) return blocks + cadence;
  // Per block, the residual was multiplied by rate on average since the check before.
  const PetscReal rate   = std::pow(worst / prev_worst, 1.0 / (PetscReal)(blocks - prev_blocks));
  const PetscReal needed = std::ceil(std::log(stop / worst) / std::log(rate));
  return blocks + (std::isfinite(needed) ? (Eigen::Index)std::clamp<PetscReal>(needed, 1, (PetscReal)cadence) : cadence);
}

Eigen::Index FloquetBlocksToReach(Eigen::Index blocks, Eigen::Index prev_blocks, PetscReal prev_worst, PetscReal worst, PetscReal stop)
{
  if (prev_blocks <= 0 || prev_blocks >= blocks || !(worst > stop) || !(prev_worst > worst) || !(stop > 0)) return 0;
  const PetscReal rate   = std::pow(worst / prev_worst, 1.0 / (PetscReal)(blocks - prev_blocks));
  const PetscReal needed = std::ceil(std::log(stop / worst) / std::log(rate));
  return std::isfinite(needed) && needed >= 1 && needed < 1e6 ? blocks + (Eigen::Index)needed : 0;
}

PetscReal FloquetArnoldiTolerance(PetscReal tol, PetscReal tol_error, const std::vector<std::complex<PetscReal>> &ritz)
{
  if (!(tol_error > 0) || ritz.empty()) return tol;
  PetscReal d = kInf;
  for (const auto &l : ritz) d = std::min(d, std::abs(l - 1.0));
  return d <= 0.1 ? std::max(tol, std::min<PetscReal>(tol_error * d, 1e-4)) : tol;
}

FloquetVerdictResult FloquetVerdict(PetscReal largest_nontrivial, PetscReal trivial_error, PetscReal phase_spread)
{
  const PetscReal margin = 1 - largest_nontrivial, error = std::max(trivial_error, phase_spread);
  return {std::abs(margin) <= error ? "undecided" : margin > 0 ? "stable" : "unstable", margin, error};
}

} // namespace squeal
