// Shooting's pre-periods (Shooting::PrePeriods): periods of the flow before Newton, which bring the
// start near an attracting cycle and measure the motion's own period on the way.
#include "squeal/shooting/shooting.h"
#include "internal.h"
#include "squeal/core/inf.h"
#include "squeal/core/interrupt.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <utility>
#include <vector>

namespace squeal {

namespace {

// The motion's own period, measured along the pre-periods' flow (Shooting::PrePeriods): the first-
// order correction of the period only reaches a cycle within a few per cent of T0 (case 1 at mu = 5
// settles at 2.14 T_lin, beyond the bracket (T0/2, 2 T0)). The section through a state Z_r of the
// flow normal to G(Z_r), and its upward crossings (the states interpolated linearly in the step)
// that come back within kReturn of the largest excursion from Z_r since. A cycle may loop several
// times near Z_r before it closes (case 1 at mu = 5: twice, the loops 2 % apart): at each crossing,
// of the last four (Z_r the first) the loop count m is the smallest of 2, 3 whose returns are kLoop
// closer than one loop's (as -analyses transient reads it), else 1, and the period the time of the
// last m crossings. Two successive periods within kAgree with the same m make the measurement
// (Measured). A section the motion has drifted away from (no crossing for 4 flow periods) restarts
// at the current state.
class SectionPeriod {
public:
  // G(Z): the vector field at a state with its reactions (Shooting::VectorField).
  using Field = std::function<PetscErrorCode(Vec, Vec, const Eigen::VectorXd &, Vec, Vec)>;

  PetscErrorCode Create(Vec U0, Vec dU0, PetscInt steps, Field field)
  {
    PetscFunctionBeginUser;
    steps_ = steps, field_ = std::move(field);
    for (VecH *v : {&ZrU, &GrU, &mU, &pU, &CU[0], &CU[1], &CU[2], &CU[3]}) PetscCall(VecDuplicate(U0, v->out()));
    for (VecH *v : {&ZrdU, &GrdU, &mdU, &pdU, &CdU[0], &CdU[1], &CdU[2], &CdU[3]}) PetscCall(VecDuplicate(dU0, v->out()));
    PetscFunctionReturn(0);
  }
  void           SetStep(PetscReal T, PetscInt steps) { sec.h = T / steps, steps_ = steps; }
  PetscErrorCode Step(Vec U1, Vec dU1, const Eigen::VectorXd &rr); // after every step of the flow
  // When a period was measured since the last call: Tm, the last one once it agrees with the one
  // before (else 0), and its loop count (only when Tm > 0); true when Tm > 0.
  bool           Measured(PetscReal &Tm, int &loops);

private:
  static constexpr PetscReal kReturn = 0.2, kAgree = 1e-2, kLoop = 0.1;
  static constexpr int       kRing   = 4;
  PetscErrorCode             SetRef(Vec U1, Vec dU1, const Eigen::VectorXd &rr);
  PetscErrorCode             Dist(int a, int b, PetscReal *d);
  PetscErrorCode             Crossing(Vec U1, Vec dU1, PetscReal s);

  PetscInt steps_ = 0;
  Field    field_;
  VecH     ZrU, ZrdU, GrU, GrdU, mU, mdU, pU, pdU, CU[kRing], CdU[kRing];
  struct {
    bool      ref = false;
    PetscInt  n   = 0;                       // crossings so far, Z_r the first; crossing i in slot i % kRing
    PetscReal t = 0, h = 0, s = 0, dmax = 0; // time since Z_r, step, last G_r.(Z - Z_r), largest |Z - Z_r|
    PetscReal tc[kRing] = {0};
    std::vector<std::pair<PetscReal, int>> periods; // (period, loops) per crossing from the fourth on
  } sec;
  size_t seen_ = 0; // periods that Measured has seen
};

PetscErrorCode SectionPeriod::SetRef(Vec U1, Vec dU1, const Eigen::VectorXd &rr)
{
  PetscFunctionBeginUser;
  PetscCall(VecCopy(U1, ZrU));
  PetscCall(VecCopy(dU1, ZrdU));
  PetscCall(VecCopy(U1, CU[0]));
  PetscCall(VecCopy(dU1, CdU[0]));
  PetscCall(field_(U1, dU1, rr, GrU, GrdU));
  sec.ref = true, sec.n = 1, sec.t = sec.s = sec.dmax = sec.tc[0] = 0;
  PetscFunctionReturn(0);
}

// |C_a - C_b| for the crossings a and b back from the last (0: the last).
PetscErrorCode SectionPeriod::Dist(int a, int b, PetscReal *d)
{
  const int i = (int)((sec.n - 1 - a) % kRing), j = (int)((sec.n - 1 - b) % kRing);
  PetscReal n1, n2;
  PetscFunctionBeginUser;
  PetscCall(VecWAXPY(mU, -1.0, CU[i], CU[j]));
  PetscCall(VecWAXPY(mdU, -1.0, CdU[i], CdU[j]));
  PetscCall(VecNorm(mU, NORM_2, &n1));
  PetscCall(VecNorm(mdU, NORM_2, &n2));
  *d = std::hypot(n1, n2);
  PetscFunctionReturn(0);
}

// A crossing in the step from the previous state (pU, pdU; G_r.(Z - Z_r) = sec.s) to (U1, dU1; s):
// stored, and from the fourth on the period with its loop count.
PetscErrorCode SectionPeriod::Crossing(Vec U1, Vec dU1, PetscReal s)
{
  PetscFunctionBeginUser;
  const PetscReal th = sec.s / (sec.s - s); // of the step, from the previous state
  const int       j  = (int)(sec.n % kRing);
  PetscCall(VecAXPBYPCZ(CU[j], 1 - th, th, 0.0, pU, U1));
  PetscCall(VecAXPBYPCZ(CdU[j], 1 - th, th, 0.0, pdU, dU1));
  sec.tc[j] = sec.t - (1 - th) * sec.h;
  if (++sec.n >= kRing) {
    PetscReal d01, d12, d23, d02, d13, d03;
    PetscCall(Dist(0, 1, &d01));
    PetscCall(Dist(1, 2, &d12));
    PetscCall(Dist(2, 3, &d23));
    PetscCall(Dist(0, 2, &d02));
    PetscCall(Dist(1, 3, &d13));
    PetscCall(Dist(0, 3, &d03));
    const PetscReal r1 = std::max(std::min(d01, d12), std::min(std::max(d01, d12), d23)); // the median
    const int       m  = std::max(d02, d13) < kLoop * r1 ? 2 : d03 < kLoop * r1 ? 3 : 1;
    sec.periods.push_back({sec.tc[j] - sec.tc[(sec.n - 1 - m) % kRing], m});
  }
  PetscFunctionReturn(0);
}

PetscErrorCode SectionPeriod::Step(Vec U1, Vec dU1, const Eigen::VectorXd &rr)
{
  PetscScalar a1, a2;
  PetscReal   n1, n2;
  PetscFunctionBeginUser;
  if (!sec.ref || sec.t - sec.tc[(sec.n - 1) % kRing] > 4 * steps_ * sec.h) PetscCall(SetRef(U1, dU1, rr));
  else {
    sec.t += sec.h;
    PetscCall(VecWAXPY(mU, -1.0, ZrU, U1));
    PetscCall(VecWAXPY(mdU, -1.0, ZrdU, dU1));
    // One reduction for the four.
    PetscCall(VecDotBegin(mU, GrU, &a1));
    PetscCall(VecDotBegin(mdU, GrdU, &a2));
    PetscCall(VecNormBegin(mU, NORM_2, &n1));
    PetscCall(VecNormBegin(mdU, NORM_2, &n2));
    PetscCall(VecDotEnd(mU, GrU, &a1));
    PetscCall(VecDotEnd(mdU, GrdU, &a2));
    PetscCall(VecNormEnd(mU, NORM_2, &n1));
    PetscCall(VecNormEnd(mdU, NORM_2, &n2));
    const PetscReal s = PetscRealPart(a1 + a2), d = std::hypot(n1, n2);
    sec.dmax          = std::max(sec.dmax, d);
    if (sec.s < 0 && s >= 0 && d < kReturn * sec.dmax) PetscCall(Crossing(U1, dU1, s));
    sec.s = s;
  }
  PetscCall(VecCopy(U1, pU));
  PetscCall(VecCopy(dU1, pdU));
  PetscFunctionReturn(0);
}

bool SectionPeriod::Measured(PetscReal &Tm, int &loops)
{
  const size_t n = sec.periods.size();
  if (n <= seen_) return false;
  seen_         = n;
  const auto &p = sec.periods;
  Tm = n >= 2 && p[n - 1].second == p[n - 2].second && std::abs(p[n - 1].first - p[n - 2].first) < kAgree * p[n - 1].first
       ? p[n - 1].first
       : 0;
  if (Tm > 0) loops = p[n - 1].second;
  return Tm > 0;
}

// The return distance after a period of the flow from Z = (U, dU) to Z1 = (U1, dU1), whose vector
// field is G = (gU, gdU), with the period corrected to first order along G:
// dt = -G.(Z1 - Z)/|G|^2, e = |Z1 - Z + dt G| / |Z1| (the residual Newton would see at T + dt).
// (wU, wdU): work.
PetscErrorCode ReturnDistance(Vec U, Vec dU, Vec U1, Vec dU1, Vec gU, Vec gdU, Vec wU, Vec wdU, PetscReal *dt, PetscReal *e)
{
  PetscScalar a1, a2, b1, b2;
  PetscReal   n1, n2;
  PetscFunctionBeginUser;
  PetscCall(VecWAXPY(wU, -1.0, U, U1));
  PetscCall(VecWAXPY(wdU, -1.0, dU, dU1));
  PetscCall(VecDot(wU, gU, &a1));
  PetscCall(VecDot(wdU, gdU, &a2));
  PetscCall(VecDot(gU, gU, &b1));
  PetscCall(VecDot(gdU, gdU, &b2));
  *dt = PetscRealPart(b1 + b2) > 0 ? -PetscRealPart(a1 + a2) / PetscRealPart(b1 + b2) : 0.0;
  PetscCall(VecAXPY(wU, *dt, gU));
  PetscCall(VecAXPY(wdU, *dt, gdU));
  PetscCall(VecNorm(wU, NORM_2, &n1));
  PetscCall(VecNorm(wdU, NORM_2, &n2));
  const PetscReal d = std::hypot(n1, n2);
  PetscCall(VecNorm(U1, NORM_2, &n1));
  PetscCall(VecNorm(dU1, NORM_2, &n2));
  *e = d / std::hypot(n1, n2);
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode Shooting::PrePeriods(Vec U0, Vec dU0, PetscReal T0, PetscReal tol, Vec x)
{
  const bool resume = pre_done_ > 0; // a -shoot_pre_retries restart: the period was measured already
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(shoot_ev::pre, 0, 0, 0, 0));
  // Where the cycle's shape is far from the unstable mode's (many contacts with separation and
  // stick), periods of the flow bring the start into the attracting cycle's neighbourhood. After
  // each period the return distance is read with the period corrected to first order
  // (ReturnDistance). It stops once e < -shoot_pre_tol (and the period measured along the way,
  // SectionPeriod, holds) and starts Newton at T + dt. Beyond the first-order correction's reach
  // (kReach) the start period and the bracket move onto the measured period.
  constexpr PetscReal kReach = 0.05;
  VecH                U, dU;
  Eigen::VectorXd     r;
  // The pre-periods run at -shoot_pre_steps a period until they return within the tolerance, then
  // on at -shoot_steps until they return within it again (3-4 periods on the pads), so that Newton
  // starts from a return of the flow whose cycle it solves for: on the half brake a start a few
  // 1e-3 of a period off was enough to leave Newton's basin (docs/records.md). A restart after a
  // failed Newton runs at -shoot_steps throughout. Flow and SetUpAt read `steps`: swapped for this
  // frame (also on an error), with the step size set up again on each side of the swap.
  struct StepsSwap {
    Shooting &s;
    PetscInt  kept;
    StepsSwap(Shooting &sh, PetscInt n) : s(sh), kept(sh.steps)
    {
      if (n != kept) s.steps = n, s.T_setup_ = -1;
    }
    bool Coarse() const { return s.steps != kept; }
    void Restore()
    {
      if (s.steps != kept) s.steps = kept, s.T_setup_ = -1;
    }
    ~StepsSwap() { Restore(); }
  } swap{*this, resume || pre_steps <= 0 ? steps : pre_steps};
  PetscInt            coarse_periods = 0; // run at -shoot_pre_steps, once the flow went on at -shoot_steps
  // The contact problems of these flows to -shoot_pre_fp_tol, restored for Newton (also on an error).
  struct FixedPointLoose {
    ThetaIntegrator &ti;
    const PetscReal  kept;
    const PetscInt   max_it;
    FixedPointLoose(ThetaIntegrator &t, PetscReal loose) : ti(t), kept(t.FixedPointTolerance()), max_it(t.FixedPointMaxIt())
    {
      if (loose > kept) (void)ti.SetFixedPoint(loose, max_it); // valid: positive, as -shoot_pre_fp_tol is checked to be
    }
    ~FixedPointLoose() { (void)ti.SetFixedPoint(kept, max_it); }
    PetscReal Tol() const { return ti.FixedPointTolerance(); }
  } loose{*ti_, pre_fp_tol};
  PetscBool           mon = PETSC_FALSE;
  PetscCall(PetscOptionsHasName(nullptr, "shoot_", "-snes_monitor", &mon));
  mon = (PetscBool)(mon || monitor);
  PetscCall(VecDuplicate(U0, U.out()));
  PetscCall(VecDuplicate(dU0, dU.out()));
  PetscCall(VecCopy(U0, U));
  PetscCall(VecCopy(dU0, dU));
  SectionPeriod sec;
  PetscCall(sec.Create(U0, dU0, steps, [this](Vec a, Vec b, const Eigen::VectorXd &rr, Vec g, Vec gd) { return VectorField(a, b, rr, g, gd); }));
  on_step_ = [&](PetscInt, Vec U1, Vec dU1, const Eigen::VectorXd &rr) -> PetscErrorCode { return sec.Step(U1, dU1, rr); };
  struct Unhook {
    std::function<PetscErrorCode(PetscInt, Vec, Vec, const Eigen::VectorXd &)> &f;
    ~Unhook() { f = nullptr; } // also on an error: the hook refers to this frame
  } unhook{on_step_};

  PetscReal T = T0, e = kInf;
  // The period the flow integrates over: it follows the estimate T only when T has moved from it by
  // more than -shoot_pre_drift times the last return distance. Each new period is a new step size,
  // and the step's set-up (A^-1 B, A^-1 K, A^-1 H: O(N^3) where C is not diagonal in the modal
  // basis) cost 0.72 s against 0.27 s for the period's flow on the size-1 brake example (N = 1858):
  // 50 set-ups, 36 of the pre-periods' 48 s. The return distance is corrected to first order from
  // the period the flow ran to the estimate, but that correction is not exact across impacts: a lag
  // of 1e-3 T read 1.8e-2 where the flow at T read 7.8e-3. In proportion to the distance, the
  // error stays a fraction of what it measures; and at most kMaxLag of the period whatever that is.
  // Not in the fine periods after the coarse ones (-shoot_pre_steps): they hand Newton its start.
  // The discrete flow has cycles a step's event apart, and Newton from a lagging fine flow reached
  // one farther from the transient's on the 562-DOF pad: 8832.0771 Hz, against 8832.1055 from the
  // exact fine periods (8832.0995 before this option) and the transient's 8832.108.
  constexpr PetscReal kMaxLag = 2e-3;
  PetscReal           Tf      = T0;
  const bool          two_phases = swap.Coarse();
  std::vector<PetscReal> growths;  // each period's relative energy change, for -shoot_pre_boost
  PetscReal              gmax = 0; // ... the largest
  int                    boosting = 0; // 0: not yet, 1: on, -1: over
  constexpr int          kSteady = 5;
  constexpr PetscReal    kSpread = 1.5, kLinear = 0.75, kMaxBoost = 1.05, kAfterBoost = 0.3;
  PetscInt  k = 0;
  PetscReal Tm    = 0; // the last measured period, once it agrees with the one before (0: not, or not yet)
  int       loops = 1;
  // The return distances since the start period last moved, for -shoot_pre_stagnation.
  const PetscInt         W = pre_stagnation > 0 ? pre_stagnation : 0;
  std::vector<PetscReal> hist;
  PetscReal              best_recent = 0, best_before = 0;
  bool                   stagnated = false;
  while (k < pre_periods) {
    if (interruptible) PetscCall(InterruptPoint(comm_, "shooting's pre-periods"));
    const PetscReal lag = two_phases && !swap.Coarse() ? 0.0 : std::min(pre_drift * e, kMaxLag); // e: the last return distance (inf before the first)
    if (!(std::abs(T - Tf) <= lag * T)) Tf = T;
    sec.SetStep(Tf, steps);
    PetscReal E0, E1;
    PetscCall(DeviationEnergy(U, dU, &E0));
    PetscCall(Flow(U, dU, Tf, U1_, dU1_, &r, nullptr));
    PetscCall(DeviationEnergy(U1_, dU1_, &E1));
    const PetscReal growth = E0 > 0 ? E1 / E0 - 1 : 0;
    ++k;
    pre_passes_ += flow_passes_, pre_steps_run_ += steps;
    PetscCall(VectorField(U1_, dU1_, r, gU_, gdU_));
    PetscReal dt = 0;
    PetscCall(ReturnDistance(U, dU, U1_, dU1_, gU_, gdU_, wU_, wdU_, &dt, &e));
    PetscCall(VecCopy(U1_, U));
    PetscCall(VecCopy(dU1_, dU));
    // -shoot_pre_boost b: the period's energy change (1 + g) raised to 1 + b by scaling the deviation
    // from Z_e, so that the flow's slow drift along the cycle's amplitude runs 1 + b times faster;
    // the cycle (g = 0) is left as it is. Near the threshold a start on the growing side (g > 0)
    // sends Newton to Z_e (the brake example at size 1: g = +8.5e-3, 2 sigma T = 9.1e-3 after 9
    // pre-periods, and Newton's corrections halve |U - U_e| at every iteration).
    // Only from a flow still in its linear growth: the last kSteady periods' gains within a factor
    // kSpread of each other and at least kLinear of the largest so far (the 562-DOF pad's flow is
    // past that: it gains 1e-2 a period after 2.6e-2 in its first, and its Newton converges from
    // there); then on while the flow gains energy, never again once it stops.
    PetscCallCXX(growths.push_back(std::isfinite(growth) ? growth : 0));
    gmax = std::max(gmax, growths.back());
    if (pre_boost > 0 && boosting == 0 && growths.size() >= (size_t)kSteady) {
      PetscReal lo = kInf, hi = 0;
      for (size_t i = growths.size() - kSteady; i < growths.size(); ++i) lo = std::min(lo, growths[i]), hi = std::max(hi, growths[i]);
      if (lo > 0 && hi < kSpread * lo && lo >= kLinear * gmax) boosting = 1;
    }
    if (boosting == 1 && !(growths.back() > 0)) boosting = -1;
    PetscReal boost = 1;
    if (boosting == 1) {
      boost = std::min(std::pow(1 + growths.back(), 0.5 * pre_boost), kMaxBoost);
      PetscCall(VecAXPBY(U, 1 - boost, boost, Ue_)); // U = U_e + boost (U - U_e)
      PetscCall(VecScale(dU, boost));
    }
    if (mon)
      PetscCall(PetscPrintf(comm_, "  pre-period %3" PetscInt_FMT ": return distance %.3e at T + dt = %.9f s, energy %+.2e (x %.4f), %.1f contact iterations a step\n", k,
                            (double)e, (double)(Tf + dt), (double)growth, (double)boost, (double)flow_passes_ / steps));
    if (sec.Measured(Tm, loops) && !resume) pre_measured_ = Tm;
    // Not on a restart: the motion has returned within -shoot_pre_tol at T with its period measured,
    // and so close to the cycle the section's loop count reads noise (the half brake's interface-
    // reduced flow at return distances of 2e-3: 1, 2 and 3 loops in turn, the period moved
    // between T and 2 T six times).
    if (!resume && Tm > 0 && std::abs(Tm - T) > kReach * T) {
      PetscCall(PetscPrintf(comm_,
                            "shooting: after %" PetscInt_FMT " pre-period(s) the motion returns to its Poincare section every %.7f s "
                            "(%d loop(s), %.3f x the start period %.7f s): start period and bracket (T/2, 2 T) = (%.6g, %.6g) s moved there\n",
                            k, (double)Tm, loops, (double)(Tm / T0), (double)T0, (double)(0.5 * Tm), (double)(2 * Tm)));
      T = Tf = T0_ = Tm, recentred_ = true;
      hist.clear();
      continue; // this period's return distance was read at the old period
    }
    // The corrected period is used from here on only while it stays near the bracket's centre: far
    // from the cycle the first-order correction can be large and meaningless.
    if (std::abs(dt) < kReach * T0_) T = Tf + dt;
    // Not before the measured period holds (two returns agree, and it is near T): early in a growing
    // motion the flow can come back close at the linear period (case 1 at mu = 5: 2.4e-2 after 2
    // periods) and settle elsewhere, and a single return can still read one loop of a cycle that
    // closes after two (there, stopping at the first return near T sent Newton to the unstable
    // one-loop cycle at 0.0096261 s instead of the attracting one at 0.0193433 s).
    // Not while boosted: such a flow returns within the tolerance only because it grows slowly, and
    // Newton from the growing side heads for Z_e.
    // After a boost, kAfterBoost of the tolerance: that flow is near the threshold, where Newton's
    // basin is small.
    if (e < (boosting == -1 ? kAfterBoost * tol : tol) && (Tm > 0 || resume) && boosting != 1) {
      if (!swap.Coarse()) break;
      coarse_periods = k;
      swap.Restore();
      continue;
    }
    // A flow on its way to a cycle halves its return distance in far fewer than W periods (the pads'
    // flows reach 0.02 in 22-38); one that does not return wanders at the same distances. Not after
    // a coarse return: the fine flow hovers near the tolerance (the half brake: 30 periods) and
    // has returned already, which -analyses auto must not read as a flow that does not.
    if (W > 0 && coarse_periods == 0) {
      PetscCallCXX(hist.push_back(e));
      const size_t n = hist.size(), w = (size_t)W;
      if (n >= 2 * w) {
        best_recent = *std::min_element(hist.end() - (long)w, hist.end());
        best_before = *std::min_element(hist.begin(), hist.end() - (long)w);
        if (best_recent > 0.5 * best_before) {
          stagnated = true;
          PetscCall(PetscPrintf(comm_,
                                "shooting: pre-periods stopped after %" PetscInt_FMT " period(s): the return distance stagnates (best %.2e in the last %" PetscInt_FMT
                                ", %.2e before; -shoot_pre_stagnation %" PetscInt_FMT ")\n",
                                k, (double)best_recent, W, (double)best_before, W));
          break;
        }
      }
    }
  }
  const PetscInt ncoarse = swap.Coarse() ? k : coarse_periods; // a flow that never returned stayed coarse
  pre_coarse_ += ncoarse;
  char coarse[96] = "";
  if (ncoarse > 0) std::snprintf(coarse, sizeof coarse, "; the first %" PetscInt_FMT " at -shoot_pre_steps %" PetscInt_FMT, ncoarse, pre_steps);
  if (pre_done_ == 0)
    PetscCall(PetscPrintf(comm_,
                          "shooting: start after %" PetscInt_FMT " period(s) of the flow from the given state (-shoot_pre_periods %" PetscInt_FMT
                          ", -shoot_pre_tol %g%s): return distance %.2e, T = %.9f s, %.1f contact iterations a step (to %g, -shoot_pre_fp_tol)\n",
                          k, pre_periods, (double)tol, coarse, (double)e, (double)T, (double)PreContactIterations(), (double)loose.Tol()));
  else
    PetscCall(PetscPrintf(comm_,
                          "shooting: start after %" PetscInt_FMT " more period(s) of the flow (up to %" PetscInt_FMT
                          ", return distance tolerance %g): return distance %.2e, T = %.9f s\n",
                          k, pre_periods, (double)tol, (double)e, (double)T));
  // Returned: on the fine flow, or on the coarse one when -shoot_pre_periods ran out before the fine
  // flow came back within the tolerance (Newton then starts from the fine flow's last state).
  pre_done_ += k, pre_T_ = T, pre_e_ = e, pre_returned_ = (e < tol && (Tm > 0 || resume)) || coarse_periods > 0;
  pre_stagnated_ = stagnated, pre_best_recent_ = best_recent, pre_best_before_ = best_before;
  PetscCall(PetscLogEventEnd(shoot_ev::pre, 0, 0, 0, 0));
  PetscCall(Pack(U, dU, T, x));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::DeviationEnergy(Vec U, Vec dU, PetscReal *E)
{
  PetscScalar a, b;
  PetscFunctionBeginUser;
  PetscCall(VecWAXPY(tmp_, -1.0, Ue_, U));
  PetscCall(MatMult(model_->K, tmp_, wU_));
  PetscCall(VecDot(tmp_, wU_, &a));
  PetscCall(MatMult(model_->M, dU, wdU_));
  PetscCall(VecDot(dU, wdU_, &b));
  *E = 0.5 * PetscRealPart(a + b);
  PetscFunctionReturn(0);
}

} // namespace squeal
