#include "squeal/stability/sweep.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/inf.h"
#include "squeal/core/errors.h"
#include "squeal/core/options.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/stability.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace squeal {

namespace {

constexpr PetscReal kNaN = std::numeric_limits<PetscReal>::quiet_NaN();

// Track modes along mu at each V: the slots of point i + 1 are reordered so that slot s holds the
// eigenvalue nearest (greedy over all pairs, in the complex plane) to slot s of point i; a mode's
// growth rate can then be followed across mu, also where frequencies cross.
void TrackModes(std::vector<PetscReal> &table, PetscInt k, PetscInt mu_n, PetscInt v_n)
{
  for (PetscInt iv = 0; iv < v_n; ++iv)
    for (PetscInt i = 1; i < mu_n; ++i) {
      const PetscReal *prev = &table[((iv * mu_n + i - 1) * k) * 2];
      PetscReal       *cur  = &table[((iv * mu_n + i) * k) * 2];
      std::vector<std::pair<PetscReal, std::pair<PetscInt, PetscInt>>> pairs;
      for (PetscInt a = 0; a < k; ++a)
        for (PetscInt b = 0; b < k; ++b)
          if (!std::isnan(prev[2 * a]) && !std::isnan(cur[2 * b]))
            pairs.push_back({std::hypot(prev[2 * a] - cur[2 * b], prev[2 * a + 1] - cur[2 * b + 1]), {a, b}});
      std::sort(pairs.begin(), pairs.end());
      std::vector<PetscInt> dest(k, -1), used(k, 0);
      for (const auto &pr : pairs) {
        const PetscInt a = pr.second.first, b = pr.second.second;
        if (used[a] || dest[b] >= 0) continue;
        dest[b] = a, used[a] = 1;
      }
      for (PetscInt b = 0, a = 0; b < k; ++b) // the rest (and empty slots) into free slots, in order
        if (dest[b] < 0) {
          while (used[a]) ++a;
          dest[b] = a, used[a] = 1;
        }
      std::vector<PetscReal> moved(2 * k);
      for (PetscInt b = 0; b < k; ++b) moved[2 * dest[b]] = cur[2 * b], moved[2 * dest[b] + 1] = cur[2 * b + 1];
      std::copy(moved.begin(), moved.end(), cur);
    }
}

} // namespace

PetscReal SweepResult::MaxSigma(size_t iv, size_t imu) const
{
  PetscReal best = -kInf;
  for (PetscInt s = 0; s < k; ++s) {
    const PetscReal *e = &eigenvalues[(((iv * mu.size()) + imu) * k + s) * 2];
    if (!std::isnan(e[0]) && e[1] > 0) best = PetscMax(best, e[0]);
  }
  return best;
}

PetscErrorCode SweepSolver::SetFromOptions(PetscReal default_V)
{
  PetscFunctionBeginUser;
  OptionChecks checks;
  v_min_ = v_max_ = default_V;
  PetscOptionsBegin(comm_, prefix_.c_str(), "Stability map over mu and V", "SweepSolver");
  SquealOptionsReal("-mu_min", "Smallest friction coefficient", "SweepSolver", &mu_min_, Range::NonNegative(), checks);
  SquealOptionsReal("-mu_max", "Largest friction coefficient", "SweepSolver", &mu_max_, Range::NonNegative(), checks);
  PetscCall(PetscOptionsInt("-mu_n", "Number of mu values (uniform grid)", "SweepSolver", mu_n_, &mu_n_, nullptr));
  SquealOptionsReal("-v_min", "Smallest sliding speed (m/s); default: the model's V", "SweepSolver", &v_min_, Range::Positive(), checks);
  SquealOptionsReal("-v_max", "Largest sliding speed (m/s); default: -sweep_v_min", "SweepSolver", &v_max_, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-v_n", "Number of V values (uniform grid)", "SweepSolver", v_n_, &v_n_, nullptr));
  SquealOptionsReal("-bisect_tol", "Refine the critical mu by bisection to this width (0: grid interpolation only)",
                    "SweepSolver", &bisect_tol_, Range::NonNegative(), checks);
  PetscCall(PetscOptionsBool("-monitor", "Print progress (points done) on rank 0", "SweepSolver", monitor_, &monitor_, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(mu_n_ >= 1 && v_n_ >= 1, comm_, kErrInput, "sweep: -%smu_n and -%sv_n must be >= 1", prefix_.c_str(), prefix_.c_str());
  PetscCheck(mu_max_ >= mu_min_ && v_max_ >= v_min_, comm_, kErrInput, "sweep: empty range (max < min)");
  if (v_n_ == 1) v_max_ = v_min_;
  PetscFunctionReturn(0);
}

PetscErrorCode SweepSolver::Solve(const SweepPoint &point, SweepResult &res)
{
  PetscMPIInt rank, size;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  auto grid = [](PetscReal a, PetscReal b, PetscInt n) {
    std::vector<PetscReal> g(n);
    for (PetscInt i = 0; i < n; ++i) g[i] = n == 1 ? a : a + (b - a) * i / (n - 1);
    return g;
  };
  res.mu               = grid(mu_min_, mu_max_, mu_n_);
  res.V                = grid(v_min_, v_max_, v_n_);
  const PetscInt npts  = mu_n_ * v_n_;

  // Solve the local share; keep results until the slot count is known everywhere.
  std::vector<std::vector<PetscReal>> local(npts);
  std::vector<PetscInt>               failed(npts, 0), covered(npts, 0);
  std::vector<PetscReal>              complete(npts, 0.0);
  PetscInt                            kmax = 0, done = 0;
  // Rounds of one point per rank, so that every rank polls the interrupt as often (collective);
  // the points a signal leaves unsolved are marked 2 (not computed), not "without steady sliding".
  res.interrupted = false;
  for (PetscInt p0 = 0; p0 < npts; p0 += size) {
    bool stop;
    PetscCall(InterruptRequested(comm_, &stop));
    if (stop) {
      res.interrupted = true;
      for (PetscInt p = p0 + rank; p < npts; p += size) failed[p] = 2;
      break;
    }
    const PetscInt p = p0 + rank;
    if (p >= npts) continue;
    StabilityResult sr;
    bool            ok;
    PetscCall(point(res.mu[p % mu_n_], res.V[p / mu_n_], sr, &ok));
    // The point's eigensolve, on this rank alone, fails at its first monitor call after a signal.
    if (!ok) failed[p] = InterruptSignal() ? 2 : 1;
    else {
      for (const Mode &m : sr.modes) local[p].insert(local[p].end(), {m.sigma, m.omega});
      covered[p]  = sr.BandCovered();
      complete[p] = sr.CompleteUpTo();
      res.fmax    = sr.fmax;
      kmax = PetscMax(kmax, (PetscInt)sr.modes.size());
    }
    if (monitor_ && rank == 0 && (++done % 10 == 0 || p + size >= npts))
      PetscCall(PetscPrintf(PETSC_COMM_SELF, "sweep: rank 0 solved %" PetscInt_FMT " of its %" PetscInt_FMT " points\n", done,
                            (npts - 1) / size + 1));
  }
  PetscCallMPI(MPI_Allreduce(&kmax, &res.k, 1, MPIU_INT, MPI_MAX, comm_));
  res.failed.assign(npts, 0);
  PetscCallMPI(MPI_Allreduce(failed.data(), res.failed.data(), (int)npts, MPIU_INT, MPI_MAX, comm_));
  res.covered.assign(npts, 0);
  PetscCallMPI(MPI_Allreduce(covered.data(), res.covered.data(), (int)npts, MPIU_INT, MPI_MAX, comm_));
  res.complete_up_to.assign(npts, 0.0);
  PetscCallMPI(MPI_Allreduce(complete.data(), res.complete_up_to.data(), (int)npts, MPIU_REAL, MPI_MAX, comm_));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &res.fmax, 1, MPIU_REAL, MPI_MAX, comm_));
  // Sum of disjoint contributions; slots a point does not fill are marked and set to NaN after.
  std::vector<PetscReal> table(npts * res.k * 2, 0.0), filled(npts * res.k, 0.0);
  for (PetscInt p = 0; p < npts; ++p)
    for (size_t s = 0; s < local[p].size() / 2; ++s) {
      table[(p * res.k + s) * 2]     = local[p][2 * s];
      table[(p * res.k + s) * 2 + 1] = local[p][2 * s + 1];
      filled[p * res.k + s]          = 1;
    }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, table.data(), (int)table.size(), MPIU_REAL, MPIU_SUM, comm_));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, filled.data(), (int)filled.size(), MPIU_REAL, MPIU_SUM, comm_));
  for (size_t s = 0; s < filled.size(); ++s)
    if (filled[s] == 0) table[2 * s] = table[2 * s + 1] = kNaN;
  TrackModes(table, res.k, mu_n_, v_n_);
  res.eigenvalues = std::move(table);

  // Critical mu per V: bracket on the grid, then bisection on the owning rank.
  std::vector<PetscReal> crit(v_n_, 0.0), freq(v_n_, 0.0);
  PetscMPIInt any_stop = res.interrupted ? 1 : 0;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &any_stop, 1, MPI_INT, MPI_MAX, comm_));
  res.interrupted = any_stop != 0;
  for (PetscInt iv = rank; iv < v_n_; iv += size) {
    crit[iv] = freq[iv] = kNaN;
    if (res.interrupted) continue; // the grid has holes: no crossing is located (nor certified)
    for (PetscInt i = 0; i + 1 < mu_n_; ++i) {
      const PetscReal s0 = res.MaxSigma(iv, i), s1 = res.MaxSigma(iv, i + 1);
      if (!(s0 <= 0 && s1 > 0)) continue;
      PetscReal a = res.mu[i], b = res.mu[i + 1], fa = s0, fb = s1;
      PetscReal f_at = kNaN;
      while (bisect_tol_ > 0 && b - a > bisect_tol_) {
        const PetscReal m = 0.5 * (a + b);
        StabilityResult sr;
        bool            ok;
        PetscCall(point(m, res.V[iv], sr, &ok));
        if (!ok) break;
        PetscInt        w;
        const PetscReal sm = sr.MaxOscillatorySigma(&w);
        if (w >= 0) f_at = sr.modes[w].Frequency();
        if (sm > 0) b = m, fb = sm;
        else a = m, fa = sm;
      }
      crit[iv] = (std::isfinite(fa) && std::isfinite(fb) && fb != fa) ? a + (b - a) * (-fa) / (fb - fa) : 0.5 * (a + b);
      if (std::isnan(f_at)) { // interpolate the frequency of the most unstable mode on the grid
        StabilityResult sr;
        bool            ok;
        PetscCall(point(crit[iv], res.V[iv], sr, &ok));
        PetscInt w;
        sr.MaxOscillatorySigma(&w);
        if (ok && w >= 0) f_at = sr.modes[w].Frequency();
      }
      freq[iv] = f_at;
      break;
    }
  }
  // NaN survives the sum only from the owner; others contribute 0.
  for (PetscInt iv = 0; iv < v_n_; ++iv)
    if ((iv % size) != rank) crit[iv] = freq[iv] = 0.0;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, crit.data(), (int)v_n_, MPIU_REAL, MPIU_SUM, comm_));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, freq.data(), (int)v_n_, MPIU_REAL, MPIU_SUM, comm_));
  res.critical_mu           = crit;
  res.coalescence_frequency = freq;
  // A crossing (or its absence) is certified only if every point up to it covered its band.
  res.critical_certified.assign(v_n_, 1);
  for (PetscInt iv = 0; iv < v_n_; ++iv)
    for (PetscInt i = 0; i < mu_n_; ++i) {
      if (res.interrupted) res.critical_certified[iv] = 0;
      if (!std::isnan(crit[iv]) && res.mu[i] > crit[iv]) break;
      if (!res.failed[iv * mu_n_ + i] && !res.covered[iv * mu_n_ + i]) res.critical_certified[iv] = 0;
    }
  PetscFunctionReturn(0);
}

PetscErrorCode SweepSolver::View(const SweepResult &res, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscInt nfail = 0, nskip = 0;
  for (PetscInt f : res.failed) nfail += f == 1, nskip += f == 2;
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "stability map: %zu mu value(s) in [%g, %g] x %zu V value(s) in [%g, %g] m/s, %" PetscInt_FMT
                                   " point(s) without steady sliding\n",
                                   res.mu.size(), (double)res.mu.front(), (double)res.mu.back(), res.V.size(),
                                   (double)res.V.front(), (double)res.V.back(), nfail));
  if (res.interrupted)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "INTERRUPTED by %s: %" PetscInt_FMT " of %zu point(s) computed (/sweep/failed = 2: not computed); no "
                                     "critical mu located\n",
                                     InterruptSignalName(), (PetscInt)res.failed.size() - nskip, res.failed.size()));
  PetscInt nuncov = 0;
  PetscReal worst = kInf;
  for (size_t p = 0; p < res.covered.size(); ++p)
    if (!res.failed[p] && !res.covered[p]) nuncov++, worst = PetscMin(worst, res.complete_up_to[p]);
  if (res.fmax > 0 && nuncov == 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "band up to %g Hz covered at every point (-stab_fmax)\n", (double)res.fmax));
  else if (res.fmax > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "BAND NOT COVERED at %" PetscInt_FMT " point(s) (down to %.6g Hz of %g Hz): raise -stab_nev_max or lower "
                                     "-stab_fmax; an unstable mode may be missing there (/sweep/band_covered)\n",
                                     nuncov, (double)worst, (double)res.fmax));
  PetscCall(PetscViewerASCIIPrintf(viewer, "      V (m/s)   critical mu   coalescence f (Hz)\n"));
  for (size_t iv = 0; iv < res.V.size(); ++iv) {
    const char *flag = res.critical_certified[iv] ? "" : "   (not certified: band not covered below it)";
    if (std::isnan(res.critical_mu[iv]))
      PetscCall(PetscViewerASCIIPrintf(viewer, "  %11.5g   %11s   %18s%s\n", (double)res.V[iv], "none", "-", flag));
    else
      PetscCall(PetscViewerASCIIPrintf(viewer, "  %11.5g   %11.6f   %18.4f%s\n", (double)res.V[iv], (double)res.critical_mu[iv],
                                       (double)res.coalescence_frequency[iv], flag));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode SweepSolver::Write(const SweepResult &res, io::H5Writer &out) const
{
  PetscFunctionBeginUser;
  PetscCall(out.WriteArray("/sweep/mu", {(hsize_t)res.mu.size()}, res.mu.data()));
  PetscCall(out.WriteArray("/sweep/V", {(hsize_t)res.V.size()}, res.V.data()));
  PetscCall(out.WriteArray("/sweep/eigenvalues", {(hsize_t)res.V.size(), (hsize_t)res.mu.size(), (hsize_t)res.k, 2},
                           res.eigenvalues.data()));
  PetscCall(out.WriteIntArray("/sweep/failed", {(hsize_t)res.V.size(), (hsize_t)res.mu.size()}, res.failed.data()));
  PetscCall(out.WriteIntArray("/sweep/band_covered", {(hsize_t)res.V.size(), (hsize_t)res.mu.size()}, res.covered.data()));
  PetscCall(out.WriteArray("/sweep/complete_up_to", {(hsize_t)res.V.size(), (hsize_t)res.mu.size()}, res.complete_up_to.data()));
  PetscCall(out.WriteIntArray("/sweep/critical_certified", {(hsize_t)res.V.size()}, res.critical_certified.data()));
  PetscCall(out.WriteAttribute("/sweep/complete_up_to", "units", "Hz; every eigenvalue with |lambda| < 2 pi x computed (inf: all; 0: failed point)"));
  PetscCall(out.WriteAttribute("/sweep/failed", "meaning", "0 solved, 1 no steady sliding or no eigenvalues, 2 not computed (interrupted)"));
  PetscCall(out.WriteAttribute("/sweep", "interrupted", (PetscInt)res.interrupted));
  PetscCall(out.WriteAttribute("/sweep", "fmax", res.fmax));
  PetscCall(out.WriteAttribute("/sweep/V", "units", "m/s"));
  PetscCall(out.WriteAttribute("/sweep/eigenvalues", "units", "1/s"));
  PetscCall(out.WriteAttribute("/sweep/eigenvalues", "layout",
                               "[V][mu][slot][re, im], omega >= 0 members, NaN: absent; a slot follows one mode along mu (nearest eigenvalue)"));
  PetscCall(out.WriteAttribute("/sweep", "critical_mu", res.critical_mu));
  PetscCall(out.WriteAttribute("/sweep", "coalescence_frequency", res.coalescence_frequency));
  PetscCall(out.WriteAttribute("/sweep", "coalescence_frequency_units", "Hz"));
  PetscFunctionReturn(0);
}

} // namespace squeal
