// Stiff and extreme settings of the transient: each ends in a correct result or a clear error,
// never a hang or a silent NaN.
#include "squeal/integration/transient.h"
#include "squeal/model/builders.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>

using namespace squeal;

namespace {

struct Outcome {
  PetscErrorCode  ierr = 0;
  TransientResult res;
};

Outcome RunCase(const std::function<PetscErrorCode(Model &)> &build, const std::function<void(ThetaIntegrator &, TransientAnalysis &)> &tune,
            PetscReal periods)
{
  Outcome            o;
  Model              model;
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  StabilitySolver    stab(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  StabilityResult    sr;
  ThetaIntegrator    ti(PETSC_COMM_WORLD);
  TransientAnalysis  ta(PETSC_COMM_WORLD);
  PetscCallAbort(PETSC_COMM_WORLD, build(model));
  PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(model, eq));
  PetscCallAbort(PETSC_COMM_WORLD, stab.Solve(model, eq, sr));
  PetscCallAbort(PETSC_COMM_WORLD, ti.SetFromOptions());
  PetscCallAbort(PETSC_COMM_WORLD, ta.SetFromOptions());
  ta.periods    = periods;
  ta.keep_every = 10;
  tune(ti, ta);
  PetscCallAbort(PETSC_COMM_WORLD, PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  o.ierr = ta.Run(model, eq, sr, ti, o.res);
  PetscCallAbort(PETSC_COMM_WORLD, PetscPopErrorHandler());
  return o;
}

std::function<PetscErrorCode(Model &)> ThreeDof(std::function<void(ThreeDofParams &)> f)
{
  return [f](Model &m) {
    ThreeDofParams p;
    f(p);
    return BuildThreeDof(PETSC_COMM_WORLD, p, m);
  };
}

void NoTune(ThetaIntegrator &, TransientAnalysis &) {}

bool AllFinite(const TransientResult &r)
{
  for (double x : r.U)
    if (!std::isfinite(x)) return false;
  for (double x : r.V)
    if (!std::isfinite(x)) return false;
  return true;
}

double MaxVelocity(const TransientResult &r, size_t from, size_t to)
{
  double m = 0;
  for (size_t k = from * r.N; k < to * r.N; ++k) m = std::max(m, std::abs(r.V[k]));
  return m;
}

bool Rank0()
{
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  return rank == 0;
}

} // namespace

TEST(Extreme, StiffnessTimesThousand)
{
  Outcome o = RunCase(ThreeDof([](ThreeDofParams &p) { p.k1 *= 1e3, p.k2 *= 1e3, p.k3 *= 1e3, p.Fn *= 1e3; }), NoTune, 50);
  ASSERT_EQ(o.ierr, 0);
  if (!Rank0()) return;
  EXPECT_TRUE(AllFinite(o.res));
  EXPECT_EQ(o.res.summary.fp_capped, 0);
}

TEST(Extreme, MuJustBelowCriticalDecays)
{
  Outcome o = RunCase(ThreeDof([](ThreeDofParams &p) { p.mu = 0.14; }), NoTune, 80);
  ASSERT_EQ(o.ierr, 0);
  if (!Rank0()) return;
  const size_t n = o.res.t.size();
  EXPECT_LT(MaxVelocity(o.res, n - 10, n), 0.05 * MaxVelocity(o.res, 0, n / 20));
}

TEST(Extreme, MuJustAboveAndFarAboveCritical)
{
  for (double mu : {0.15, 1.2}) {
    Outcome o = RunCase(ThreeDof([mu](ThreeDofParams &p) { p.mu = mu; }), NoTune, 80);
    ASSERT_EQ(o.ierr, 0) << "mu = " << mu;
    if (!Rank0()) continue;
    EXPECT_TRUE(AllFinite(o.res));
    EXPECT_GT(o.res.summary.period, 0) << "mu = " << mu; // a sustained oscillation
  }
}

TEST(Extreme, VerySlowAndVeryFastSurface)
{
  for (double V : {1e-3, 100.0}) {
    Outcome o = RunCase(ThreeDof([V](ThreeDofParams &p) { p.V = V; }), NoTune, 40);
    ASSERT_EQ(o.ierr, 0) << "V = " << V;
    if (!Rank0()) continue;
    EXPECT_TRUE(AllFinite(o.res));
    EXPECT_EQ(o.res.summary.fp_capped, 0) << "V = " << V;
  }
}

TEST(Extreme, ThetaOneAndTenStepsPerPeriod)
{
  Outcome a = RunCase(ThreeDof([](ThreeDofParams &) {}), [](ThetaIntegrator &ti, TransientAnalysis &) { ti.SetTheta(1.0); }, 40);
  ASSERT_EQ(a.ierr, 0);
  Outcome b = RunCase(ThreeDof([](ThreeDofParams &) {}), [](ThetaIntegrator &, TransientAnalysis &ta) { ta.steps_per_period = 10; }, 200);
  ASSERT_EQ(b.ierr, 0);
  if (!Rank0()) return;
  EXPECT_TRUE(AllFinite(a.res));
  EXPECT_TRUE(AllFinite(b.res));
  EXPECT_EQ(b.res.steps, 2000);
}

TEST(Extreme, BadlyScaledRhoConvergesOrSaysSo)
{
  for (double s : {1e-6, 1e6}) {
    Outcome o = RunCase(ThreeDof([](ThreeDofParams &) {}),
                    [s](ThetaIntegrator &ti, TransientAnalysis &) {
                      ti.SetRhoScale(s);
                      ti.SetFixedPoint(1e-12, 200);
                    },
                    5);
    if (!Rank0()) continue;
    if (o.ierr == 0) {
      EXPECT_TRUE(AllFinite(o.res)) << "rho x " << s;
      // Either it converged in every step, or the capped steps are counted (reported in the summary).
      if (o.res.summary.mean_fp_iterations >= 200) {
        EXPECT_GT(o.res.summary.fp_capped, 0);
      }
    } else {
      EXPECT_EQ(o.ierr, PETSC_ERR_FP) << "rho x " << s; // the NaN error, with step and time
    }
  }
}

TEST(Extreme, ChainWithMixedContactStates)
{
  Outcome o = RunCase(
    [](Model &m) {
      ChainParams p;
      p.cells       = 4;
      p.cell.V      = 1.5;
      p.gamma_step  = 40;
      return BuildChain(PETSC_COMM_WORLD, p, m);
    },
    NoTune, 100);
  ASSERT_EQ(o.ierr, 0);
  if (!Rank0()) return;
  EXPECT_TRUE(AllFinite(o.res));
  EXPECT_EQ(o.res.summary.fp_capped, 0);
  PetscInt seen[3] = {0, 0, 0};
  for (PetscInt s : o.res.status) seen[s]++;
  EXPECT_GT(seen[kSlip], 0);
  EXPECT_GT(seen[kStick], 0);
  EXPECT_GT(seen[kOpen], 0);
  std::printf("chain: open %d stick %d slip %d records x points, fp %.2f\n", (int)seen[0], (int)seen[1], (int)seen[2],
              o.res.summary.mean_fp_iterations);
}
