// Continuation of the limit cycle in mu (issue 11): every point against a stand-alone shooting run
// from the energy estimate at its mu and against a transient; the 3-DOF branches from the Hopf
// point (mu_c by bisection on the linear stability) to mu = 0.6 with their regime changes checked
// by stand-alone shooting on both sides; the branch in V at fixed mu; a failed step halves the
// step and keeps the branch.
#include "squeal/app/pipeline.h"
#include "squeal/continuation/continuation.h"
#include "squeal/core/errors.h"
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
  Problem(PetscReal V, PetscReal mu, PetscReal eps = 1e-5, PetscInt steps = 0)
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
    if (steps > 0) sh.steps = steps;
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

// From the start's mu = 0.5 up to 0.56 in at most 6 points, without the equilibrium's stability nor
// the bisection of regime changes: the branch whose points the tests compare with stand-alone runs.
void BranchTo056(Problem &pr, ContinuationResult &res)
{
  Continuation c(PETSC_COMM_WORLD);
  ASSERT_EQ(c.SetFromOptions(), 0);
  c.both = PETSC_FALSE, c.lmax = 0.56, c.max_steps = 6, c.equilibrium = PETSC_FALSE, c.locate_tol = 0;
  ASSERT_EQ(RunBranch(pr, c, res), 0);
  ASSERT_GE(res.points.size(), 3u);
  EXPECT_EQ(res.points.back().param, 0.56);
}

const ContinuationEvent *Find(const ContinuationResult &r, const char *type)
{
  for (auto &e : r.events)
    if (e.type == type) return &e;
  return nullptr;
}

} // namespace

TEST(Continuation, PointsAgreeWithStandAloneShootingTo1e8)
{
  // The discrete period map has a one-parameter family of fixed points (Z0, T) along the orbit
  // (the phase), and on it T varies with where the status changes fall within a step: measured
  // spread of T over starts of the stand-alone run (q_scale 0.7-1.3) 2.9e-7 / 8.6e-7 (case 1 / 2)
  // at N_s = 1000 steps, 1.1e-8 / 3.1e-8 at 4000, 2e-10 (16000) / 2e-9 (8000). The branch's points
  // (phase anchored to the previous point) and the stand-alone runs (phase of the energy estimate)
  // sit at different phases: branch against stand-alone measured up to 1.8e-8 at N_s = 8000 and
  // 2.4e-9 at 16000, so the 1e-8 check of issue 11 runs at N_s = 16000. Shooting and corrector
  // tolerances (1e-10) are far below it; the same h = T / N_s in both runs.
  // One rank only: 16000-step flows are replicated on every rank of the dense back end, and a
  // 2-rank run pays a collective per step (this test took > 7 min on 2 loaded ranks against 11 s
  // on one); the 2-rank suite checks the other Continuation tests.
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (size > 1) GTEST_SKIP() << "single-rank test (16000-step flows)";
  const PetscInt steps = 16000;
  for (PetscReal V : {3.0, 0.75}) {
    Problem pr(V, 0.5, 1e-10, steps);
    ASSERT_EQ(pr.err, 0) << "V = " << V;
    ContinuationResult res;
    BranchTo056(pr, res);
    if (HasFatalFailure()) return;
    for (size_t i : {(size_t)1, res.points.size() / 2 + 1, res.points.size() - 1}) {
      const ContinuationPoint &p = res.points[i];
      Problem                  alone(V, p.param, 1e-10, steps);
      ASSERT_EQ(alone.err, 0) << "V = " << V << ", mu = " << p.param;
      PetscPrintf(PETSC_COMM_WORLD, "V = %g, mu = %.6f: |dT|/T = %.2e against the stand-alone run\n", (double)V, (double)p.param,
                  (double)std::abs(alone.sr.period / p.period - 1.0));
      EXPECT_LE(std::abs(alone.sr.period / p.period - 1.0), 1e-8) << "V = " << V << ", mu = " << p.param;
      EXPECT_EQ(alone.sr.stable_cycle, p.stable_cycle);
    }
  }
}

// The FE models' corrector (exact tangent products, shooting's linear-monodromy preconditioner
// bordered by dH/dmu and the arclength row: Shooting::PreparePreconditioner) forced on case 1 by
// -shoot_jacobian_dense_max 1: every point of its branch against stand-alone shooting from the
// energy estimate at that mu (4000 steps, where T spreads by 1.1e-8 over the orbit's phase;
// measured 1.5e-9 to 4.3e-8).
TEST(Continuation, PreconditionedCorrectorPointsAgreeWithStandAloneShooting)
{
  const PetscInt steps = 4000;
  Problem        pr(3.0, 0.5, 1e-10, steps);
  ASSERT_EQ(pr.err, 0);
  pr.sh.jacobian_dense_max = 1; // 2N + 1 = 7 > 1: the preconditioned corrector, and shooting's linear preconditioner
  ContinuationResult res;
  BranchTo056(pr, res);
  if (HasFatalFailure()) return;
  for (size_t i = 1; i < res.points.size(); ++i) {
    const ContinuationPoint &p = res.points[i];
    Problem                  alone(3.0, p.param, 1e-10, steps);
    ASSERT_EQ(alone.err, 0) << "mu = " << p.param;
    PetscPrintf(PETSC_COMM_WORLD, "mu = %.6f: |dT|/T = %.2e against the stand-alone run\n", (double)p.param,
                (double)std::abs(alone.sr.period / p.period - 1.0));
    EXPECT_LE(std::abs(alone.sr.period / p.period - 1.0), 1e-7) << "mu = " << p.param;
    EXPECT_EQ(alone.sr.stable_cycle, p.stable_cycle) << "mu = " << p.param;
  }
}

TEST(Continuation, AStablePointAgreesWithTheTransient)
{
  Problem pr(3.0, 0.5, 1e-10);
  ASSERT_EQ(pr.err, 0);
  Continuation c(PETSC_COMM_WORLD);
  ASSERT_EQ(c.SetFromOptions(), 0);
  c.both = PETSC_FALSE, c.lmax = 0.56, c.max_steps = 6, c.equilibrium = PETSC_FALSE, c.locate_tol = 0;
  ContinuationResult res;
  ASSERT_EQ(RunBranch(pr, c, res), 0);
  ASSERT_GE(res.points.size(), 3u);
  // At 1000 steps the stand-alone run agrees to the phase spread above (measured 2.7e-7, 3.2e-8).
  const ContinuationPoint &p = res.points[res.points.size() / 2];
  {
    Problem alone(3.0, p.param, 1e-10);
    ASSERT_EQ(alone.err, 0) << "mu = " << p.param;
    EXPECT_NEAR(alone.sr.period / p.period, 1.0, 1e-6) << "mu = " << p.param;
  }
  // A stable point: the transient settles on the same period (at the same step h = T / N_s).
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
  if (rank == 0) {
    EXPECT_NEAR(tr.summary.period / p.period, 1.0, 1e-4);
  }
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
    // Located by bisection (case 1's lift-off at the kink too: measured [0.143394, 0.143474]).
    EXPECT_LT(e->hi - e->lo, 2 * c.locate_tol) << cs.event << " bracket [" << e->lo << ", " << e->hi << "]";
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

TEST(Continuation, BranchInVAtFixedMuWithItsRegimeChanges)
{
  // Case 2's stick-slip cycle at mu = 0.5 continued in V from 0.75 up to 2: separation appears
  // (measured V = 1.1833) and stick disappears (1.7097) on the way to case 1's regime. Each
  // change is confirmed by stand-alone shooting from the energy estimate on both sides.
  // One rank only (5 s there; > 300 s on 2 ranks under a load of 12): the 2-rank path of the
  // corrector is the same for mu and V, and the mu tests run on 2 ranks.
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (size > 1) GTEST_SKIP() << "single-rank test";
  Problem pr(0.75, 0.5);
  ASSERT_EQ(pr.err, 0);
  Continuation c(PETSC_COMM_WORLD);
  ASSERT_EQ(c.SetFromOptions(), 0);
  c.param = "v", c.lmin = 0.5, c.lmax = 2.0, c.both = PETSC_FALSE, c.equilibrium = PETSC_FALSE;
  ContinuationResult res;
  ASSERT_EQ(RunBranch(pr, c, res), 0);
  EXPECT_EQ(res.param_name, "v");
  ASSERT_GE(res.points.size(), 10u);
  EXPECT_EQ(res.points.back().param, 2.0);
  EXPECT_EQ(pr.model.contacts.V(), 0.75) << "the model's V is restored";
  for (size_t i = 1; i < res.points.size(); ++i) EXPECT_GT(res.points[i].param, res.points[i - 1].param);
  struct Change {
    const char *type;
    bool        sep, before; // the fraction that changes, and whether it is non-zero below the event
  } changes[] = {{"lift-off", true, false}, {"stick-ends", false, true}};
  for (const Change &ch : changes) {
    const ContinuationEvent *e = Find(res, ch.type);
    ASSERT_NE(e, nullptr) << ch.type;
    EXPECT_LT(e->hi - e->lo, 2 * c.locate_tol) << ch.type << ": located by bisection";
    Problem below(e->lo - 0.01, 0.5), above(e->hi + 0.01, 0.5);
    ASSERT_EQ(below.err, 0);
    ASSERT_EQ(above.err, 0);
    PetscReal f[2] = {ch.sep ? below.sr.frac_separated : below.sr.frac_stuck, ch.sep ? above.sr.frac_separated : above.sr.frac_stuck};
    MPI_Bcast(f, 2, MPIU_REAL, 0, PETSC_COMM_WORLD);
    EXPECT_EQ(f[0] > 0, ch.before) << ch.type << " at V = " << e->lo - 0.01;
    EXPECT_EQ(f[1] > 0, !ch.before) << ch.type << " at V = " << e->hi + 0.01;
  }
  // A point of the branch against the stand-alone run at its V (1000 steps: the phase spread).
  const ContinuationPoint &p = res.points[res.points.size() / 2];
  Problem                  alone(p.param, 0.5, 1e-10);
  ASSERT_EQ(alone.err, 0);
  EXPECT_NEAR(alone.sr.period / p.period, 1.0, 1e-6) << "V = " << p.param;
}

TEST(Continuation, ParameterSlicesOverRankGroupsGiveOneBranch)
{
  // -cont_slices 2 on [0.4, 0.6]: [0.4, 0.5] and [0.5, 0.6], each from its own shooting solution
  // (energy estimate) at its upper end; on 2 ranks one rank each, on one rank in turn.
  Problem pr(3.0, 0.5);
  ASSERT_EQ(pr.err, 0);
  Continuation c(PETSC_COMM_WORLD);
  ASSERT_EQ(c.SetFromOptions(), 0);
  c.lmin = 0.4, c.lmax = 0.6, c.slices = 2, c.equilibrium = PETSC_FALSE;
  c.SetBranchStarter(Pipeline::SliceStarter()); // each slice's chain, as the program runs it
  ContinuationResult res;
  ASSERT_EQ(RunBranch(pr, c, res), 0);
  ASSERT_GE(res.points.size(), 6u);
  EXPECT_EQ(res.points.front().param, 0.4);
  EXPECT_EQ(res.points.back().param, 0.6);
  PetscInt n[2] = {0, 0};
  for (size_t i = 0; i < res.points.size(); ++i) {
    ++n[res.points[i].slice];
    EXPECT_EQ(res.points[i].slice, res.points[i].param < 0.5 ? 0 : 1) << "mu = " << res.points[i].param;
    if (i) {
      EXPECT_GT(res.points[i].param, res.points[i - 1].param);
    }
  }
  EXPECT_GT(n[0], 1);
  EXPECT_GT(n[1], 1);
  // Slice 1's lower end (mu = 0.5, reached by continuation from 0.6) against stand-alone shooting
  // there (the phase spread at 1000 steps) and the same on every rank.
  const auto *p = &res.points.front();
  for (auto &q : res.points)
    if (q.param == 0.5) p = &q;
  ASSERT_EQ(p->param, 0.5);
  EXPECT_NEAR(pr.sr.period / p->period, 1.0, 1e-6);
  PetscReal T[2] = {p->period, -p->period};
  MPI_Allreduce(MPI_IN_PLACE, T, 2, MPIU_REAL, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_EQ(T[0], -T[1]) << "every rank holds the same merged branch";
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

TEST(Continuation, AnAmplitudeStopFarFromMuCIsNotCalledAHopfPoint)
{
  // Issue 20 item 8: -cont_min_amplitude 0.99 stops the leg towards mu_c = 0.143068 after a few
  // points, with the equilibrium still strongly unstable: not the Hopf point. With the default
  // (0.02) the leg reaches mu_c, and that end is the Hopf point, from either energy estimate's
  // start: they lie at different places on the orbit, and the arclength norm and steps must not
  // depend on where (from the impact-aware one the leg had stopped at 10 % of the start's
  // amplitude, 1.6e-4 above mu_c).
  for (const char *impacts : {"true", "false"})
  for (const double amin : {0.99, 0.02}) {
    PetscOptionsSetValue(nullptr, "-energy_impacts", impacts);
    Problem pr(3.0, 0.5);
    PetscOptionsClearValue(nullptr, "-energy_impacts");
    ASSERT_EQ(pr.err, 0);
    Continuation c(PETSC_COMM_WORLD);
    ASSERT_EQ(c.SetFromOptions(), 0);
    c.lmin = 0.1, c.lmax = 0.5, c.min_amplitude = amin;
    ContinuationResult res;
    ASSERT_EQ(RunBranch(pr, c, res), 0);
    ASSERT_GE(res.leg_end.size(), 1u);
    const std::string &down = res.leg_end[0];
    const PetscReal    lowest = res.points.front().param;
    if (amin > 0.5) {
      EXPECT_NE(down.find("not a Hopf point"), std::string::npos) << down;
      EXPECT_GT(lowest, 0.3) << "stopped early";
    } else {
      EXPECT_NE(down.find("(Hopf point)"), std::string::npos) << down << " (-energy_impacts " << impacts << ")";
      EXPECT_LT(lowest - 0.143068, 1e-3);
    }
  }
}

namespace {
PetscErrorCode Raise(PetscErrorCode code, const char *what)
{
  PetscFunctionBeginUser;
  SETERRQ(PETSC_COMM_SELF, code, "%s", what);
}
} // namespace

// The corrector's guard (PushErrorHandlerQuietOnSignal): a signal's PETSC_ERR_SIG reaches the
// caller silently (it keeps the branch and reports the interrupt once), any other error is still
// reported in the one-line form, with its own message.
TEST(Continuation, CorrectorGuardIsQuietOnSignalsOnly)
{
  ASSERT_EQ(PushErrorHandler(), 0);
  ASSERT_EQ(PushErrorHandlerQuietOnSignal(), 0);
  testing::internal::CaptureStderr();
  const PetscErrorCode sig = Raise(PETSC_ERR_SIG, "interrupted by SIGTERM during a period integration");
  const std::string    quiet = testing::internal::GetCapturedStderr();
  testing::internal::CaptureStderr();
  const PetscErrorCode user = Raise(PETSC_ERR_USER, "the model is singular");
  const std::string    loud = testing::internal::GetCapturedStderr();
  ASSERT_EQ(PetscPopErrorHandler(), 0);
  ASSERT_EQ(PetscPopErrorHandler(), 0);
  EXPECT_EQ(sig, PETSC_ERR_SIG);
  EXPECT_EQ(quiet, "");
  EXPECT_EQ(user, PETSC_ERR_USER);
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  // PETSC_COMM_SELF: every rank prints its own.
  EXPECT_EQ(loud, "squeal: error: the model is singular\n") << "rank " << rank;
}
