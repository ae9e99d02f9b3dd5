#include "squeal/energy/energy.h"
#include "squeal/core/inf.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/errors.h"
#include "squeal/core/options.h"
#include "squeal/integration/theta.h"
#include "squeal/shooting/shooting.h"

#include <cmath>
#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif
#include <limits>

namespace squeal {

PetscErrorCode EnergyAnalysis::SetFromOptions()
{
  OptionChecks checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, "energy_", "Energy estimate of the limit-cycle amplitude", "EnergyAnalysis");
  PetscCall(PetscOptionsInt("-mode", "Mode to estimate (index in the eigenvalue table; -1: most unstable)", "EnergyAnalysis",
                            mode, &mode, nullptr));
  PetscCall(PetscOptionsInt("-n_scan", "Points of the amplitude scan", "EnergyAnalysis", n_scan, &n_scan, nullptr));
  PetscCall(PetscOptionsInt("-samples", "Time samples per period for the mean powers", "EnergyAnalysis", samples, &samples, nullptr));
  PetscCall(PetscOptionsInt("-bisections", "After the scan the balance is bracketed to 2^-n of the scan's step (regula falsi, Illinois)", "EnergyAnalysis", bisections, &bisections, nullptr));
  SquealOptionsReal("-q_max_factor", "Scan up to this multiple of the first lift-off amplitude", "EnergyAnalysis", &q_max_factor,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-extend", "Doublings of the scan range when it holds no balance", "EnergyAnalysis", extend, &extend,
                            nullptr));
  PetscCall(PetscOptionsBool("-all_modes", "Estimate every unstable mode (one line each), not only the chosen one",
                             "EnergyAnalysis", all_modes, &all_modes, nullptr));
  PetscCall(PetscOptionsBool("-impacts", "Impact losses in the balance: the tensile impulse the separated points miss, lost at re-contact",
                             "EnergyAnalysis", impacts, &impacts, nullptr));
  PetscCall(PetscOptionsInt("-impact_steps", "Steps per period of the Delassus operator of the impact losses (-1: shooting's default for the model)",
                            "EnergyAnalysis", impact_steps, &impact_steps, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  // -7 ran as -1 (the most unstable mode) without a word.
  PetscCheck(mode >= -1, comm_, kErrInput, "option -energy_mode = %" PetscInt_FMT ": expected a mode index >= 0, or -1 for the most unstable mode",
             mode);
  PetscCheck(impact_steps == PETSC_DECIDE || impact_steps >= 1, comm_, kErrInput,
             "option -energy_impact_steps = %" PetscInt_FMT ": expected >= 1, or -1 for shooting's default", impact_steps);
  PetscCheck(n_scan >= 2 && samples >= 8 && bisections >= 0 && extend >= 0, comm_, kErrInput,
             "energy: need -energy_n_scan >= 2, -energy_samples >= 8, -energy_bisections >= 0, -energy_extend >= 0");
  PetscFunctionReturn(0);
}

namespace {

// One point's motion over the period: r_n = N + pr cos - pi sin, u_t = tr sin + ti cos, u_b = br sin + bi cos.
struct PointMotion {
  PetscReal N, pr, pi, tr, ti, br, bi, V;
};

// Largest squared slip speed the fast kernel takes (float's range is 3.4e38); none without AVX2
// and FMA, where Eigen's expression is the faster.
#if defined(__AVX2__) && defined(__FMA__)
constexpr PetscReal kPlanarFastMax = 1e30;
#else
constexpr PetscReal kPlanarFastMax = 0;
#endif

// sum over the samples of max(r_n, 0) (s_t u_t - u_b^2) / sqrt(s_t^2 + u_b^2), s_t = V - u_t: the
// planar law's sliding power. A vector divide and square root cost 14 cycles for 4 samples on this
// machine, most of the scan (docs/records.md "Energy scan"). Instead: a single-precision estimate
// y of 1/sqrt(m2) (|y sqrt(m2) - 1| <= 1.5 2^-12, so e = 1 - m2 y^2 within 7.3e-4) and the series
// of (1 - e)^-1/2 to e^4 in double: the first term left out is 5e-17, below the rounding of e
// itself (two Newton steps would leave 6e-14; three cost more). m2 is floored at 1e-36, inside
// float's normal range: below a slip speed of 1e-18 m/s, where the friction direction jumps
// anyway, the term is scaled down instead of divided by zero (0 at exactly no slip, as the
// other paths give).
PetscReal PlanarArcSum(const PetscReal *c, const PetscReal *s, Eigen::Index n, const PointMotion &m)
{
  Eigen::Index i   = 0;
  PetscReal    sum = 0;
#if defined(__AVX2__) && defined(__FMA__)
  const __m256d N = _mm256_set1_pd(m.N), pr = _mm256_set1_pd(m.pr), pi = _mm256_set1_pd(m.pi), tr = _mm256_set1_pd(m.tr);
  const __m256d ti = _mm256_set1_pd(m.ti), br = _mm256_set1_pd(m.br), bi = _mm256_set1_pd(m.bi), V = _mm256_set1_pd(m.V);
  const __m256d zero = _mm256_setzero_pd(), floor = _mm256_set1_pd(1e-36), one = _mm256_set1_pd(1.0);
  // (1 - e)^-1/2 = 1 + e/2 + 3e^2/8 + 5e^3/16 + 35e^4/128 + ...: with |e| <= 7.3e-4 the first term
  // left out, 63e^5/256, is 5e-17.
  const __m256d c1 = _mm256_set1_pd(0.5), c2 = _mm256_set1_pd(0.375), c3 = _mm256_set1_pd(0.3125), c4 = _mm256_set1_pd(0.2734375);
  __m256d acc = zero;
  for (; i + 4 <= n; i += 4) {
    const __m256d C  = _mm256_loadu_pd(c + i), S = _mm256_loadu_pd(s + i);
    const __m256d rn = _mm256_fmadd_pd(pr, C, _mm256_fnmadd_pd(pi, S, N));
    const __m256d ut = _mm256_fmadd_pd(tr, S, _mm256_mul_pd(ti, C));
    const __m256d ub = _mm256_fmadd_pd(br, S, _mm256_mul_pd(bi, C));
    const __m256d st = _mm256_sub_pd(V, ut), ub2 = _mm256_mul_pd(ub, ub);
    const __m256d num = _mm256_fmsub_pd(st, ut, ub2);
    const __m256d m2  = _mm256_max_pd(_mm256_fmadd_pd(st, st, ub2), floor);
    const __m256d y   = _mm256_cvtps_pd(_mm_rsqrt_ps(_mm256_cvtpd_ps(m2)));
    const __m256d e   = _mm256_fnmadd_pd(_mm256_mul_pd(m2, y), y, one); // 1/sqrt(m2) = y (1 - e)^-1/2
    __m256d       t   = _mm256_fmadd_pd(c4, e, c3);
    t                 = _mm256_fmadd_pd(t, e, c2);
    t                 = _mm256_fmadd_pd(t, e, c1);
    t                 = _mm256_fmadd_pd(t, e, one);
    acc               = _mm256_fmadd_pd(_mm256_mul_pd(_mm256_mul_pd(_mm256_max_pd(rn, zero), num), y), t, acc);
  }
  alignas(32) PetscReal lanes[4];
  _mm256_store_pd(lanes, acc);
  sum = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
#endif
  for (; i < n; ++i) {
    const PetscReal rn = m.N + m.pr * c[i] - m.pi * s[i], ut = m.tr * s[i] + m.ti * c[i], ub = m.br * s[i] + m.bi * c[i];
    const PetscReal st = m.V - ut, m2 = st * st + ub * ub;
    if (rn > 0 && m2 > 0) sum += rn * (st * ut - ub * ub) / std::sqrt(m2);
  }
  return sum;
}

} // namespace

void EnergyAnalysis::Powers(PetscReal q, PetscReal *P_R, PetscReal *P_I, std::vector<PetscReal> *J) const
{
  using Arr                     = Eigen::Array<PetscReal, Eigen::Dynamic, 1>;
  const ContactSet &cs          = *cs_;
  const bool        rectilinear = cs.law == FrictionLaw::Rectilinear;
  const Eigen::Index ns         = (Eigen::Index)cos_.size();
  const bool        impacts     = Wn_.size() > 0 || J;
  const Eigen::Map<const Arr> C(cos_.data(), ns), S(sin_.data(), ns);
  // sqrt(max(m2, tiny)) instead of a test: the numerator is 0 where m2 is (st = ub = 0).
  const PetscReal tiny = std::numeric_limits<PetscReal>::min();
  PetscReal       sum  = 0;
  if (impacts) J_.assign(N_.size(), 0.0);
  // Points outside, samples inside, each point's samples as one branch-free array expression that
  // Eigen evaluates in one SIMD pass. The scan calls this n_scan + bisections times, samples x
  // points each: 1.4e9 evaluations for the 175-point pad, 3.6 s as a scalar loop with branches.
  const PetscReal dtheta = 2 * PETSC_PI / ns;
  for (size_t p = 0; p < N_.size(); ++p) {
    const PetscReal pr = q * psi_[p].real(), pi = q * psi_[p].imag(), Np = N_[p], V = speed_[p];
    const PetscReal tr = -q * omega_ * phit_[p].real(), ti = -q * omega_ * phit_[p].imag();
    const PetscReal br = -q * omega_ * phib_[p].real(), bi = -q * omega_ * phib_[p].imag();
    // The fast kernel's first guess of 1/sqrt is in single precision: only while the squared slip
    // speed, at most (|V| + |u_t|)^2 + |u_b|^2, stays well inside float's range.
    const PetscReal m2_max      = std::pow(std::abs(V) + std::hypot(tr, ti), 2) + std::pow(std::hypot(br, bi), 2);
    const bool      fast_planar = m2_max < kPlanarFastMax;
    // Re(z e^{i w t}) = Re z cos - Im z sin; velocity Re(i w z e^{i w t}) = -w (Re z sin + Im z cos).
    const auto sliding = [&](Eigen::Index a, Eigen::Index len) {
      if (!rectilinear && fast_planar)
        return PlanarArcSum(cos_.data() + a, sin_.data() + a, len, {Np, pr, pi, tr, ti, br, bi, V});
      const auto Cs = C.segment(a, len), Ss = S.segment(a, len);
      const auto rn = Np + pr * Cs - pi * Ss;
      const auto ut = tr * Ss + ti * Cs;
      const auto st = V - ut; // surface velocity relative to the structure
      if (rectilinear) return (rn.max(0) * st.sign() * ut).sum();
      const auto ub = br * Ss + bi * Cs;
      return (rn.max(0) * (st * ut - ub * ub) / (st * st + ub * ub).max(tiny).sqrt()).sum();
    };
    // rn = N + q |psi| cos(theta + arg psi) is positive on one arc of the period and friction is 0
    // off it: sum over that arc, widened by 2 samples each side, where max(rn, 0) decides as it
    // would over the whole period. The same sum without the separated samples' zeros: the scan to
    // 50 q_sep finds the first points to lift off separated for up to half the period
    // (docs/records.md "Energy scan": 3.3 -> 2.3 s on the 562-DOF pad). Likewise the tension
    // max(-rn, 0) of the impact losses, over the other arc. over_arc takes the samples of the angles
    // [lo, hi] widened by 2 each side: one segment, or two round theta = 0.
    const auto over_arc = [&](PetscReal lo, PetscReal hi, const auto &f) {
      const auto i0 = (Eigen::Index)std::floor(lo / dtheta) - 2, i1 = (Eigen::Index)std::ceil(hi / dtheta) + 2;
      if (i1 - i0 + 1 >= ns) return f(0, ns);
      const Eigen::Index a = ((i0 % ns) + ns) % ns, len = i1 - i0 + 1, first = std::min(len, ns - a);
      return first < len ? f(a, first) + f(0, len - first) : f(a, first);
    };
    const auto tension = [&](Eigen::Index a, Eigen::Index len) {
      return (-(Np + pr * C.segment(a, len) - pi * S.segment(a, len))).max(0).sum();
    };
    const PetscReal rho = std::hypot(pr, pi);
    PetscReal       jp  = 0; // the sum of the tension samples max(-r_n, 0)
    if (rho > 0 && Np < rho && Np > -rho) {
      // Closed on theta + alpha in (-beta, beta), open on (beta, 2 pi - beta).
      const PetscReal alpha = std::atan2(pi, pr), beta = std::acos(-Np / rho);
      sum += over_arc(-alpha - beta, -alpha + beta, sliding);
      if (impacts) jp = over_arc(beta - alpha, 2 * PETSC_PI - alpha - beta, tension);
    } else if (Np >= rho) sum += sliding(0, ns); // closed all the period (rho = 0 included): no tension
    else if (impacts) jp = tension(0, ns);     // open all the period: no friction
    if (impacts) J_[p] = jp * period_ / ns;
  }
  *P_R = cs.Mu() * sum / ns;
  *P_I = 0;
  if (Wn_.size() > 0) {
    const Eigen::Map<const Eigen::VectorXd> j(J_.data(), (Eigen::Index)J_.size());
    *P_I = 0.5 * j.dot(Wn_ * j) / period_;
  }
  if (J) *J = J_;
}

PetscErrorCode EnergyAnalysis::Scan(PetscReal factor, EnergyEstimate &est, bool *found) const
{
  PetscFunctionBeginUser;
  *found = false;
  const PetscReal q_max = factor * est.q_sep;
  // A signal is seen every ~1e7 contact evaluations (0.1 s or less): a fine scan of the reduced
  // small pad (-energy_n_scan 40000) ran 83 s deaf. Counted, not timed, so every rank polls at
  // the same point.
  const PetscInt poll_every = PetscMax((PetscInt)1, (PetscInt)(1e7 / PetscMax((double)(cos_.size() * N_.size()), 1.0)));
  est.q.resize(n_scan);
  est.P_damping.resize(n_scan);
  est.P_reactions.resize(n_scan);
  est.P_impacts.assign(est.impacts ? n_scan : 0, 0.0);
  std::vector<PetscReal> f(n_scan);
  PetscInt crossing = -1;
  for (PetscInt k = 0; k < n_scan; ++k) {
    const PetscReal q = (k + 1) * q_max / n_scan;
    est.q[k]          = q;
    est.P_damping[k]  = 0.5 * q * q * omega_ * omega_ * cphi_;
  }
  if (full_scan) {
    // The whole curve is asked for: its amplitudes shared round the ranks (every rank holds the
    // model's contact data), each power summed from one rank and zeros, so the same on every rank.
    PetscMPIInt rank, size;
    PetscCallMPI(MPI_Comm_rank(comm_, &rank));
    PetscCallMPI(MPI_Comm_size(comm_, &size));
    std::fill(est.P_reactions.begin(), est.P_reactions.end(), 0.0);
    for (PetscInt k = 0; k < n_scan; ++k) {
      if (k % poll_every == 0) PetscCall(InterruptPoint(comm_, "the energy scan"));
      if (k % size != rank) continue;
      PetscReal P_I;
      Powers(est.q[k], &est.P_reactions[k], &P_I);
      if (est.impacts) est.P_impacts[k] = P_I;
    }
    if (size > 1) {
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, est.P_reactions.data(), (PetscMPIInt)n_scan, MPIU_REAL, MPIU_SUM, comm_));
      if (est.impacts) PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, est.P_impacts.data(), (PetscMPIInt)n_scan, MPIU_REAL, MPIU_SUM, comm_));
    }
  }
  for (PetscInt k = 0; k < n_scan; ++k) {
    if (!full_scan) {
      if (k % poll_every == 0) PetscCall(InterruptPoint(comm_, "the energy scan"));
      PetscReal P_I;
      Powers(est.q[k], &est.P_reactions[k], &P_I);
      if (est.impacts) est.P_impacts[k] = P_I;
    }
    f[k] = est.P_reactions[k] - est.P_damping[k] - (est.impacts ? est.P_impacts[k] : 0.0);
    if (crossing < 0 && k > 0 && f[k - 1] > 0 && f[k] <= 0) crossing = k - 1;
    if (crossing >= 0 && !full_scan) {
      est.q.resize(k + 1), est.P_damping.resize(k + 1), est.P_reactions.resize(k + 1);
      if (est.impacts) est.P_impacts.resize(k + 1);
      break;
    }
  }
  // Already saturated at the first scan point (a fine structure of f below q_max / n_scan): the
  // balance lies in (0, q_1]; f > 0 near 0 for an unstable mode, so bisect there.
  PetscReal lo = 0, hi = 0, f_lo = 0, f_hi = 0;
  if (crossing >= 0) lo = est.q[crossing], hi = est.q[crossing + 1], f_lo = f[crossing], f_hi = f[crossing + 1];
  else if (f[0] <= 0 && (f_lo = PowerBalance(1e-6 * est.q[0])) > 0) {
    lo = 1e-6 * est.q[0], hi = est.q[0], f_hi = f[0];
    crossing = 0;
  }
  if (crossing < 0) PetscFunctionReturn(0);
  est.q0 = BracketedRoot([this](PetscReal q) { return PowerBalance(q); }, lo, f_lo, hi, f_hi, bisections);
  *found = true;
  PetscFunctionReturn(0);
}

PetscErrorCode EnergyAnalysis::AgreeOnScan(EnergyEstimate &est) const
{
  PetscMPIInt size;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  if (size == 1) PetscFunctionReturn(0);
  // Every rank scans the same data, but the planar kernel's first guess of 1/sqrt comes from the
  // CPU's own table (vendors differ in its last bits), so on a mixed cluster a bisection could end
  // a bit apart from rank to rank: rank 0's scan holds for all.
  PetscInt found = est.found;
  PetscCallMPI(MPI_Bcast(&found, 1, MPIU_INT, 0, comm_));
  est.found = found != 0;
  PetscCallMPI(MPI_Bcast(&est.q0, 1, MPIU_REAL, 0, comm_));
  for (std::vector<PetscReal> *v : {&est.q, &est.P_damping, &est.P_reactions, &est.P_impacts}) {
    PetscInt n = (PetscInt)v->size();
    PetscCallMPI(MPI_Bcast(&n, 1, MPIU_INT, 0, comm_));
    v->resize(n);
    if (n > 0) PetscCallMPI(MPI_Bcast(v->data(), (PetscMPIInt)n, MPIU_REAL, 0, comm_));
  }
  PetscFunctionReturn(0);
}

PetscReal BracketedRoot(const std::function<PetscReal(PetscReal)> &f, PetscReal lo, PetscReal f_lo, PetscReal hi, PetscReal f_hi, PetscInt halvings,
                        PetscInt *evaluations)
{
  // Regula falsi with the Illinois rule (the end kept twice in a row has its value halved, so both
  // ends move): superlinear where f is smooth, as the power balance is between the contact events'
  // kinks. Every third step is a bisection unless the two before it halved the bracket, so it never
  // takes more than about twice bisection's count: 10-11 evaluations instead of 60 on smooth or
  // kinked test functions, 41 on one flat at its end, 57 on a step.
  const PetscReal width0 = hi - lo, tol = std::ldexp(width0, -(int)std::min<PetscInt>(halvings, 1000));
  PetscInt        n = 0, side = 0, since_check = 0;
  PetscReal       checked = width0;
  while (hi - lo > tol && n < 2 * halvings + 4) {
    PetscReal c = hi - f_hi * (hi - lo) / (f_hi - f_lo);
    if (++since_check == 3) {
      if (hi - lo > 0.5 * checked) c = 0.5 * (lo + hi);
      checked = hi - lo, since_check = 0;
    }
    if (!(c > lo && c < hi)) c = 0.5 * (lo + hi); // the secant left the bracket (round-off) or f was flat
    if (!(c > lo && c < hi)) break;                // lo and hi adjacent doubles
    const PetscReal fc = f(c);
    ++n;
    if (fc == 0) {
      lo = hi = c;
      break;
    }
    if (fc > 0) {
      lo = c, f_lo = fc;
      if (side == -1) f_hi *= 0.5;
      side = -1;
    } else {
      hi = c, f_hi = fc;
      if (side == 1) f_lo *= 0.5;
      side = 1;
    }
  }
  if (evaluations) *evaluations = n;
  return 0.5 * (lo + hi);
}

PetscReal EnergyAnalysis::PowerBalance(PetscReal q) const
{
  PetscReal P_R, P_I;
  Powers(q, &P_R, &P_I);
  return P_R - P_I - 0.5 * q * q * omega_ * omega_ * cphi_;
}

PetscErrorCode EnergyAnalysis::SetUpImpacts(const Model &model, const SlidingEquilibrium &eq, EnergyEstimate &est)
{
  PetscFunctionBeginUser;
  Wn_ = Eigen::SparseMatrix<PetscReal>();
  est.impacts      = impacts && !eq.active.empty();
  est.impact_steps = 0;
  if (!est.impacts) PetscFunctionReturn(0);
  // The integrator the transient and shooting would build (the same -theta_ options), at their
  // step: its Delassus operator is the velocity per impulse of the scheme that does the impacts.
  est.impact_steps = impact_steps == PETSC_DECIDE ? Shooting::DefaultSteps(model.Size()) : impact_steps;
  ThetaIntegrator ti(comm_);
  PetscCall(ti.SetFromOptions());
  ti.SetDelassusOnly(true);
  PetscCall(ti.SetUp(model, period_ / est.impact_steps));
  // Every rank holds the same W (replicated), so every rank keeps the same entries.
  const PetscInt        nc = model.contacts.Size();
  std::vector<PetscInt> slot(nc, -1); // contact -> its place in eq.active
  for (size_t i = 0; i < eq.active.size(); ++i) slot[eq.active[i]] = (PetscInt)i;
  std::vector<Eigen::Triplet<PetscReal>> t;
  auto keep = [&](Eigen::Index r, Eigen::Index c, PetscReal v) {
    if (r % 3 != kN || c % 3 != kN || v == 0) return;
    const PetscInt i = slot[r / 3], j = slot[c / 3];
    if (i >= 0 && j >= 0) t.emplace_back(i, j, v);
  };
  if (ti.SparseDelassus()) {
    const Eigen::SparseMatrix<PetscReal> &W = ti.DelassusSparse();
    for (Eigen::Index k = 0; k < W.outerSize(); ++k)
      for (Eigen::SparseMatrix<PetscReal>::InnerIterator it(W, k); it; ++it) keep(it.row(), it.col(), it.value());
  } else {
    const Eigen::MatrixXd &W = ti.Delassus();
    for (const PetscInt a : eq.active)
      for (const PetscInt b : eq.active) keep(3 * a + kN, 3 * b + kN, W(3 * a + kN, 3 * b + kN));
  }
  Wn_.resize((Eigen::Index)eq.active.size(), (Eigen::Index)eq.active.size());
  Wn_.setFromTriplets(t.begin(), t.end());
  PetscFunctionReturn(0);
}

PetscErrorCode EnergyAnalysis::Estimate(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab,
                                        EnergyEstimate &est)
{
  const ContactSet &cs = model.contacts;
  PetscFunctionBeginUser;
  est       = EnergyEstimate{};
  est.mode  = mode >= 0 ? mode : (stab.unstable.empty() ? -1 : stab.unstable[0]);
  if (est.mode < 0) PetscFunctionReturn(0);
  PetscCheck(est.mode < (PetscInt)stab.modes.size() && stab.modes[est.mode].Oscillatory(), comm_, kErrInput,
             "energy: mode %" PetscInt_FMT " is not an oscillatory mode of the eigenvalue table", est.mode);
  const Mode &m = stab.modes[est.mode];
  PetscCheck(m.phi_re, comm_, kErrInput, "energy: mode shapes are needed (-stab_modes)");
  est.omega = omega_ = m.omega;
  est.sigma          = m.sigma;
  est.T0             = 2 * PETSC_PI / m.omega;
  period_            = est.T0;
  cs_                = &cs;

  // phi^H C phi and (-omega^2 M + i omega C + K) phi, split in real and imaginary parts.
  VecH a, b, t1;
  PetscCall(VecDuplicate(m.phi_re, a.out()));
  PetscCall(VecDuplicate(m.phi_re, b.out()));
  PetscCall(VecDuplicate(m.phi_re, t1.out()));
  cphi_ = 0;
  PetscCall(MatMult(model.K, m.phi_re, a));
  PetscCall(MatMult(model.M, m.phi_re, t1));
  PetscCall(VecAXPY(a, -m.omega * m.omega, t1));
  PetscCall(MatMult(model.K, m.phi_im, b));
  PetscCall(MatMult(model.M, m.phi_im, t1));
  PetscCall(VecAXPY(b, -m.omega * m.omega, t1));
  if (model.HasDamping()) {
    PetscScalar d1, d2;
    PetscCall(MatMult(model.C, m.phi_im, t1));
    PetscCall(VecDot(m.phi_im, t1, &d2));
    PetscCall(VecAXPY(a, -m.omega, t1));
    PetscCall(MatMult(model.C, m.phi_re, t1));
    PetscCall(VecDot(m.phi_re, t1, &d1));
    PetscCall(VecAXPY(b, m.omega, t1));
    cphi_ = PetscRealPart(d1 + d2);
  }
  std::vector<PetscReal> la, lb, pr, pi;
  PetscCall(cs.LocalComponents(a, la));
  PetscCall(cs.LocalComponents(b, lb));
  PetscCall(cs.LocalComponents(m.phi_re, pr));
  PetscCall(cs.LocalComponents(m.phi_im, pi));
  N_.clear();
  psi_.clear();
  phit_.clear();
  phib_.clear();
  speed_.clear();
  est.q_sep = kInf;
  for (PetscInt c : eq.active) {
    PetscReal D = 0; // h_n^T h_n (H_n^T H_n is diagonal: ContactSet::Validate)
    cs.ForEachEntry(c, kN, [&](PetscInt, PetscReal v) { D += v * v; });
    N_.push_back(eq.N[c]);
    psi_.emplace_back(la[3 * c + kN] / D, lb[3 * c + kN] / D);
    phit_.emplace_back(pr[3 * c + kT], pi[3 * c + kT]);
    phib_.emplace_back(pr[3 * c + kB], pi[3 * c + kB]);
    speed_.push_back(cs.Speed(c));
    if (std::abs(psi_.back()) > 0) est.q_sep = std::min(est.q_sep, eq.N[c] / std::abs(psi_.back()));
  }
  // Without normal reaction fluctuations lift-off never bounds the scan: use the amplitude at
  // which the tangential velocity reaches the surface speed (the stick side saturation).
  if (!std::isfinite(est.q_sep)) {
    PetscReal best = kInf;
    for (size_t p = 0; p < phit_.size(); ++p)
      if (std::abs(phit_[p]) > 0) best = std::min(best, cs.Speed(eq.active[p]) / (m.omega * std::abs(phit_[p])));
    est.q_sep = std::isfinite(best) ? best : 1.0;
  }
  cos_.resize(samples);
  sin_.resize(samples);
  for (PetscInt k = 0; k < samples; ++k) {
    cos_[k] = std::cos(2 * PETSC_PI * k / samples);
    sin_[k] = std::sin(2 * PETSC_PI * k / samples);
  }

  PetscCall(SetUpImpacts(model, eq, est));

  est.found = false;
  for (est.extensions = 0; est.extensions <= extend; ++est.extensions) {
    est.q_max_factor = q_max_factor * std::ldexp(1.0, (int)est.extensions);
    PetscCall(Scan(est.q_max_factor, est, &est.found));
    PetscCall(AgreeOnScan(est));
    if (est.found) break;
  }
  if (!est.found) est.extensions = extend;
  if (est.found) {
    Powers(est.q0, &est.P_R0, &est.P_I0);
    est.P_c0 = 0.5 * est.q0 * est.q0 * omega_ * omega_ * cphi_;
    // (7.5): the phase puts the normalising component at its maximum, on the surface (phi_n = 0).
    PetscCall(VecDuplicate(eq.U, est.U0.out()));
    PetscCall(VecWAXPY(est.U0, est.q0, m.phi_re, eq.U));
    PetscCall(VecDuplicate(eq.U, est.dU0.out()));
    PetscCall(VecCopy(m.phi_im, est.dU0));
    PetscCall(VecScale(est.dU0, -est.q0 * m.omega));
    VecH mag;
    PetscCall(VecDuplicate(m.phi_re, mag.out()));
    PetscCall(VecPointwiseMult(mag, m.phi_re, m.phi_re));
    PetscCall(VecPointwiseMult(t1, m.phi_im, m.phi_im));
    PetscCall(VecAXPY(mag, 1.0, t1));
    PetscCall(VecMax(mag, &est.dof, &est.dof_amplitude));
    est.dof_amplitude = est.q0 * std::sqrt(est.dof_amplitude);
  }
  PetscFunctionReturn(0);
}

PetscErrorCode EnergyAnalysis::View(const EnergyEstimate &est, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  if (est.mode < 0) {
    PetscCall(PetscViewerASCIIPrintf(viewer, "energy estimate: no unstable mode in the band: nothing to estimate\n"));
    PetscFunctionReturn(0);
  }
  PetscCall(PetscViewerASCIIPrintf(viewer, "energy estimate for mode %" PetscInt_FMT " (f = %.4f Hz, sigma = %.4f 1/s):\n", est.mode,
                                   (double)(est.omega / (2 * PETSC_PI)), (double)est.sigma));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "first lift-off amplitude q_sep = %.6e, scan up to %.4g q_sep\n", (double)est.q_sep,
                                   (double)est.q_max_factor));
  if (est.extensions > 0 && est.found)
    PetscCall(PetscViewerASCIIPrintf(viewer, "no balance up to %.4g q_sep (-energy_q_max_factor): range doubled %" PetscInt_FMT " time(s)\n",
                                     (double)q_max_factor, est.extensions));
  if (est.found) {
    PetscCall(PetscViewerASCIIPrintf(viewer, "power balance at q0 = %.6e (%.3f q_sep); shooting guess T0 = %.7f s\n", (double)est.q0,
                                     (double)(est.q0 / est.q_sep), (double)est.T0));
    PetscCall(PetscViewerASCIIPrintf(viewer, "largest DOF amplitude of the estimate's motion %.4e m (RMS %.4e m) at DOF %" PetscInt_FMT "\n",
                                     (double)est.dof_amplitude, (double)(est.dof_amplitude / std::sqrt(2.0)), est.dof));
    if (est.impacts) {
      PetscCall(PetscViewerASCIIPrintf(viewer, "at q0: reaction power %.4e W = damping %.4e W + impact losses %.4e W (W_nn at %" PetscInt_FMT " steps per period)\n",
                                       (double)est.P_R0, (double)est.P_c0, (double)est.P_I0,
                                       est.impact_steps));
    }
  }
  else
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "no balance up to %.4g q_sep (%" PetscInt_FMT " doubling(s) of -energy_q_max_factor %g): reaction power "
                                     "never falls below damping power; raise -energy_q_max_factor above %.4g or -energy_extend\n",
                                     (double)est.q_max_factor, est.extensions, (double)q_max_factor, (double)est.q_max_factor));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode EnergyAnalysis::Write(const EnergyEstimate &est, io::H5Writer &out) const
{
  PetscFunctionBeginUser;
  if (est.mode < 0) {
    PetscCall(out.WriteAttribute("/energy", "stable", (PetscInt)1));
    PetscFunctionReturn(0);
  }
  const hsize_t n = est.q.size();
  PetscCall(out.WriteArray("/energy/q", {n}, est.q.data()));
  PetscCall(out.WriteArray("/energy/P_damping", {n}, est.P_damping.data()));
  PetscCall(out.WriteArray("/energy/P_reactions", {n}, est.P_reactions.data()));
  PetscCall(out.WriteAttribute("/energy/P_damping", "units", "W"));
  PetscCall(out.WriteAttribute("/energy/P_reactions", "units", "W"));
  if (est.impacts) {
    PetscCall(out.WriteArray("/energy/P_impacts", {n}, est.P_impacts.data()));
    PetscCall(out.WriteAttribute("/energy/P_impacts", "units", "W"));
    PetscCall(out.WriteAttribute("/energy", "impact_steps", est.impact_steps));
  }
  PetscCall(out.WriteAttribute("/energy", "impacts", (PetscInt)est.impacts));
  PetscCall(out.WriteAttribute("/energy/q", "units", "m (modal amplitude, largest tangential contact component of phi = 1)"));
  PetscCall(out.WriteAttribute("/energy", "mode", est.mode));
  PetscCall(out.WriteAttribute("/energy", "q_sep", est.q_sep));
  PetscCall(out.WriteAttribute("/energy", "T0", est.T0));
  PetscCall(out.WriteAttribute("/energy", "found", (PetscInt)est.found));
  PetscCall(out.WriteAttribute("/energy", "q_max_factor", est.q_max_factor));
  PetscCall(out.WriteAttribute("/energy", "extensions", est.extensions));
  if (est.found) {
    PetscCall(out.WriteAttribute("/energy", "q0", est.q0));
    Vec  parts[2] = {est.U0, est.dU0};
    PetscInt n0;
    PetscCall(VecGetSize(est.U0, &n0));
    // Z0 = (U0, dU0) as one 2N dataset, gathered like the other arrays.
    std::vector<PetscReal> z;
    for (Vec v : parts) {
      VecScatter         sc;
      Vec                all;
      const PetscScalar *a;
      PetscCall(VecScatterCreateToZero(v, &sc, &all));
      PetscCall(VecScatterBegin(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
      PetscCall(VecScatterEnd(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
      PetscInt nl;
      PetscCall(VecGetLocalSize(all, &nl));
      PetscCall(VecGetArrayRead(all, &a));
      for (PetscInt i = 0; i < nl; ++i) z.push_back(PetscRealPart(a[i]));
      PetscCall(VecRestoreArrayRead(all, &a));
      PetscCall(VecDestroy(&all));
      PetscCall(VecScatterDestroy(&sc));
    }
    PetscCall(out.WriteArray("/energy/Z0", {(hsize_t)(2 * n0)}, z.data()));
    PetscCall(out.WriteAttribute("/energy/Z0", "layout", "(U, dU)"));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
