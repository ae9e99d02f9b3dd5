// Energy estimate of the limit-cycle amplitude (docs/method.md §7).
#include "dense.h"
#include "squeal/energy/energy.h"
#include "squeal/integration/transient.h"
#include "squeal/model/builders.h"

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
