// Continuation of the limit cycle in mu (issue 11): every point against a stand-alone shooting run
// from the energy estimate at its mu and against a transient; the 3-DOF branches from the Hopf
// point (mu_c by bisection on the linear stability) to mu = 0.6 with their regime changes checked
// by stand-alone shooting on both sides; a failed step halves the step and keeps the branch.
#include "squeal/continuation/continuation.h"
#include "squeal/energy/energy.h"
#include "squeal/integration/transient.h"
#include "squeal/model/builders.h"

#include <gtest/gtest.h>

using namespace squeal;

namespace {

struct Problem {
  Model              model;
  SlidingEquilibrium eq;
  StabilityResult    stab;
  EnergyEstimate     est;
  EquilibriumSolver  eqs{PETSC_COMM_WORLD};
  StabilitySolver    ss{PETSC_COMM_WORLD};
  ThetaIntegrator    ti{PETSC_COMM_WORLD};
  Shooting           sh{PETSC_COMM_WORLD};
  ShootingResult     sr;
  PetscErrorCode     err = 0;
  Problem(PetscReal V, PetscReal mu, PetscReal eps = 1e-5)
  {
    ThreeDofParams p;
    p.V = V, p.mu = mu;
    EnergyAnalysis ea(PETSC_COMM_WORLD);
    PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, p, model));
    PetscCallAbort(PETSC_COMM_WORLD, eqs.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, ss.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(model, eq));
    PetscCallAbort(PETSC_COMM_WORLD, ss.Solve(model, eq, stab));
    PetscCallAbort(PETSC_COMM_WORLD, ea.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, ea.Estimate(model, eq, stab, est));
    PetscCallAbort(PETSC_COMM_WORLD, ti.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, sh.SetFromOptions());
    sh.eps1 = sh.eps2 = eps;
    err = sh.Solve(model, eq, ti, est.U0, est.dU0, est.T0, sr);
  }
};

// mu_c: the growth rate of the sliding equilibrium's flutter mode crosses zero (bisection).
PetscReal CriticalMu(PetscReal V, PetscReal lo, PetscReal hi)
{
  for (int it = 0; it < 40; ++it) {
    const PetscReal mid = 0.5 * (lo + hi);
    ThreeDofParams  p;
    p.V = V, p.mu = mid;
    Model              m;
    SlidingEquilibrium eq;
    StabilityResult    st;
    EquilibriumSolver  eqs(PETSC_COMM_WORLD);
    StabilitySolver    ss(PETSC_COMM_WORLD);
    PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, p, m));
    PetscCallAbort(PETSC_COMM_WORLD, eqs.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, ss.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(m, eq));
    PetscCallAbort(PETSC_COMM_WORLD, ss.Solve(m, eq, st));
    (st.unstable.empty() ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

PetscErrorCode RunBranch(Problem &pr, Continuation &c, ContinuationResult &res)
{
  PetscFunctionBeginUser;
  PetscCall(c.Run(pr.model, pr.eqs, pr.ss, pr.ti, pr.sh, pr.sr, res));
  PetscFunctionReturn(0);
}

const ContinuationEvent *Find(const ContinuationResult &r, const char *type)
{
  for (auto &e : r.events)
    if (e.type == type) return &e;
  return nullptr;
}

} // namespace

TEST(Continuation, PointsAgreeWithStandAloneShootingAndTheTransient)
{
  // Tight tolerances: the continuation's points and the stand-alone runs (from the energy
  // estimate at each mu, a different start) must then agree on the period to 1e-8.
  Problem pr(3.0, 0.5, 1e-10);
  ASSERT_EQ(pr.err, 0);
  Continuation c(PETSC_COMM_WORLD);
  ASSERT_EQ(c.SetFromOptions(), 0);
  c.both = PETSC_FALSE, c.lmax = 0.56, c.max_steps = 6, c.equilibrium = PETSC_FALSE, c.locate_tol = 0;
  ContinuationResult res;
  ASSERT_EQ(RunBranch(pr, c, res), 0);
  ASSERT_GE(res.points.size(), 3u);
  EXPECT_EQ(res.points.back().param, 0.56);
  for (size_t i : {res.points.size() / 2, res.points.size() - 1}) {
    const ContinuationPoint &p = res.points[i];
    Problem                  alone(3.0, p.param, 1e-10);
    ASSERT_EQ(alone.err, 0) << "mu = " << p.param;
    // Measured 2.7e-7 and 3.2e-8: the discrete orbit (N_s = 1000 steps) depends on where its
    // status changes fall within steps, i.e. on the phase of Z0, which differs between the two
    // runs (branch: anchored to the previous point; stand-alone: the energy estimate's phase).
    EXPECT_NEAR(alone.sr.period / p.period, 1.0, 1e-6) << "mu = " << p.param;
    EXPECT_EQ(alone.sr.stable_cycle, p.stable_cycle);
  }
  // A stable point: the transient settles on the same period (at the same step h = T / N_s).
  const ContinuationPoint &p = res.points[res.points.size() / 2];
  ASSERT_TRUE(p.stable_cycle);
  Problem           at(3.0, p.param);
  TransientAnalysis ta(PETSC_COMM_WORLD);
  ThetaIntegrator   ti2(PETSC_COMM_WORLD);
  ASSERT_EQ(ta.SetFromOptions(), 0);
  ASSERT_EQ(ti2.SetFromOptions(), 0);
  ta.h       = p.period / at.sh.steps;
  ta.periods = 120;
  TransientResult tr;
  ASSERT_EQ(ta.Run(at.model, at.eq, at.stab, ti2, tr), 0);
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) EXPECT_NEAR(tr.summary.period / p.period, 1.0, 1e-4);
}

TEST(Continuation, ThreeDofBranchesFromTheHopfPointToMu06WithTheirRegimeChanges)
{
  struct Case {
    PetscReal   V;
    const char *event; // the regime change along the branch from mu_c
  } cases[] = {{3.0, "lift-off"}, {0.75, "stick"}};
  for (const Case &cs : cases) {
    Problem pr(cs.V, 0.5);
    ASSERT_EQ(pr.err, 0);
    Continuation c(PETSC_COMM_WORLD);
    ASSERT_EQ(c.SetFromOptions(), 0);
    ContinuationResult res;
    ASSERT_EQ(RunBranch(pr, c, res), 0) << "V = " << cs.V;
    ASSERT_GE(res.points.size(), 10u);
    // From the Hopf point: the small-cycle end lies just above mu_c, with the equilibrium unstable.
    const PetscReal mu_c = CriticalMu(cs.V, 0.1, 0.2);
    const auto     &first = res.points.front();
    EXPECT_GT(first.param, mu_c) << "V = " << cs.V;
    EXPECT_LT(first.param - mu_c, 3e-4) << "V = " << cs.V;
    PetscReal amax = 0;
    for (auto &p : res.points) amax = std::max(amax, p.amplitude);
    EXPECT_LT(first.amplitude, 0.02 * amax);
    EXPECT_EQ(first.frac_separated + first.frac_stuck, 0.0) << "small cycles slide throughout";
    EXPECT_EQ(first.equilibrium_unstable, 1);
    EXPECT_EQ(res.points.back().param, 0.6);
    // The regime change, confirmed by stand-alone shooting just outside its bracket.
    const ContinuationEvent *e = Find(res, cs.event);
    ASSERT_NE(e, nullptr) << "V = " << cs.V;
    const bool sep = std::string(cs.event) == "lift-off";
    const PetscReal mu_below = std::max(e->lo - 1e-3, 0.5 * (mu_c + e->lo)), mu_above = e->hi + 1e-3;
    Problem         below(cs.V, mu_below), above(cs.V, mu_above);
    ASSERT_EQ(below.err, 0);
    ASSERT_EQ(above.err, 0);
    PetscReal f[2] = {sep ? below.sr.frac_separated : below.sr.frac_stuck, sep ? above.sr.frac_separated : above.sr.frac_stuck};
    MPI_Bcast(f, 2, MPIU_REAL, 0, PETSC_COMM_WORLD);
    EXPECT_EQ(f[0], 0.0) << cs.event << " at mu = " << mu_below;
    EXPECT_GT(f[1], 0.0) << cs.event << " at mu = " << mu_above;
    // Every point of these branches is stable (measured: largest non-trivial |L| < 1).
    for (auto &p : res.points) EXPECT_TRUE(p.stable_cycle) << "mu = " << p.param;
  }
}

TEST(Continuation, AFailedStepHalvesTheStepAndKeepsTheBranch)
{
  Problem pr(0.75, 0.5);
  ASSERT_EQ(pr.err, 0);
  Continuation c(PETSC_COMM_WORLD);
  ASSERT_EQ(c.SetFromOptions(), 0);
  c.both = PETSC_FALSE, c.lmax = 0.6, c.equilibrium = PETSC_FALSE, c.locate_tol = 0, c.fail_step = 3;
  c.ds = c.ds_max = 0.01; // constant step, so that the halved one is recognisable
  ContinuationResult res;
  ASSERT_EQ(RunBranch(pr, c, res), 0);
  EXPECT_EQ(res.halvings, 1);
  // Points 1 and 2 of the leg (after the start) at ds, the third after the failure at ds / 2.
  ASSERT_GE(res.points.size(), 5u);
  EXPECT_EQ(res.points[1].ds, 0.01);
  EXPECT_EQ(res.points[2].ds, 0.01);
  EXPECT_EQ(res.points[3].ds, 0.005);
  EXPECT_EQ(res.points.back().param, 0.6);
  for (size_t i = 1; i < res.points.size(); ++i) EXPECT_GT(res.points[i].param, res.points[i - 1].param);
}
