// Energy estimate of the limit-cycle amplitude (docs/method.md §7).
#include "dense.h"
#include "squeal/energy/energy.h"
#include "squeal/integration/transient.h"
#include "squeal/model/builders.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <functional>
#include <cstdio>

#include <gtest/gtest.h>

using namespace squeal;

namespace {

struct Estimated {
  Model              model;
  SlidingEquilibrium eq;
  StabilityResult    stab;
  EnergyAnalysis     ea{PETSC_COMM_WORLD};
  EnergyEstimate     est;
  explicit Estimated(const ThreeDofParams &p)
  {
    EquilibriumSolver eqs(PETSC_COMM_WORLD);
    StabilitySolver   ss(PETSC_COMM_WORLD);
    PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, p, model));
    PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(model, eq));
    PetscCallAbort(PETSC_COMM_WORLD, ss.Solve(model, eq, stab));
    PetscCallAbort(PETSC_COMM_WORLD, ea.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, ea.Estimate(model, eq, stab, est));
  }
};

// The 4-cell chain (several points in their own frames, W_nn coupled), estimated after `set` has
// adjusted the analysis.
struct ChainEstimated {
  ChainParams        p;
  Model              model;
  SlidingEquilibrium eq;
  StabilityResult    stab;
  EnergyAnalysis     ea{PETSC_COMM_WORLD};
  EnergyEstimate     est;
  explicit ChainEstimated(const std::function<void(EnergyAnalysis &)> &set = nullptr)
  {
    EquilibriumSolver eqs(PETSC_COMM_WORLD);
    StabilitySolver   ss(PETSC_COMM_WORLD);
    p.cells = 4;
    PetscCallAbort(PETSC_COMM_WORLD, BuildChain(PETSC_COMM_WORLD, p, model));
    PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(model, eq));
    PetscCallAbort(PETSC_COMM_WORLD, ss.Solve(model, eq, stab));
    PetscCallAbort(PETSC_COMM_WORLD, ea.SetFromOptions());
    if (set) set(ea);
    PetscCallAbort(PETSC_COMM_WORLD, ea.Estimate(model, eq, stab, est));
  }
};

} // namespace

TEST(Energy, StableEquilibriumHasNoEstimate)
{
  ThreeDofParams p;
  p.mu = 0.1;
  Estimated s(p);
  EXPECT_EQ(s.est.mode, -1);
  EXPECT_FALSE(s.est.found);
}

TEST(Energy, BalanceAtQ0AndSignChange)
{
  for (double V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    Estimated s(p);
    ASSERT_TRUE(s.est.found) << "V = " << V;
    const double q0 = s.est.q0;
    // q0 is a root of P_R - P_c, positive below and negative above.
    const double scale = 0.5 * q0 * q0 * s.est.omega * s.est.omega * 20.0 * 1.0; // P_c(q0) order, c = 20
    EXPECT_LT(std::abs(s.ea.PowerBalance(q0)), 1e-9 * scale);
    EXPECT_GT(s.ea.PowerBalance(0.9 * q0), 0);
    EXPECT_LT(s.ea.PowerBalance(1.1 * q0), 0);
    EXPECT_NEAR(s.est.T0, 2 * M_PI / s.est.omega, 1e-15);
    // Z0 starts on the surface with zero normal velocity (phi_n = 0 at a closed point).
    const Eigen::VectorXd U0 = test::ToDense(s.est.U0), dU0 = test::ToDense(s.est.dU0);
    EXPECT_NEAR(U0(2), 0.0, 1e-15);
    EXPECT_NEAR(dU0(2), 0.0, 1e-12);
    // The normalising component (phi_t = 1) is at its maximum: zero tangential modal velocity.
    EXPECT_NEAR(dU0(0), 0.0, 1e-12);
  }
}

TEST(Energy, BracketedRootMeetsBisectionsPrecisionInFewerEvaluations)
{
  // Roots known in closed form: a smooth f, one with a kink next to the root (the power balance has
  // kinks where points lift off or stick), one flat near its end (a plain regula falsi keeps one end
  // there for ever) and a step (no better than bisection). The bracket's width after 60 halvings
  // would be below a double's spacing: the root to round-off, in fewer calls than bisection's 60.
  struct Case {
    const char                        *name;
    std::function<double(double)>      f;
    double                             lo, hi, root;
    PetscInt                           most;
  };
  const double r = std::sqrt(2.0);
  const Case   cases[] = {
    {"smooth", [&](double q) { return 2.0 - q * q; }, 1.0, 2.0, r, 12},
    {"kink", [&](double q) { return q < 1.3 ? 4.0 * (1.5 - q) : 2.0 - q * q; }, 1.0, 2.0, r, 12},
    {"flat end", [&](double q) { return std::pow(r - q, 3) + 1e-3 * (r - q); }, 0.0, 10.0, r, 50},
    {"step", [&](double q) { return q < r ? 1.0 : -1.0; }, 1.0, 2.0, r, 64},
  };
  for (const Case &c : cases) {
    PetscInt     n  = 0;
    const double q0 = BracketedRoot(c.f, c.lo, c.f(c.lo), c.hi, c.f(c.hi), 60, &n);
    if (PetscGlobalRank == 0) std::printf("%s: root within %.1e in %d evaluations\n", c.name, std::abs(q0 - c.root), (int)n);
    EXPECT_NEAR(q0, c.root, 4e-16 * c.root) << c.name;
    EXPECT_LE(n, c.most) << c.name;
  }
  // 10 halvings asked: the bracket within 2^-10 of its width, the root within it.
  PetscInt     n  = 0;
  const double q0 = BracketedRoot([](double q) { return q < 0.7 ? 1.0 : -1.0; }, 0.0, 1.0, 1.0, -1.0, 10, &n);
  EXPECT_NEAR(q0, 0.7, std::ldexp(1.0, -10));
  EXPECT_LE(n, 24);
}

TEST(Energy, SmallAmplitudeGrowthMatchesSigma)
{
  // For small q: P_R - P_c ~ 2 sigma <E>, <E> = q^2/4 (omega^2 phi^H M phi + phi^H K phi).
  ThreeDofParams p;
  Estimated          s(p);
  const Mode    &m = s.stab.modes[s.est.mode];
  const Eigen::VectorXd re = test::ToDense(m.phi_re), im = test::ToDense(m.phi_im);
  const Eigen::MatrixXd M = test::ToDense(s.model.M), K = test::ToDense(s.model.K);
  const double q  = 1e-3 * s.est.q_sep;
  const double E  = 0.25 * q * q * (m.omega * m.omega * (re.dot(M * re) + im.dot(M * im)) + re.dot(K * re) + im.dot(K * im));
  const double fq = s.ea.PowerBalance(q);
  EXPECT_GT(fq, 0);
  EXPECT_NEAR(fq / (2 * m.sigma * E), 1.0, 0.25);
}

TEST(Energy, AmplitudeCloseToTransientCycle)
{
  // q0 estimates the tangential half-amplitude of the settled cycle (phi_t = 1).
  ThreeDofParams p;
  Estimated          s(p);
  ThetaIntegrator   ti(PETSC_COMM_WORLD);
  TransientAnalysis ta(PETSC_COMM_WORLD);
  ASSERT_EQ(ti.SetFromOptions(), 0);
  ASSERT_EQ(ta.SetFromOptions(), 0);
  ta.periods = 120;
  TransientResult tr;
  ASSERT_EQ(ta.Run(s.model, s.eq, s.stab, ti, tr), 0);
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank) return;
  const double half_t = 0.5 * tr.summary.peak_to_peak[0];
  EXPECT_NEAR(s.est.q0 / half_t, 1.0, 0.1);
  EXPECT_NEAR(s.est.T0 / tr.summary.period, 1.0, 0.02);
}

namespace {

// Tensile impulse of N + a cos(omega t) over one period (a = |q psi|): it pulls on
// |x| < alpha = arccos(N / a) about the trough, int (a cos x - N) dx / omega there.
double TensileImpulse(double N, double a, double omega)
{
  if (a <= N) return 0;
  const double alpha = std::acos(N / a);
  return 2 * (a * std::sin(alpha) - N * alpha) / omega;
}

} // namespace

// Impact losses (7.6) on a model with several contacts in their own frames (the chain: H is not the
// identity, W_nn is coupled): against a dense reference that shares nothing with the library's
// path: psi from the dense dynamic stiffness, the tensile impulses in closed form (not sampled),
// and W_nn = H_n^T (M + h theta C + h^2 theta^2 K)^-1 H_n by Eigen's LU (not the integrator's KSP).
TEST(Energy, ImpactLossesMatchClosedFormImpulsesAndDenseDelassus)
{
  bool           impacts_default = false;
  ChainEstimated s([&](EnergyAnalysis &a) {
    impacts_default = a.impacts;
    a.impact_steps  = 8; // a long step: h^2 K couples the points in W_nn
  });
  ASSERT_TRUE(impacts_default);
  const ChainParams        &p     = s.p;
  const Model              &model = s.model;
  const SlidingEquilibrium &eq    = s.eq;
  const StabilityResult    &stab  = s.stab;
  EnergyAnalysis           &ea    = s.ea;
  const EnergyEstimate     &est   = s.est;
  ASSERT_GE(est.mode, 0);
  ASSERT_EQ((PetscInt)eq.active.size(), p.cells);
  ASSERT_TRUE(est.impacts);
  EXPECT_EQ(est.impact_steps, 8);

  const PetscInt        N = model.Size();
  const Eigen::MatrixXd M = test::ToDense(model.M), C = test::ToDense(model.C), K = test::ToDense(model.K);
  const Eigen::MatrixXd Hn = test::DenseColumns(model.contacts, N, kN);
  const double          w = est.omega, T = 2 * M_PI / w, h = T / est.impact_steps, th = 0.5;
  const Eigen::MatrixXd A = M + h * th * C + h * h * th * th * K;
  Eigen::MatrixXd       W(p.cells, p.cells); // on eq.active's order
  {
    const Eigen::MatrixXd Wall = Hn.transpose() * A.partialPivLu().solve(Hn);
    for (PetscInt i = 0; i < p.cells; ++i)
      for (PetscInt j = 0; j < p.cells; ++j) W(i, j) = Wall(eq.active[i], eq.active[j]);
  }
  ASSERT_EQ(ea.NormalDelassus().rows(), p.cells);
  EXPECT_LT((Eigen::MatrixXd(ea.NormalDelassus()) - W).norm(), 1e-10 * W.norm());
  EXPECT_GT(std::abs(W(0, 1)), 1e-3 * W(0, 0)); // coupled: the test sees the off-diagonal terms

  const Mode                     &m = stab.modes[est.mode];
  const Eigen::VectorXcd          phi = test::ToDense(m.phi_re).cast<std::complex<double>>() +
                                   std::complex<double>(0, 1) * test::ToDense(m.phi_im).cast<std::complex<double>>();
  const Eigen::MatrixXcd          D = (-w * w * M + K).cast<std::complex<double>>() + std::complex<double>(0, w) * C.cast<std::complex<double>>();
  const Eigen::VectorXcd          psi = Hn.transpose().cast<std::complex<double>>() * (D * phi);
  for (double factor : {0.5, 2.0, 7.0}) {
    const double   q = factor * est.q_sep;
    Eigen::VectorXd J(p.cells);
    for (PetscInt c = 0; c < p.cells; ++c) {
      const PetscInt a = eq.active[c];
      J(c)             = TensileImpulse(eq.N[a], q * std::abs(psi(a)) / Hn.col(a).squaredNorm(), w);
    }
    const double P_ref = 0.5 * J.dot(W * J) / T;
    PetscReal    P_R, P_I;
    std::vector<PetscReal> Jl;
    ea.Powers(q, &P_R, &P_I, &Jl);
    ASSERT_EQ((PetscInt)Jl.size(), p.cells);
    for (PetscInt c = 0; c < p.cells; ++c) EXPECT_NEAR(Jl[c], J(c), 1e-6 * J.maxCoeff() + 1e-14) << "q/q_sep " << factor << " point " << c;
    if (factor < 1) EXPECT_EQ(P_I, 0.0); // below the first lift-off nothing separates
    else EXPECT_NEAR(P_I / P_ref, 1.0, 1e-5) << "q/q_sep " << factor;
    // The balance holds the losses.
    const double P_c = 0.5 * q * q * w * w * (test::ToDense(m.phi_re).dot(C * test::ToDense(m.phi_re)) +
                                              test::ToDense(m.phi_im).dot(C * test::ToDense(m.phi_im)));
    EXPECT_NEAR(ea.PowerBalance(q), P_R - P_c - P_ref, 1e-6 * (std::abs(P_R) + P_c + P_ref));
  }
}

// The losses only lower the balance: q0 with them (the default) lies at or below q0 without, and
// -energy_impacts false gives the former estimate (no P_impacts, the balance P_R - P_c).
TEST(Energy, ImpactLossesLowerTheBalanceAndCanBeSwitchedOff)
{
  for (double V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    Estimated with(p); // the default
    ASSERT_TRUE(with.est.found);
    ASSERT_TRUE(with.est.impacts);
    EXPECT_EQ(with.est.impact_steps, 1000); // shooting's default for N = 3
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-energy_impacts", "false"), 0);
    Estimated without(p);
    ASSERT_EQ(PetscOptionsClearValue(nullptr, "-energy_impacts"), 0);
    ASSERT_TRUE(without.est.found);
    EXPECT_FALSE(without.est.impacts);
    EXPECT_TRUE(without.est.P_impacts.empty());
    EXPECT_EQ(without.ea.NormalDelassus().size(), 0);
    EXPECT_LE(with.est.q0, without.est.q0 * (1 + 1e-12)) << "V = " << V;
    EXPECT_EQ(with.est.P_impacts.size(), with.est.q.size());
    // The reference estimate balances P_R and P_c alone.
    PetscReal P_R, P_I;
    without.ea.Powers(without.est.q0, &P_R, &P_I);
    EXPECT_EQ(P_I, 0.0);
    EXPECT_NEAR(P_R, without.est.P_c0, 1e-9 * without.est.P_c0);
    EXPECT_NEAR(with.est.P_R0, with.est.P_c0 + with.est.P_I0, 1e-9 * with.est.P_R0);
    if (PetscGlobalRank == 0) std::printf("V = %g: q0 %.6e (impacts) / %.6e (none), q_sep %.6e, P_I(q0) / P_c(q0) = %.3e\n", V, with.est.q0, without.est.q0,
                                          with.est.q_sep, with.est.P_I0 / with.est.P_c0);
  }
}

// The mean reaction power (7.2)-(7.4) against every sample of the imposed motion, computed here from
// the dense mode (psi from the dense dynamic stiffness, the local velocities from the dense H): the
// library sums only each point's arc of contact (the rest adds 0), so amplitudes from before the
// first lift-off to 40 q_sep, where the points separate for up to half the period on arcs that wrap
// round the period's start, must give the full sum; both friction laws.
TEST(Energy, ReactionPowerSumsEverySampleOfTheImposedMotion)
{
  ChainEstimated            s;
  Model                    &model = s.model;
  const SlidingEquilibrium &eq    = s.eq;
  const StabilityResult    &stab  = s.stab;
  EnergyAnalysis           &ea    = s.ea;
  const EnergyEstimate     &est   = s.est;
  ASSERT_GE(est.mode, 0);

  using cd                        = std::complex<double>;
  const PetscInt        N         = model.Size();
  const Eigen::MatrixXd M         = test::ToDense(model.M), C = test::ToDense(model.C), K = test::ToDense(model.K);
  const Eigen::MatrixXd Hn        = test::DenseColumns(model.contacts, N, kN);
  const Eigen::MatrixXd Ht        = test::DenseColumns(model.contacts, N, kT), Hb = test::DenseColumns(model.contacts, N, kB);
  const Mode           &m         = stab.modes[est.mode];
  const double          w         = m.omega;
  const Eigen::VectorXcd phi      = test::ToDense(m.phi_re).cast<cd>() + cd(0, 1) * test::ToDense(m.phi_im).cast<cd>();
  const Eigen::MatrixXcd D        = (-w * w * M + K).cast<cd>() + cd(0, w) * C.cast<cd>();
  const Eigen::VectorXcd psi      = Hn.transpose().cast<cd>() * (D * phi);
  const Eigen::VectorXcd phit     = Ht.transpose().cast<cd>() * phi, phib = Hb.transpose().cast<cd>() * phi;
  const PetscInt         ns       = ea.samples;
  const double           mu       = model.contacts.Mu();
  std::vector<double>    phases; // where each point's normal reaction peaks, to see the arcs spread
  for (PetscInt a : eq.active) phases.push_back(std::arg(psi(a)));
  EXPECT_GT(*std::max_element(phases.begin(), phases.end()) - *std::min_element(phases.begin(), phases.end()), 0.1);

  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    model.contacts.law = law; // Powers reads the law at each call: the same mode, the other reactions
    for (double factor : {0.5, 1.5, 4.0, 40.0}) {
      const double q     = factor * est.q_sep;
      double       P_ref = 0, scale = 0;
      for (PetscInt a : eq.active) {
        const cd     ps = q * psi(a) / Hn.col(a).squaredNorm(), vt = cd(0, w) * q * phit(a), vb = cd(0, w) * q * phib(a);
        const double V  = model.contacts.Speed(a);
        for (PetscInt k = 0; k < ns; ++k) {
          const cd     e  = std::polar(1.0, 2 * M_PI * k / ns);
          const double rn = std::max(eq.N[a] + (ps * e).real(), 0.0), ut = (vt * e).real(), ub = (vb * e).real();
          const double st = V - ut;
          const double P  = law == FrictionLaw::Rectilinear ? mu * rn * (st > 0 ? 1 : st < 0 ? -1 : 0) * ut
                                                             : (rn > 0 ? mu * rn * (st * ut - ub * ub) / std::hypot(st, ub) : 0.0);
          P_ref += P / ns, scale += std::abs(P) / ns;
        }
      }
      PetscReal P_R, P_I;
      ea.Powers(q, &P_R, &P_I);
      EXPECT_NEAR(P_R, P_ref, 1e-12 * scale) << FrictionLawName(law) << ", q/q_sep " << factor;
    }
  }
}
