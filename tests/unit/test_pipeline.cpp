// The pipeline (issue 22 item 0): the operating point has one writer and every stage follows it;
// the pipeline's chain gives what the stages give when called by hand.
#include "squeal/app/pipeline.h"
#include "squeal/model/builders.h"

#include "dense.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace squeal;

namespace {

// n steps of the theta-method from the sliding equilibrium of `model`, pushed off it.
PetscErrorCode Steps(const Model &model, ThetaIntegrator &ti, const SlidingEquilibrium &eq, PetscInt n, Eigen::VectorXd &out)
{
  VecH U, dU;
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(eq.U, U.out()));
  PetscCall(VecCopy(eq.U, U));
  PetscCall(VecDuplicate(eq.U, dU.out()));
  PetscCall(VecSet(dU, 0.05));
  const PetscInt  nc = model.contacts.Size();
  Eigen::VectorXd r  = Eigen::VectorXd::Zero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) r[3 * c + kN] = eq.N[c], r[3 * c + kT] = model.contacts.Mu() * eq.N[c];
  for (PetscInt i = 0; i < n; ++i) {
    StepInfo info;
    PetscCall(ti.Step(U, dU, r, &info));
  }
  out = test::ToDense(dU);
  PetscFunctionReturn(0);
}

} // namespace

TEST(Pipeline, TheIntegratorFollowsANewSlidingSpeedWithoutANewSetUp)
{
  // Set up at V = 3, then V = 0.75 through the one writer: the steps must be those of an integrator
  // set up at V = 0.75 from the start (the contact solver's cached speeds follow FrictionState).
  ThreeDofParams p;
  p.mu = 0.5, p.V = 3.0;
  Model a(PETSC_COMM_WORLD), b(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, a), 0);
  p.V = 0.75;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, b), 0);
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  ASSERT_EQ(eqs.SetFromOptions(), 0);
  ASSERT_EQ(eqs.Solve(b, eq), 0);
  ThetaIntegrator ta(PETSC_COMM_WORLD), tb(PETSC_COMM_WORLD);
  ASSERT_EQ(ta.SetFromOptions(), 0);
  ASSERT_EQ(tb.SetFromOptions(), 0);
  const PetscReal h = 1e-4;
  ASSERT_EQ(ta.SetUp(a, h), 0);
  ASSERT_EQ(tb.SetUp(b, h), 0);
  const unsigned long before = a.contacts.FrictionState();
  a.contacts.SetFriction(0.5, 0.75);
  EXPECT_NE(a.contacts.FrictionState(), before);
  Eigen::VectorXd va, vb;
  ASSERT_EQ(Steps(a, ta, eq, 2000, va), 0);
  ASSERT_EQ(Steps(b, tb, eq, 2000, vb), 0);
  ASSERT_EQ(va.size(), 3);
  EXPECT_EQ((va - vb).lpNorm<Eigen::Infinity>(), 0.0) << "velocities " << va.transpose() << " against " << vb.transpose();
  // The comparison has teeth: the same steps with the speeds of V = 3 end elsewhere.
  Model c(PETSC_COMM_WORLD);
  p.V = 3.0;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, c), 0);
  ThetaIntegrator tc(PETSC_COMM_WORLD);
  ASSERT_EQ(tc.SetFromOptions(), 0);
  ASSERT_EQ(tc.SetUp(c, h), 0);
  Eigen::VectorXd vc;
  ASSERT_EQ(Steps(c, tc, eq, 2000, vc), 0);
  EXPECT_GT((vc - vb).lpNorm<Eigen::Infinity>(), 1e-3 * vb.lpNorm<Eigen::Infinity>());
}

TEST(Pipeline, OperatingPointIsCheckedAndReadByEveryStage)
{
  Pipeline pl(PETSC_COMM_WORLD);
  ASSERT_EQ(pl.BuildModel(), 0);
  ASSERT_EQ(pl.SetFromOptions(), 0);
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  EXPECT_NE(pl.SetFriction(-0.1, 3.0), 0);
  EXPECT_NE(pl.SetFriction(0.5, 0.0), 0);
  EXPECT_NE(pl.SetFriction(NAN, 3.0), 0);
  // Shooting before an estimate: a clear error, not a run from empty vectors.
  EXPECT_NE(pl.Shoot(), 0);
  PetscPopErrorHandler();
  ASSERT_EQ(pl.SetFriction(0.1, 3.0), 0);
  ASSERT_EQ(pl.SolveEquilibrium(), 0);
  ASSERT_EQ(pl.SolveStability(), 0);
  EXPECT_TRUE(pl.stability.unstable.empty()) << "below mu_c = 0.143068 (docs/method.md §8)";
  EXPECT_EQ(pl.eq.mu, 0.1);
  ASSERT_EQ(pl.SetFriction(0.5, 3.0), 0);
  ASSERT_EQ(pl.SolveEquilibrium(), 0);
  ASSERT_EQ(pl.SolveStability(), 0);
  ASSERT_EQ(pl.stability.unstable.size(), 1u);
  EXPECT_EQ(pl.eq.mu, 0.5);
}

TEST(Pipeline, ChainGivesTheCycleOfTheStagesCalledByHand)
{
  // Case 1 at mu = 0.5 (the default three_dof scene): the pipeline's chain against the stages
  // called one by one with the estimate's orbit as shooting's start (-shoot_q_scale 1).
  Pipeline pl(PETSC_COMM_WORLD);
  ASSERT_EQ(pl.BuildModel(), 0);
  ASSERT_EQ(pl.SetFromOptions(), 0);
  ASSERT_EQ(pl.SetFriction(0.5, 3.0), 0);
  ASSERT_EQ(pl.SolveEquilibrium(), 0);
  ASSERT_EQ(pl.SolveStability(), 0);
  ASSERT_EQ(pl.EstimateEnergy(), 0);
  ASSERT_TRUE(pl.estimate.found);
  ASSERT_EQ(pl.Shoot(), 0);
  ASSERT_TRUE(pl.cycle.converged);

  ThreeDofParams p;
  p.mu = 0.5, p.V = 3.0;
  Model              m(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  StabilityResult    st;
  EnergyEstimate     est;
  ShootingResult     sr;
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  StabilitySolver    ss(PETSC_COMM_WORLD);
  EnergyAnalysis     ea(PETSC_COMM_WORLD);
  ThetaIntegrator    ti(PETSC_COMM_WORLD);
  Shooting           sh(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, m), 0);
  ASSERT_EQ(eqs.SetFromOptions(), 0);
  ASSERT_EQ(ss.SetFromOptions(), 0);
  ASSERT_EQ(ea.SetFromOptions(), 0);
  ASSERT_EQ(ti.SetFromOptions(), 0);
  ASSERT_EQ(sh.SetFromOptions(), 0);
  ASSERT_EQ(eqs.Solve(m, eq), 0);
  ASSERT_EQ(ss.Solve(m, eq, st), 0);
  ASSERT_EQ(ea.Estimate(m, eq, st, est), 0);
  ASSERT_EQ(sh.Solve(m, eq, ti, est.U0, est.dU0, est.T0, sr), 0);
  ASSERT_TRUE(sr.converged);
  EXPECT_NEAR(pl.estimate.q0 / est.q0, 1.0, 1e-12);
  // The same start up to round-off (U_e + 1 (U0 - U_e)): the same cycle to Newton's tolerance.
  EXPECT_NEAR(pl.cycle.period / sr.period, 1.0, 1e-8);
  // The reference cycle of case 1 (docs/method.md §8): about 92.4 Hz.
  EXPECT_NEAR(1.0 / sr.period, 92.4, 0.2);
}
