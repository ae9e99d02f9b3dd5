// The cycle summary of a transient run (TransientAnalysis::Summarise, declared in transient.h):
// the settled test on rank 0's records.
#include "squeal/integration/transient.h"
#include "squeal/core/inf.h"

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <vector>

namespace squeal {

namespace {

// Cubic Hermite interpolant of one record interval of length h from the values and the recorded
// velocities: p(s) = x0 + h v0 s + b s^2 + c s^3, s in [0, 1]. Its error is O(h^4): a clean
// cycle's crossing times and extrema come out far below the record spacing.
struct Hermite {
  PetscReal x0, hv0, b, c;
  Hermite(PetscReal x0_, PetscReal x1, PetscReal v0, PetscReal v1, PetscReal h) : x0(x0_), hv0(h * v0)
  {
    const PetscReal d = x1 - x0_;
    b                 = 3 * d - h * (2 * v0 + v1);
    c                 = h * (v0 + v1) - 2 * d;
  }
  PetscReal operator()(PetscReal s) const { return x0 + s * (hv0 + s * (b + s * c)); }
  // Smallest and largest value on [0, 1]: the end points and the roots of p' = hv0 + 2 b s + 3 c s^2.
  void Range(PetscReal &lo, PetscReal &hi) const
  {
    lo = std::min((*this)(0), (*this)(1));
    hi = std::max((*this)(0), (*this)(1));
    const PetscReal A = 3 * c, B = 2 * b, C = hv0;
    PetscReal       r[2];
    int             n = 0;
    if (std::abs(A) > 1e-12 * (std::abs(B) + std::abs(C))) {
      const PetscReal disc = B * B - 4 * A * C;
      if (disc >= 0) {
        const PetscReal q = -0.5 * (B + std::copysign(std::sqrt(disc), B));
        r[n++]            = q / A;
        if (q != 0) r[n++] = C / q;
      }
    } else if (B != 0) r[n++] = -C / B;
    for (int i = 0; i < n; ++i)
      if (r[i] > 0 && r[i] < 1) lo = std::min(lo, (*this)(r[i])), hi = std::max(hi, (*this)(r[i]));
  }
  // A root of p(s) = level in [0, 1] given p(0) < level <= p(1); bisection, since p need not be monotone.
  PetscReal Crossing(PetscReal level) const
  {
    PetscReal lo = 0, hi = 1;
    for (int i = 0; i < 64 && hi - lo > 1e-16; ++i) {
      const PetscReal m = 0.5 * (lo + hi);
      ((*this)(m) < level ? lo : hi) = m;
    }
    return 0.5 * (lo + hi);
  }
};

struct Crossing {
  PetscReal t;    // time of the up-crossing
  size_t    k;    // record interval [k, k + 1] it lies in
  PetscReal s;    // fraction of that interval
};

// Least-squares line y = a + slope i, i = 0..n-1: slope and the std of the residuals.
void FitLine(const std::vector<PetscReal> &y, PetscReal &slope, PetscReal &scatter)
{
  const size_t n = y.size();
  PetscReal    im = 0.5 * (n - 1), ym = 0, sxx = 0, sxy = 0, r2 = 0;
  for (PetscReal v : y) ym += v / n;
  for (size_t i = 0; i < n; ++i) sxx += (i - im) * (i - im), sxy += (i - im) * (y[i] - ym);
  slope = sxx > 0 ? sxy / sxx : 0;
  for (size_t i = 0; i < n; ++i) r2 += std::pow(y[i] - ym - slope * (i - im), 2);
  scatter = n > 2 ? std::sqrt(r2 / (n - 2)) : 0;
}

// The cycle read off rank 0's records for Summarise, in steps: the signal (peak-to-peak per DOF,
// the DOF that moves most), its Poincare section, the whole state at the crossings, the state's
// period in crossings, and per cycle the period, peak-to-peak and return error with the verdict.
// Everything is read over the last 20 % of the records (from on).
class CycleReader {
public:
  // The window: records from..nr-1 (by default the last 20 %).
  explicit CycleReader(const TransientResult &res) : CycleReader(res, res.t.size() - std::max<size_t>(res.t.size() / 5, 2)) {}
  CycleReader(const TransientResult &res, size_t from)
    : res_(res), nr_(res.t.size()), N_(res.N), from_(from),
      has_v_(res.V.size() >= nr_ * N_) // without velocities the interpolant is the chord
  {
  }
  void      Signal(TransientSummary &s);
  void      Section();
  size_t    Crossings() const { return cr_.size(); }
  PetscReal Spacing() const { return dt_; } // the mean record spacing
  void      States(PetscInt settle_periods);
  size_t    PeriodMultiple() const;
  void      Cycles(TransientSummary &s, size_t m, PetscReal settle_tol, PetscInt settle_periods) const;

private:
  PetscReal U(size_t k, PetscInt j) const { return res_.U[k * N_ + j]; }
  Hermite   Piece(size_t k, PetscInt j) const
  {
    const PetscReal h = res_.t[k + 1] - res_.t[k], chord = (U(k + 1, j) - U(k, j)) / h;
    return Hermite(U(k, j), U(k + 1, j), has_v_ ? res_.V[k * N_ + j] : chord, has_v_ ? res_.V[(k + 1) * N_ + j] : chord, h);
  }
  void      Extrema(PetscInt j, size_t a, size_t b, PetscReal &lo, PetscReal &hi) const;
  void      Refine(PetscInt j, size_t a, size_t b, size_t klo, size_t khi, PetscReal &lo, PetscReal &hi) const;
  void      Cross(PetscReal depth);
  PetscReal Return(size_t e, size_t m) const;
  PetscReal MedianReturn(size_t m) const;

  const TransientResult &res_;
  const size_t           nr_;
  const PetscInt         N_;
  const size_t           from_;
  const bool             has_v_;
  std::vector<PetscReal> mean_;           // per DOF, over the window
  std::vector<size_t>    klo_;            // per DOF, the record of its smallest value in the window
  PetscInt               best_ = 0;       // the DOF that moves most
  PetscReal              c_ = 0, dt_ = 0; // the section's level (best_'s mean), the record spacing
  std::vector<Crossing>  cr_;
  // The state Z = (U - mean, dU / omega) at crossings e0_ .. e0_ + ne_ - 1, its interpolation error
  // per crossing, both relative to zscale_, the mean |Z| over the window.
  size_t                 e0_ = 0, ne_ = 0;
  std::vector<PetscReal> Z_, zfloor_;
  PetscReal              zscale_ = 0;
};

// Extrema of DOF j over records a..b: the recorded ones refined in their neighbouring intervals.
void CycleReader::Extrema(PetscInt j, size_t a, size_t b, PetscReal &lo, PetscReal &hi) const
{
  size_t klo = a, khi = a;
  for (size_t k = a; k <= b; ++k) {
    if (U(k, j) < U(klo, j)) klo = k;
    if (U(k, j) > U(khi, j)) khi = k;
  }
  Refine(j, a, b, klo, khi, lo, hi);
}

// Extrema's refinement of the recorded extrema klo, khi of DOF j over records a..b.
void CycleReader::Refine(PetscInt j, size_t a, size_t b, size_t klo, size_t khi, PetscReal &lo, PetscReal &hi) const
{
  lo = U(klo, j), hi = U(khi, j);
  for (size_t k : {klo, khi})
    for (size_t i = k > a ? k - 1 : a; i <= k && i < b; ++i) {
      PetscReal l, h;
      Piece(i, j).Range(l, h);
      lo = std::min(lo, l), hi = std::max(hi, h);
    }
}

// Peak-to-peak and mean per DOF; the section DOF, the one that moves most. One pass over the
// window's records for every DOF (the recorded extrema and the means, each DOF's sums in record
// order as a pass per DOF would make them), then each DOF's extrema refined as Extrema does.
void CycleReader::Signal(TransientSummary &s)
{
  s.peak_to_peak.assign(N_, 0.0);
  mean_.assign(N_, 0.0);
  klo_.assign(N_, from_);
  std::vector<size_t> khi(N_, from_);
  const PetscReal     nw = (PetscReal)(nr_ - from_);
  const PetscReal    *u  = res_.U.data();
  // The extrema so far by value too (the same tests as against U(klo, j), without the index loads).
  std::vector<PetscReal> lov(u + from_ * N_, u + (from_ + 1) * N_), hiv(lov);
  PetscReal          *mean = mean_.data(), *lo = lov.data(), *hi = hiv.data();
  size_t             *klo = klo_.data(), *kh = khi.data();
  // The pass on N_ values a record, or on 3 known at compile time (the 3-DOF model: the loop over
  // the DOFs unrolled); the same operations either way.
  const auto pass = [&](auto n_c) {
    constexpr PetscInt NC = decltype(n_c)::value;
    const PetscInt     n  = NC > 0 ? NC : N_;
    for (size_t k = from_; k < nr_; ++k) {
      const PetscReal *uk = u + k * n;
#if defined(__GNUC__) && !defined(__clang__)
  #pragma GCC unroll 4
#endif
      for (PetscInt j = 0; j < n; ++j) {
        const PetscReal x = uk[j];
        if (x < lo[j]) klo[j] = k, lo[j] = x;
        if (x > hi[j]) kh[j] = k, hi[j] = x;
        mean[j] += x / nw;
      }
    }
  };
  if (N_ == 3) pass(std::integral_constant<PetscInt, 3>{});
  else pass(std::integral_constant<PetscInt, 0>{});
  best_ = 0;
  for (PetscInt j = 0; j < N_; ++j) {
    PetscReal lo, hi;
    Refine(j, from_, nr_ - 1, klo[j], kh[j], lo, hi);
    s.peak_to_peak[j] = hi - lo;
    if (s.peak_to_peak[j] > s.peak_to_peak[best_]) best_ = j;
  }
  s.signal_dof = best_;
}

// Poincare section: up-crossings of the mean of the DOF that moves most, with hysteresis. A
// crossing counts only after the DOF went below mean - kHysteresis x the depth of the previous
// cycle, so the wiggles of strong harmonics across the mean are not cycles, and a growing or
// decaying motion (by up to 1 / kHysteresis per cycle) keeps every cycle. Before the first
// crossing the depth is that of the first period of the window (a first pass with the whole
// window's depth estimates the period), so a growing motion loses no cycle either.
constexpr PetscReal kHysteresis = 0.5;

void CycleReader::Cross(PetscReal depth)
{
  PetscReal cyc_min = kInf;
  bool      armed   = false;
  cr_.clear();
  // Locals: the members would be read again at every record (push_back might change them).
  const PetscReal *ub = res_.U.data() + best_;
  const size_t     N = (size_t)N_;
  const PetscReal  c = c_;
  for (size_t k = from_; k + 1 < nr_; ++k) {
    const PetscReal x0 = ub[k * N], x1 = ub[(k + 1) * N];
    cyc_min            = std::min(cyc_min, x0);
    if (x0 < c - kHysteresis * depth) armed = true;
    if (armed && x0 < c && x1 >= c) {
      const PetscReal sk = Piece(k, best_).Crossing(c_);
      cr_.push_back({res_.t[k] + sk * (res_.t[k + 1] - res_.t[k]), k, sk});
      armed   = false;
      depth   = c_ - cyc_min;
      cyc_min = kInf;
    }
  }
}

void CycleReader::Section()
{
  c_  = mean_[best_];
  dt_ = (res_.t[nr_ - 1] - res_.t[from_]) / (PetscReal)(nr_ - 1 - from_);
  // The largest c_ - U over the window, c_ - its smallest U (the rounded difference is monotone in U).
  PetscReal depth = std::max<PetscReal>(0, c_ - U(klo_[best_], best_));
  Cross(depth);
  if (cr_.size() >= 2) {
    const PetscReal T1 = (cr_.back().t - cr_.front().t) / (PetscReal)(cr_.size() - 1);
    depth              = 0;
    for (size_t k = from_; k < nr_ && res_.t[k] <= res_.t[from_] + T1; ++k) depth = std::max(depth, c_ - U(k, best_));
    Cross(depth);
  }
}

// The whole state Z = (U - mean, dU / omega) at the last crossings (at most kMax, so a
// long window of a large model costs little): U by its Hermite interpolant, dU by the cubic
// through the 4 nearest records (no acceleration is recorded). Needs 2 crossings.
void CycleReader::States(PetscInt settle_periods)
{
  const size_t    L     = (size_t)settle_periods + 1;
  const size_t    kMax  = std::max<size_t>(64, L) + 3;
  const PetscReal omega = 2 * PETSC_PI * (PetscReal)(cr_.size() - 1) / (cr_.back().t - cr_.front().t);
  e0_                   = cr_.size() > kMax ? cr_.size() - kMax : 0, ne_ = cr_.size() - e0_;
  // The sum in a local and the test on has_v_ out of the loop: the same operations in the same order.
  PetscReal        zscale = 0;
  const PetscReal *mean = mean_.data(), *u = res_.U.data(), *vel = has_v_ ? res_.V.data() : nullptr;
  for (size_t k = from_; k < nr_; ++k) {
    PetscReal        z2 = 0;
    const PetscReal *uk = u + k * N_;
    if (vel) {
      const PetscReal *vk = vel + k * N_;
      for (PetscInt j = 0; j < N_; ++j) {
        z2 += std::pow(uk[j] - mean[j], 2);
        z2 += std::pow(vk[j] / omega, 2);
      }
    } else
      for (PetscInt j = 0; j < N_; ++j) z2 += std::pow(uk[j] - mean[j], 2);
    zscale += std::sqrt(z2) / (PetscReal)(nr_ - from_);
  }
  zscale_ = zscale;
  // The interpolation error of Z, estimated per crossing by the change of dU from the quadratic
  // through the 3 nearest of those records to the cubic, is the floor under which a return
  // error cannot be checked (coarse records: -transient_keep_every).
  Z_.assign(ne_ * 2 * N_, 0.0), zfloor_.assign(ne_, 0.0);
  for (size_t e = 0; e < ne_; ++e) {
    const Crossing &x  = cr_[e0_ + e];
    PetscReal      *z  = &Z_[e * 2 * N_];
    const size_t    k0 = std::min(x.k > 0 ? x.k - 1 : 0, nr_ - 4);
    const int       q0 = x.t - res_.t[k0] < res_.t[k0 + 3] - x.t ? 0 : 1; // the quadratic's first node
    PetscReal       w[4], wq[3];
    for (int a = 0; a < 4; ++a) {
      w[a] = 1;
      for (int b = 0; b < 4; ++b)
        if (b != a) w[a] *= (x.t - res_.t[k0 + b]) / (res_.t[k0 + a] - res_.t[k0 + b]);
    }
    for (int a = 0; a < 3; ++a) {
      wq[a] = 1;
      for (int b = 0; b < 3; ++b)
        if (b != a) wq[a] *= (x.t - res_.t[k0 + q0 + b]) / (res_.t[k0 + q0 + a] - res_.t[k0 + q0 + b]);
    }
    PetscReal f2 = 0;
    for (PetscInt j = 0; j < N_; ++j) {
      z[j] = Piece(x.k, j)(x.s) - mean_[j];
      if (!has_v_) continue;
      PetscReal vq = 0;
      for (int a = 0; a < 4; ++a) z[N_ + j] += w[a] * res_.V[(k0 + a) * N_ + j] / omega;
      for (int a = 0; a < 3; ++a) vq += wq[a] * res_.V[(k0 + q0 + a) * N_ + j] / omega;
      f2 += std::pow(z[N_ + j] - vq, 2);
    }
    zfloor_[e] = zscale_ > 0 ? std::sqrt(f2) / zscale_ : 0.0;
  }
}

// The return error from crossing e0 + e to e0 + e + m.
PetscReal CycleReader::Return(size_t e, size_t m) const
{
  PetscReal d2 = 0;
  for (PetscInt j = 0; j < 2 * N_; ++j) d2 += std::pow(Z_[(e + m) * 2 * N_ + j] - Z_[e * 2 * N_ + j], 2);
  return zscale_ > 0 ? std::sqrt(d2) / zscale_ : 0.0;
}

PetscReal CycleReader::MedianReturn(size_t m) const
{
  std::vector<PetscReal> r;
  for (size_t e = 0; e + m < ne_; ++e) r.push_back(Return(e, m));
  std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
  return r[r.size() / 2];
}

// The state's period: 2 or 3 crossings when the state returns 10 x closer after them than
// after one (a period-2/3 cycle, or a harmonic that still crosses twice a period).
size_t CycleReader::PeriodMultiple() const
{
  size_t m = 1;
  if (ne_ >= 4) {
    const PetscReal r1 = MedianReturn(1);
    for (size_t q = 2; q <= 3 && m == 1; ++q)
      if (ne_ >= q + 3 && MedianReturn(q) < 0.1 * r1) m = q;
  }
  return m;
}

// Per cycle (crossing i to i + m): period, peak-to-peak of the section DOF, return error; then the
// verdict on the last settle_periods + 1 cycles and the trend over all of them.
void CycleReader::Cycles(TransientSummary &s, size_t m, PetscReal settle_tol, PetscInt settle_periods) const
{
  const size_t           L = (size_t)settle_periods + 1;
  std::vector<PetscReal> T, A, logA;
  for (size_t i = 0; i + m < cr_.size(); ++i) {
    PetscReal lo, hi;
    Extrema(best_, cr_[i].k, cr_[i + m].k + 1, lo, hi);
    T.push_back(cr_[i + m].t - cr_[i].t);
    A.push_back(hi - lo);
    logA.push_back(std::log(std::max(hi - lo, PETSC_SMALL * s.peak_to_peak[best_])));
  }
  s.cycles             = (PetscInt)T.size();
  const size_t    nl   = std::min(L, T.size());
  PetscReal       Tsum = 0;
  for (size_t i = T.size() - nl; i < T.size(); ++i) Tsum += T[i];
  s.period             = Tsum / nl;
  s.records_per_period = s.period / dt_;
  if (s.records_per_period < 8 || (res_.T_ref > 0 && dt_ > res_.T_ref / 8)) s.trend = Trend::Aliased;
  else if (T.size() < L) s.trend = Trend::TooShort;
  else {
    const auto Tmm = std::minmax_element(T.end() - L, T.end());
    const auto Amm = std::minmax_element(A.end() - L, A.end());
    s.period_change    = (*Tmm.second - *Tmm.first) / s.period;
    s.amplitude_change = *Amm.second > 0 ? (*Amm.second - *Amm.first) / *Amm.second : 0;
    for (size_t i = cr_.size() - m - L; i + m < cr_.size(); ++i) {
      s.return_error = std::max(s.return_error, Return(i - e0_, m));
      s.return_floor = std::max(s.return_floor, 2 * (zfloor_[i - e0_] + zfloor_[i - e0_ + m])); // 2: a margin on an estimate
    }
    // Trend over every cycle of the window: the fitted change per period of log(peak-to-peak)
    // (a cycle advances one crossing, 1/m of a period), and the scatter about that line.
    PetscReal slope, pslope, pscatter;
    FitLine(logA, slope, s.amplitude_scatter);
    FitLine(T, pslope, pscatter);
    s.period_scatter = pscatter / s.period;
    s.fit_cycles     = (PetscInt)logA.size();
    s.amplitude_rate = std::expm1(slope * m);
    // A trend is one that carries the envelope further over the window than 4 x its scatter.
    const bool trend = std::abs(s.amplitude_rate) > settle_tol / settle_periods &&
                       std::abs(slope) * (PetscReal)(logA.size() - 1) > 4 * s.amplitude_scatter;
    if (s.period_change < settle_tol && s.amplitude_change < settle_tol && s.return_error < std::max(settle_tol, s.return_floor))
      s.trend = Trend::Settled, s.settled = true;
    else if (trend) s.trend = s.amplitude_rate > 0 ? Trend::Growing : Trend::Decaying;
    else if (s.amplitude_scatter > settle_tol || s.period_scatter > settle_tol) {
      s.trend = Trend::Irregular; // no cycle to converge to: the period is the mean over the window
      for (size_t i = 0; i + nl < T.size(); ++i) Tsum += T[i];
      s.period = Tsum / T.size();
    }
    else s.trend = Trend::Drifting;
  }
}

// The contact fractions over the last 20 % (records from on) and the energy balance's defect.
void Levels(const TransientResult &res, size_t from, TransientSummary &s)
{
  const size_t   nr = res.t.size();
  const PetscInt nc = res.nc;
  if (nc > 0 && res.status.size() >= nr * nc) {
    PetscInt cnt[3] = {0, 0, 0};
    if (nc == 1) // one point (the 3-DOF model): one loop
      for (size_t k = from; k < nr; ++k) cnt[res.status[k]]++;
    else
      for (size_t k = from; k < nr; ++k)
        for (PetscInt c = 0; c < nc; ++c) cnt[res.status[k * nc + c]]++;
    const PetscReal tot = (PetscReal)((nr - from) * nc);
    s.frac_separated    = cnt[kOpen] / tot;
    s.frac_stuck        = cnt[kStick] / tot;
    s.frac_sliding      = cnt[kSlip] / tot;
  }
  if (res.energy_kept && res.energy.size() >= 4 * nr) {
    PetscReal       emax = 0, defect = 0;
    const PetscReal E0   = res.energy[0];
#if defined(__GNUC__) && !defined(__clang__)
  #pragma GCC unroll 4
#endif
    for (size_t k = 0; k < nr; ++k) { // every record: unrolled, the loop's test is most of a record's cost
      const PetscReal *e = &res.energy[4 * k];
      emax               = std::max(emax, std::abs(e[0]));
      defect             = std::max(defect, std::abs((e[0] - E0) - (e[2] + e[3] - e[1])));
    }
    s.energy_defect = emax > 0 ? defect / emax : 0;
  }
}

} // namespace

PetscInt TransientAnalysis::SignalDof(const TransientResult &window)
{
  const size_t nr = window.t.size();
  if (nr < 2 || window.N < 1 || window.U.size() < nr * window.N) return -1;
  TransientSummary s;
  CycleReader(window, 0).Signal(s);
  return s.signal_dof;
}

void TransientAnalysis::Summarise(TransientResult &res, PetscReal settle_tol, PetscInt settle_periods)
{
  TransientSummary &s  = res.summary;
  const size_t      nr = res.t.size();
  const PetscInt    N  = res.N;
  if (nr < 4 || N < 1 || res.U.size() < nr * N) return;
  CycleReader cycle(res);
  cycle.Signal(s);
  s.settled         = false;
  s.period          = 0;
  s.cycles          = 0;
  s.fit_cycles      = 0;
  s.period_multiple = 1;
  s.amplitude_rate = s.period_change = s.amplitude_change = s.return_error = s.return_floor = s.amplitude_scatter = s.period_scatter = 0;
  s.records_per_period = 0;
  cycle.Section();
  if (!(s.peak_to_peak[s.signal_dof] > 0)) s.trend = Trend::NoOscillation;
  else if (cycle.Crossings() < 2) s.trend = res.T_ref > 0 && cycle.Spacing() > res.T_ref / 8 ? Trend::Aliased : Trend::TooShort;
  else {
    cycle.States(settle_periods);
    const size_t m    = cycle.PeriodMultiple();
    s.period_multiple = (PetscInt)m;
    cycle.Cycles(s, m, settle_tol, settle_periods);
  }
  Levels(res, nr - std::max<size_t>(nr / 5, 2), s);
}

} // namespace squeal
