// Shooting (docs/method.md §6): convergence from the energy estimate, agreement with the transient's
// settled cycle, the matrix-free Jacobian against a dense finite-difference one, Floquet check.
#include "dense.h"
#include "squeal/energy/energy.h"
#include "squeal/integration/transient.h"
#include "squeal/model/builders.h"
#include "squeal/shooting/shooting.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

using namespace squeal;

namespace {

struct Problem {
  Model              model;
  SlidingEquilibrium eq;
  StabilityResult    stab;
  EnergyEstimate     est;
  ThetaIntegrator    ti{PETSC_COMM_WORLD};
  Shooting           sh{PETSC_COMM_WORLD};
  explicit Problem(const ThreeDofParams &p) : Problem([&](Model &m) { return BuildThreeDof(PETSC_COMM_WORLD, p, m); }) {}
  template <class Build>
  explicit Problem(Build build)
  {
    EquilibriumSolver eqs(PETSC_COMM_WORLD);
    StabilitySolver   ss(PETSC_COMM_WORLD);
    EnergyAnalysis    ea(PETSC_COMM_WORLD);
    PetscCallAbort(PETSC_COMM_WORLD, build(model));
    PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(model, eq));
    PetscCallAbort(PETSC_COMM_WORLD, ss.Solve(model, eq, stab));
    PetscCallAbort(PETSC_COMM_WORLD, ea.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, ea.Estimate(model, eq, stab, est));
    PetscCallAbort(PETSC_COMM_WORLD, ti.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, sh.SetFromOptions());
  }
};

bool Rank0()
{
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  return rank == 0;
}

// k random tangent directions dZ0 (2N x k) of p's model and period changes dT (of 1e-3), the same on
// every rank.
void RandomDirections(const Problem &p, Eigen::Index k, Eigen::MatrixXd &dZ0, Eigen::RowVectorXd &dT)
{
  PetscInt N;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetSize(p.eq.U, &N));
  dZ0 = Eigen::MatrixXd::Random(2 * N, k);
  dT  = Eigen::RowVectorXd::Random(k) * 1e-3;
  MPI_Bcast(dZ0.data(), (int)dZ0.size(), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  MPI_Bcast(dT.data(), (int)k, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
}

// Shooting's state x at the converged cycle's start (sr.Z0, held on rank 0), on every rank.
PetscErrorCode CycleStart(Problem &p, const ShootingResult &sr, Vec *x)
{
  PetscInt N, lo, hi;
  Vec      U0, dU0;
  PetscFunctionBeginUser;
  PetscCall(VecGetSize(p.eq.U, &N));
  std::vector<double> z(2 * N, 0.0);
  if (Rank0()) z = sr.Z0;
  PetscCallMPI(MPI_Bcast(z.data(), (int)(2 * N), MPI_DOUBLE, 0, PETSC_COMM_WORLD));
  PetscCall(VecDuplicate(p.eq.U, &U0));
  PetscCall(VecDuplicate(p.eq.U, &dU0));
  PetscCall(VecGetOwnershipRange(U0, &lo, &hi));
  for (PetscInt i = lo; i < hi; ++i) {
    PetscCall(VecSetValue(U0, i, z[i], INSERT_VALUES));
    PetscCall(VecSetValue(dU0, i, z[N + i], INSERT_VALUES));
  }
  for (Vec v : {U0, dU0}) {
    PetscCall(VecAssemblyBegin(v));
    PetscCall(VecAssemblyEnd(v));
  }
  PetscCall(p.sh.CreateState(x));
  PetscCall(p.sh.Pack(U0, dU0, sr.period, *x));
  PetscCall(VecDestroy(&U0));
  PetscCall(VecDestroy(&dU0));
  PetscFunctionReturn(0);
}

// A start a tenth of the energy estimate's amplitude from Z_e, in the linear regime:
// (U_e + 0.1 (U0 - U_e), 0.1 dU0).
PetscErrorCode TenthOfTheEstimate(const Problem &pr, Vec *U0, Vec *dU0)
{
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(pr.est.U0, U0));
  PetscCall(VecDuplicate(pr.est.dU0, dU0));
  PetscCall(VecAXPBYPCZ(*U0, 0.1, 0.9, 0.0, pr.est.U0, pr.eq.U));
  PetscCall(VecAXPBY(*dU0, 0.1, 0.0, pr.est.dU0));
  PetscFunctionReturn(0);
}

} // namespace

TEST(Shooting, BothCasesConvergeAndMatchTheTransient)
{
  struct Case {
    double   V;
    PetscInt max_iterations; // the budget; measured 4 (case 1) and 3 (case 2, the seed's count)
  } cases[] = {{3.0, 4}, {0.75, 4}};
  for (const Case &c : cases) {
    ThreeDofParams p;
    p.V = c.V;
    Problem pr(p);
    ASSERT_TRUE(pr.est.found);
    ShootingResult sr;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0) << "V = " << c.V;
    EXPECT_TRUE(sr.converged);
    EXPECT_LE(sr.iterations, c.max_iterations) << "V = " << c.V;
    EXPECT_LT(sr.residual, 1e-5);

    // The settled cycle of a long transient at the same step (h = T / 1000 vs T_lin / 1000 differ
    // by 0.8 %, so compare at equal h: steps per period chosen from the shooting period).
    TransientAnalysis ta(PETSC_COMM_WORLD);
    ThetaIntegrator   ti2(PETSC_COMM_WORLD);
    ASSERT_EQ(ta.SetFromOptions(), 0);
    ASSERT_EQ(ti2.SetFromOptions(), 0);
    ta.h       = sr.period / pr.sh.steps;
    ta.periods = 120; // settled after ~20 periods; the summary uses the last 20 %
    TransientResult tr;
    ASSERT_EQ(ta.Run(pr.model, pr.eq, pr.stab, ti2, tr), 0);
    if (!Rank0()) continue;
    EXPECT_NEAR(tr.summary.period / sr.period, 1.0, 1e-4) << "V = " << c.V;
    for (int j = 0; j < 2; ++j) EXPECT_NEAR(tr.summary.peak_to_peak[j] / sr.peak_to_peak[j], 1.0, 1e-3) << "V = " << c.V << " DOF " << j;
    // The trivial multiplier, and the cycle's stability as the transient shows it (it settled).
    ASSERT_GE(sr.trivial, 0);
    EXPECT_LT(std::abs(sr.floquet[sr.trivial] - 1.0), 1e-2);
    EXPECT_TRUE(sr.stable_cycle);
    // Regimes of docs/method.md §8.
    if (c.V == 3.0) {
      EXPECT_GT(sr.frac_separated, 0.1);
      EXPECT_EQ(sr.frac_stuck, 0.0);
    } else {
      EXPECT_GT(sr.frac_stuck, 0.01);
      EXPECT_EQ(sr.frac_separated, 0.0);
    }
  }
}

TEST(Shooting, MatrixFreeJacobianMatchesDenseFiniteDifferences)
{
  // At the case 2 cycle (permanent contact), J v from (6.4) against the bordered matrix
  // [M - I, dZ/dT; G_a^T, 0] built column by column (monodromy + a finite difference in T).
  ThreeDofParams p;
  p.V = 0.75;
  Problem        pr(p);
  ShootingResult sr;
  pr.sh.Floquet().compute = PETSC_FALSE;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0);
  const PetscInt N = 3;
  Vec            x, v, y, U0, dU0;
  ASSERT_EQ(pr.sh.CreateState(&x), 0);
  ASSERT_EQ(VecDuplicate(x, &v), 0);
  ASSERT_EQ(VecDuplicate(x, &y), 0);
  ASSERT_EQ(VecDuplicate(pr.eq.U, &U0), 0);
  ASSERT_EQ(VecDuplicate(pr.eq.U, &dU0), 0);
  // The converged Z0 back into vectors (rank 0 holds it; broadcast for the test).
  std::vector<double> z(2 * N, 0.0);
  if (Rank0()) z = sr.Z0;
  MPI_Bcast(z.data(), 2 * N, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  PetscInt lo, hi;
  ASSERT_EQ(VecGetOwnershipRange(U0, &lo, &hi), 0);
  for (PetscInt i = lo; i < hi; ++i) {
    VecSetValue(U0, i, z[i], INSERT_VALUES);
    VecSetValue(dU0, i, z[N + i], INSERT_VALUES);
  }
  VecAssemblyBegin(U0), VecAssemblyEnd(U0), VecAssemblyBegin(dU0), VecAssemblyEnd(dU0);
  ASSERT_EQ(pr.sh.Pack(U0, dU0, sr.period, x), 0);
  ASSERT_EQ(pr.sh.SetAnchor(x), 0);

  Eigen::MatrixXd Mono;
  pr.sh.Floquet().phases = 1; // the Jacobian of the discrete map at Z0 itself, as the products are
  ASSERT_EQ(pr.sh.Monodromy(U0, dU0, sr.period, Mono), 0);
  // Dense dZ/dT by a forward difference in T.
  Vec U1, dU1, U2, dU2;
  VecDuplicate(U0, &U1), VecDuplicate(U0, &dU1), VecDuplicate(U0, &U2), VecDuplicate(U0, &dU2);
  const double dT = 1e-7 * sr.period;
  ASSERT_EQ(pr.sh.Flow(U0, dU0, sr.period, U1, dU1), 0);
  ASSERT_EQ(pr.sh.Flow(U0, dU0, sr.period + dT, U2, dU2), 0);
  Eigen::VectorXd dZdT(2 * N);
  dZdT << (test::ToDense(U2) - test::ToDense(U1)) / dT, (test::ToDense(dU2) - test::ToDense(dU1)) / dT;

  // J applied to unit vectors of (Z, T), in the packing's global order, mapped back to (U, dU, T).
  PetscInt xlo, xhi;
  ASSERT_EQ(VecGetOwnershipRange(x, &xlo, &xhi), 0);
  Eigen::VectorXd ez(2 * N);
  double          worst = 0;
  for (PetscInt j = 0; j <= 2 * N; ++j) {
    // Build v = e_j in (U, dU, T) coordinates through Pack.
    Vec eU, edU;
    VecDuplicate(U0, &eU), VecDuplicate(U0, &edU);
    VecZeroEntries(eU), VecZeroEntries(edU);
    double eT = 0;
    if (j < N) {
      if (j >= lo && j < hi) VecSetValue(eU, j, 1.0, INSERT_VALUES);
    } else if (j < 2 * N) {
      if (j - N >= lo && j - N < hi) VecSetValue(edU, j - N, 1.0, INSERT_VALUES);
    } else eT = 1.0;
    VecAssemblyBegin(eU), VecAssemblyEnd(eU), VecAssemblyBegin(edU), VecAssemblyEnd(edU);
    ASSERT_EQ(pr.sh.Pack(eU, edU, eT, v), 0);
    ASSERT_EQ(pr.sh.JacobianProduct(x, v, y), 0);
    PetscReal phase;
    ASSERT_EQ(pr.sh.Unpack(y, eU, edU, &phase), 0);
    ez << test::ToDense(eU), test::ToDense(edU);
    // Dense column j of the bordered matrix.
    Eigen::VectorXd col = j < 2 * N ? Eigen::VectorXd(Mono.col(j)) : dZdT;
    if (j < 2 * N) col[j] -= 1.0;
    const double scale = std::max(col.norm(), 1.0);
    worst              = std::max(worst, (ez - col).norm() / scale);
    VecDestroy(&eU), VecDestroy(&edU);
  }
  EXPECT_LT(worst, 1e-3);
  for (Vec *w : {&x, &v, &y, &U0, &dU0, &U1, &dU1, &U2, &dU2}) VecDestroy(w);
}

TEST(Shooting, RobustStartsEndWithAResultOrAReason)
{
  // Far starts and a small cycle near the Hopf point: converged, or a named failure; never a hang.
  struct Start {
    double mu, scale;
  } starts[] = {{0.5, 0.2}, {0.5, 5.0}, {0.15, 1.0}};
  for (const Start &s : starts) {
    ThreeDofParams p;
    p.mu = s.mu;
    Problem pr(p);
    ASSERT_TRUE(pr.est.found);
    pr.sh.Floquet().compute = PETSC_FALSE; // not under test here
    Vec U0, dU0;
    VecDuplicate(pr.est.U0, &U0), VecDuplicate(pr.est.dU0, &dU0);
    VecWAXPY(U0, -1.0, pr.eq.U, pr.est.U0), VecAYPX(U0, s.scale, pr.eq.U);
    VecCopy(pr.est.dU0, dU0), VecScale(dU0, s.scale);
    ShootingResult sr;
    PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
    const PetscErrorCode e = pr.sh.Solve(pr.model, pr.eq, pr.ti, U0, dU0, pr.est.T0, sr);
    PetscPopErrorHandler();
    if (e == 0) {
      EXPECT_TRUE(sr.converged);
      EXPECT_LT(sr.residual, 1e-5);
    } else {
      EXPECT_FALSE(sr.converged);
      EXPECT_FALSE(sr.reason.empty());
    }
    EXPECT_LE(sr.iterations, 20);
    if (Rank0()) std::printf("mu %.2f start x%.1f: %s after %d iterations\n", s.mu, s.scale, sr.reason.c_str(), (int)sr.iterations);
    VecDestroy(&U0), VecDestroy(&dU0);
  }
}

TEST(Shooting, StiffAndMultiContactModels)
{
  // Stiffness and preload x 1000 (frequency x 31.6); the 4-contact chain (24 + 1 unknowns).
  ThreeDofParams p;
  p.k1 *= 1e3, p.k2 *= 1e3, p.k3 *= 1e3, p.Fn *= 1e3;
  Problem stiff(p);
  Problem chain([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  for (Problem *pr : {&stiff, &chain}) {
    ASSERT_TRUE(pr->est.found);
    ShootingResult sr;
    ASSERT_EQ(pr->sh.Solve(pr->model, pr->eq, pr->ti, pr->est.U0, pr->est.dU0, pr->est.T0, sr), 0);
    EXPECT_LE(sr.iterations, 8);
    EXPECT_LT(std::abs(sr.floquet[sr.trivial] - 1.0), 1e-2);
  }
}

TEST(Shooting, MatrixFreeFloquetMatchesDenseMonodromy)
{
  // The SLEPc route for large models against the dense monodromy, on the 4-contact chain, both
  // averaged over the same 4 starting phases (finite differences against exact tangents on one rank).
  Problem        pr([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  pr.sh.Floquet().phases = 4;
  ShootingResult dense, mf;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, dense), 0);
  pr.sh.Floquet().dense_max = 0;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, mf), 0);
  ASSERT_GE(mf.floquet.size(), 5u);
  for (size_t i = 0; i < 5; ++i) {
    double best = 1e300;
    for (auto d : dense.floquet) best = std::min(best, std::abs(mf.floquet[i] - d));
    EXPECT_LT(best, 1e-4) << "multiplier " << mf.floquet[i];
  }
  EXPECT_LT(std::abs(mf.floquet[mf.trivial] - 1.0), 1e-2);
}

TEST(Shooting, TrivialMultiplierMissComesFromTheDiscreteMapsEventSteps)
{
  // Why the trivial multiplier of case 1 does not close on 1 as N_s grows (docs/numerics.md,
  // "Floquet multipliers: the average over one step"). Z1 = one step from Z0 is again an exact
  // fixed point of the period map Phi, so the secant over the whole shift is exact:
  // Phi(Z0 + d) - Phi(Z0) = d, d = Z1 - Z0. For a smooth Phi the secants over [0, s d] would all
  // equal d up to O(|d|). The discrete map is only piecewise
  // smooth: the step in which the impact falls moves as the orbit shifts, so the secants differ
  // by an amount that does not shrink with h. That is the miss of the trivial multiplier of the
  // discrete map's own Jacobian (-floquet_phases 1), and the reason for the phase average.
  ThreeDofParams p; // case 1: separation/slip, one impact per period
  const PetscInt N = 3;
  std::vector<double> spread_at;
  for (PetscInt steps : {1000, 4000}) {
    Problem pr(p);
    pr.sh.steps = steps;
    pr.sh.eps1 = pr.sh.eps2 = 1e-10;
    pr.sh.Floquet().compute = PETSC_FALSE;
    ShootingResult sr;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0);
    Vec U0, dU0, U, dU, U1, dU1;
    for (Vec *w : {&U0, &dU0, &U, &dU, &U1, &dU1}) ASSERT_EQ(VecDuplicate(pr.eq.U, w), 0);
    std::vector<double> z(2 * N, 0.0);
    if (Rank0()) z = sr.Z0;
    MPI_Bcast(z.data(), 2 * N, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    PetscInt lo, hi;
    ASSERT_EQ(VecGetOwnershipRange(U0, &lo, &hi), 0);
    for (PetscInt i = lo; i < hi; ++i) VecSetValue(U0, i, z[i], INSERT_VALUES), VecSetValue(dU0, i, z[N + i], INSERT_VALUES);
    VecAssemblyBegin(U0), VecAssemblyEnd(U0), VecAssemblyBegin(dU0), VecAssemblyEnd(dU0);
    auto flow = [&](double s, const Eigen::VectorXd &d, Eigen::VectorXd &out) {
      PetscInt j = 0;
      for (PetscInt i = lo; i < hi; ++i, ++j) {
        VecSetValue(U, i, z[i] + s * d[i], INSERT_VALUES);
        VecSetValue(dU, i, z[N + i] + s * d[N + i], INSERT_VALUES);
      }
      VecAssemblyBegin(U), VecAssemblyEnd(U), VecAssemblyBegin(dU), VecAssemblyEnd(dU);
      PetscCallAbort(PETSC_COMM_WORLD, pr.sh.Flow(U, dU, sr.period, U1, dU1));
      out.resize(2 * N);
      out << test::ToDense(U1), test::ToDense(dU1);
    };
    Eigen::VectorXd base, Z0(2 * N), d(2 * N), out;
    flow(0.0, Eigen::VectorXd::Zero(2 * N), base); // also sets the integrator up for h = T / N_s
    // One step from Z0, the fixed point started from the steady-sliding reactions as in Flow.
    Eigen::VectorXd r = Eigen::VectorXd::Zero(3);
    r[kT] = pr.model.contacts.Mu() * pr.eq.N[0], r[kN] = pr.eq.N[0];
    VecCopy(U0, U), VecCopy(dU0, dU);
    StepInfo info;
    ASSERT_EQ(pr.ti.Step(U, dU, r, &info), 0);
    Z0 << test::ToDense(U0), test::ToDense(dU0);
    d << test::ToDense(U), test::ToDense(dU);
    d -= Z0;
    flow(1.0, d, out);
    EXPECT_LT((out - base - d).norm(), 1e-6 * d.norm()) << "N_s = " << steps; // measured 5e-13, 3e-11
    double lo_dev = 1e300, hi_dev = 0;
    for (double s : {1e-6, 0.25, 0.5, 0.75}) {
      flow(s, d, out);
      const double dev = ((out - base) / s - d).norm() / d.norm();
      lo_dev = std::min(lo_dev, dev), hi_dev = std::max(hi_dev, dev);
      if (Rank0()) std::printf("  N_s = %d: secant over [0, s d], s = %-6g: misses d by %.2e |d|\n", (int)steps, s, dev);
    }
    // The miss depends on where on the orbit Z0 sits (the impact's step relative to it): 5.3e-4 to
    // 1.2e-2 from the impact-aware energy estimate's start, under 1e-2 from the former one.
    EXPECT_LT(hi_dev, 3e-2);
    spread_at.push_back(hi_dev - lo_dev);
    for (Vec *w : {&U0, &dU0, &U, &dU, &U1, &dU1}) VecDestroy(w);
  }
  // Pieces with different slopes at both step counts: the spread does not shrink with h.
  EXPECT_GT(spread_at[0], 1e-3);
  EXPECT_GT(spread_at[1], 0.5 * spread_at[0]);
}

TEST(Shooting, ExactStepTangentsGiveTheFiniteDifferenceMonodromy)
{
  // docs/method.md §6: the product of the exact step tangents (statuses held fixed) against the 2N
  // forward-difference flows, at the converged cycles of both cases (planar) and of
  // the 4-contact chain (dense back end, replicated on every rank under MPI).
  ThreeDofParams c1, c2;
  c2.V = 0.75;
  Problem p1(c1), p2(c2);
  Problem chain([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  for (Problem *pr : {&p1, &p2, &chain}) {
    ASSERT_TRUE(pr->est.found);
    pr->sh.Floquet().compute = PETSC_FALSE;
    ShootingResult sr;
    ASSERT_EQ(pr->sh.Solve(pr->model, pr->eq, pr->ti, pr->est.U0, pr->est.dU0, pr->est.T0, sr), 0);
    PetscInt N, lo, hi;
    Vec      U0, dU0;
    VecDuplicate(pr->eq.U, &U0), VecDuplicate(pr->eq.U, &dU0);
    VecGetSize(U0, &N), VecGetOwnershipRange(U0, &lo, &hi);
    std::vector<double> z(2 * N, 0.0);
    if (Rank0()) z = sr.Z0; // held on rank 0
    MPI_Bcast(z.data(), (int)(2 * N), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    for (PetscInt i = lo; i < hi; ++i) VecSetValue(U0, i, z[i], INSERT_VALUES), VecSetValue(dU0, i, z[N + i], INSERT_VALUES);
    VecAssemblyBegin(U0), VecAssemblyEnd(U0), VecAssemblyBegin(dU0), VecAssemblyEnd(dU0);
    Eigen::MatrixXd fd, exact;
    pr->sh.Floquet().phases = 1; // the discrete map's own monodromy
    ASSERT_EQ(pr->sh.Monodromy(U0, dU0, sr.period, fd), 0);
    ASSERT_EQ(pr->sh.MonodromyExact(U0, dU0, sr.period, exact), 0);
    // Columns scaled as the finite differences are (||U0|| vs ||dU0||): compare relative to each
    // column's size; forward differences of step 1e-7 leave about 1e-6.
    double worst = 0;
    for (PetscInt j = 0; j < 2 * N; ++j) worst = std::max(worst, (exact.col(j) - fd.col(j)).norm() / std::max(fd.col(j).norm(), 1e-3));
    EXPECT_LT(worst, 1e-4) << "N = " << N;
    Eigen::VectorXcd le = exact.eigenvalues(), lf = fd.eigenvalues();
    for (Eigen::Index i = 0; i < le.size(); ++i) {
      double best = 1e300;
      for (Eigen::Index j = 0; j < lf.size(); ++j) best = std::min(best, std::abs(le[i] - lf[j]));
      EXPECT_LT(best, 1e-4) << "multiplier " << le[i];
    }
    if (Rank0()) std::printf("  N = %d: exact vs finite-difference monodromy, worst column %.2e\n", (int)N, worst);
    VecDestroy(&U0), VecDestroy(&dU0);
  }
}

TEST(Shooting, PhaseAveragedMultipliersConvergeWithTheStep)
{
  // Case 1 (an impact per period). The Jacobian of the discrete period map at Z0 depends on where
  // the impact falls inside its step: its largest non-trivial multiplier scatters with N_s. The
  // Jacobian averaged over one step of phase (default: Gauss points on the pieces where the
  // statuses do not change) is the derivative of a smooth map: its multipliers converge
  // monotonically with N_s, and its trivial multiplier is 1 up to the quadrature and the shooting
  // residual (by construction: the average maps the one-step shift d to Phi(Z0+d) - Phi(Z0) = d).
  ThreeDofParams      p;
  std::vector<double> averaged, single;
  for (PetscInt steps : {500, 1000, 2000, 4000}) {
    for (PetscInt phases : {PETSC_DECIDE, (PetscInt)1}) {
      Problem pr(p);
      pr.sh.steps          = steps;
      pr.sh.Floquet().phases = phases;
      ShootingResult sr;
      ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0);
      ASSERT_GE(sr.trivial, 0);
      double second = 0;
      for (size_t i = 0; i < sr.floquet.size(); ++i)
        if ((PetscInt)i != sr.trivial) second = std::max(second, std::abs(sr.floquet[i]));
      (phases == 1 ? single : averaged).push_back(second);
      if (phases == PETSC_DECIDE) EXPECT_LT(std::abs(sr.floquet[sr.trivial] - 1.0), 1e-6) << "N_s = " << steps; // measured 2e-9 to 9e-9
      else EXPECT_LT(std::abs(sr.floquet[sr.trivial] - 1.0), 1e-2) << "N_s = " << steps;
      if (Rank0()) std::printf("  N_s = %4d, %s: |L_2| = %.6f, |L_trivial - 1| = %.2e\n", (int)steps, phases == 1 ? "at Z0   " : "averaged", second,
                  std::abs(sr.floquet[sr.trivial] - 1.0));
    }
  }
  // Averaged: 0.580421, 0.580577, 0.580645, 0.580667 (monotone, differences shrinking).
  for (size_t i = 1; i < averaged.size(); ++i) EXPECT_GT(averaged[i], averaged[i - 1]);
  for (size_t i = 2; i < averaged.size(); ++i) EXPECT_LT(averaged[i] - averaged[i - 1], averaged[i - 1] - averaged[i - 2]);
  // At Z0 only: 0.580275, 0.574818, 0.563494, 0.572531, a scatter 20 times the averaged spread.
  const auto [smin, smax] = std::minmax_element(single.begin(), single.end());
  EXPECT_GT(*smax - *smin, 5 * (averaged.back() - averaged.front()));
}

TEST(Shooting, InterpolatedPhaseBisectionFindsTheExactPieces)
{
  // The phase pieces of the averaged monodromy are located by bisection on the status changes.
  // Below -floquet_bisect_interp (1/32) of a step the flows start from interpolated states
  // just before the first differing transition instead of at t = 0. Reference: the same bisection
  // with every flow from the start of the period (interp 0, the former route). Measured on all
  // three cycles: the same pieces and multipliers to the last digit; Floquet 25 -> 17, 36 -> 19,
  // 163 -> 66 period integrations.
  struct Case {
    double      V;
    FrictionLaw law;
  } cases[] = {{3.0, FrictionLaw::Planar}, {0.75, FrictionLaw::Planar}, {0.75, FrictionLaw::Rectilinear}};
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  for (const Case &c : cases) {
    // The rectilinear reference takes 163 flows with a gather per step: 1 rank only (12 s on 2).
    if (size > 1 && c.law == FrictionLaw::Rectilinear) continue;
    ThreeDofParams p;
    p.V   = c.V;
    p.law = c.law;
    ShootingResult sr[2];
    for (int k = 0; k < 2; ++k) {
      Problem pr(p);
      if (k == 1) pr.sh.Floquet().bisect_interp = 0;
      ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr[k]), 0) << "V = " << c.V;
    }
    EXPECT_EQ(sr[0].floquet_phases, sr[1].floquet_phases) << "V = " << c.V;
    ASSERT_EQ(sr[0].floquet.size(), sr[1].floquet.size());
    double worst = 0;
    for (const auto &l : sr[0].floquet) {
      double best = PETSC_INFINITY;
      for (const auto &m : sr[1].floquet) best = std::min(best, std::abs(l - m));
      worst = std::max(worst, best);
    }
    EXPECT_LT(worst, 1e-9) << "V = " << c.V;
    EXPECT_LT(std::abs(sr[0].floquet[sr[0].trivial] - 1.0), 1e-4) << "V = " << c.V;
    EXPECT_LT(sr[0].floquet_evaluations, 0.75 * sr[1].floquet_evaluations) << "V = " << c.V;
    if (Rank0())
      std::printf("  V = %g, %s: %d phases, Floquet %d period integrations (every flow from t = 0: %d), multipliers %.1e apart\n", c.V,
                  c.law == FrictionLaw::Planar ? "planar" : "rectilinear", (int)sr[0].floquet_phases, (int)sr[0].floquet_evaluations,
                  (int)sr[1].floquet_evaluations, worst);
  }
}

TEST(Shooting, RectilinearCycleNamesTheTwoCycleAndConvergesWithADampedNewton)
{
  // Case 1 with rectilinear friction: a separation/stick/slip cycle whose stick phase lasts about
  // two steps (0.2 % of the period). At 1000 steps plain Newton alternates between two iterates
  // (a stick step there in one, not in the other); the run stops on that with a hint instead of
  // spending the iteration budget. The critical-point line search converges, to the period of
  // a long transient (0.0111794 s at h = T_lin / 1000).
  // With exact tangent products (default) plain Newton converges there: the finite-difference
  // products straddled the stick step; the 2-cycle is still named with -shoot_exact_jacobian 0.
  ThreeDofParams p;
  p.law = FrictionLaw::Rectilinear;
  {
    Problem        pr(p);
    ShootingResult sr;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0);
    if (Rank0()) std::printf("rectilinear, exact products, plain Newton: %d iterations, T = %.7f s\n", (int)sr.iterations, sr.period);
    EXPECT_LE(sr.iterations, 8);
    EXPECT_NEAR(sr.period / 0.0111794, 1.0, 1e-4);
  }
  {
    // From the energy estimate without impact losses: the finite-difference
    // Newton's two-cycle is that start's. From the impact-aware one (closer to the cycle) plain
    // Newton converges with finite differences too.
    PetscOptionsSetValue(nullptr, "-energy_impacts", "0");
    Problem pr(p);
    PetscOptionsClearValue(nullptr, "-energy_impacts");
    pr.sh.exact_jacobian = PETSC_FALSE;
    ShootingResult sr;
    PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
    EXPECT_NE(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0);
    PetscPopErrorHandler();
    EXPECT_FALSE(sr.converged);
    EXPECT_NE(sr.reason.find("alternates between two iterates"), std::string::npos) << sr.reason;
    EXPECT_LT(sr.corrections, 20); // measured 12: stopped before the budget of 20 iterations
  }
  PetscOptionsSetValue(nullptr, "-shoot_snes_linesearch_type", "cp");
  Problem pr(p);
  PetscOptionsClearValue(nullptr, "-shoot_snes_linesearch_type");
  ShootingResult sr;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0);
  EXPECT_TRUE(sr.converged);
  EXPECT_LE(sr.iterations, 10); // measured 8
  EXPECT_NEAR(sr.period / 0.0111794, 1.0, 1e-4);
  if (!Rank0()) return; // the orbit summary is held on rank 0
  EXPECT_GT(sr.frac_stuck, 0.0);
  EXPECT_GT(sr.frac_separated, 0.1);
}

TEST(Shooting, ExactTangentFlowMatchesFiniteDifferencesOfTheFlow)
{
  // The tangent of the period map along the stored flow, d Z / d Z0 dZ0 + d Z / d T dT (the
  // derivative in the step size included), against a central difference of two nonlinear flows
  // (each at its own step size T / N_s, so with its own factorisation), on the 4-contact chain at
  // its converged cycle and on case 2: one random direction each, relative error < 1e-5.
  ThreeDofParams p3;
  p3.V = 0.75;
  Problem chain([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  Problem case2(p3);
  for (Problem *pr : {&chain, &case2}) {
    ShootingResult sr;
    pr->sh.Floquet().compute = PETSC_FALSE;
    ASSERT_EQ(pr->sh.Solve(pr->model, pr->eq, pr->ti, pr->est.U0, pr->est.dU0, pr->est.T0, sr), 0);
    ASSERT_TRUE(pr->sh.ExactJacobian());
    PetscInt N;
    VecGetSize(pr->eq.U, &N);
    std::vector<double> z(2 * N, 0.0);
    if (Rank0()) z = sr.Z0;
    MPI_Bcast(z.data(), 2 * N, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    Eigen::VectorXd zn = Eigen::Map<Eigen::VectorXd>(z.data(), 2 * N);
    Eigen::VectorXd dz = Eigen::VectorXd::Random(2 * N);
    for (PetscInt i = 0; i < N; ++i) dz[i] *= zn.head(N).norm() / std::sqrt((double)N), dz[N + i] *= zn.tail(N).norm() / std::sqrt((double)N);
    MPI_Bcast(dz.data(), 2 * N, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
    const double dT = 0.3 * sr.period;
    Vec U0, dU0, U1, dU1, x;
    VecDuplicate(pr->eq.U, &U0), VecDuplicate(pr->eq.U, &dU0), VecDuplicate(pr->eq.U, &U1), VecDuplicate(pr->eq.U, &dU1);
    ASSERT_EQ(pr->sh.CreateState(&x), 0);
    PetscInt lo, hi;
    VecGetOwnershipRange(U0, &lo, &hi);
    auto set = [&](double e) {
      for (PetscInt i = lo; i < hi; ++i) {
        VecSetValue(U0, i, zn[i] + e * dz[i], INSERT_VALUES);
        VecSetValue(dU0, i, zn[N + i] + e * dz[N + i], INSERT_VALUES);
      }
      VecAssemblyBegin(U0), VecAssemblyEnd(U0), VecAssemblyBegin(dU0), VecAssemblyEnd(dU0);
    };
    const double    eps = 1e-7;
    Eigen::VectorXd zp(2 * N), zm(2 * N);
    set(eps);
    ASSERT_EQ(pr->sh.Flow(U0, dU0, sr.period + eps * dT, U1, dU1), 0);
    zp << test::ToDense(U1), test::ToDense(dU1);
    set(-eps);
    ASSERT_EQ(pr->sh.Flow(U0, dU0, sr.period - eps * dT, U1, dU1), 0);
    zm << test::ToDense(U1), test::ToDense(dU1);
    const Eigen::VectorXd fd = (zp - zm) / (2 * eps);
    set(0.0);
    ASSERT_EQ(pr->sh.Pack(U0, dU0, sr.period, x), 0);
    Eigen::MatrixXd    dZ1;
    Eigen::RowVectorXd dTv(1);
    dTv[0] = dT;
    ASSERT_EQ(pr->sh.TangentFlow(x, dz, dTv, dZ1), 0);
    const double err = (dZ1.col(0) - fd).norm() / fd.norm();
    if (Rank0()) std::printf("N = %d: |tangent - central difference| / |difference| = %.2e\n", (int)N, err);
    EXPECT_LT(err, 1e-5);
    VecDestroy(&U0), VecDestroy(&dU0), VecDestroy(&U1), VecDestroy(&dU1), VecDestroy(&x);
  }
}

TEST(Shooting, BlockTangentFlowEqualsItsColumnsOneByOne)
{
  // A block of 5 columns in one integration (matrix-matrix products per step; on several ranks each
  // rank integrates its share of the columns and the shares are exchanged) against the same columns
  // integrated one at a time (the matrix-vector and vector triangular-solve path of GMRES), on the
  // 4-contact chain's cycle (closed, sticking and sliding points): equal to round-off (measured
  // 2.6e-14; 8.8e-10 before the contact tangent's normal rows were scaled to velocity rows).
  Problem        chain([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  ShootingResult sr;
  chain.sh.Floquet().compute = PETSC_FALSE;
  ASSERT_EQ(chain.sh.Solve(chain.model, chain.eq, chain.ti, chain.est.U0, chain.est.dU0, chain.est.T0, sr), 0);
  ASSERT_TRUE(chain.sh.ExactJacobian());
  PetscInt N;
  VecGetSize(chain.eq.U, &N);
  const Eigen::Index k = 5;
  Eigen::MatrixXd    dZ0 = Eigen::MatrixXd::Random(2 * N, k);
  Eigen::RowVectorXd dT  = Eigen::RowVectorXd::Random(k) * sr.period;
  dT[0]                  = 0; // one column without the step-size derivative
  MPI_Bcast(dZ0.data(), (int)dZ0.size(), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  MPI_Bcast(dT.data(), (int)k, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  Vec x;
  ASSERT_EQ(CycleStart(chain, sr, &x), 0);
  Eigen::MatrixXd block, one;
  ASSERT_EQ(chain.sh.TangentFlow(x, dZ0, dT, block), 0);
  ASSERT_EQ(block.cols(), k);
  double worst = 0;
  for (Eigen::Index j = 0; j < k; ++j) {
    ASSERT_EQ(chain.sh.TangentFlow(x, dZ0.col(j), dT.segment(j, 1), one), 0);
    worst = std::max(worst, (block.col(j) - one.col(0)).norm() / one.col(0).norm());
  }
  if (Rank0()) std::printf("block of %d columns against one column at a time: worst relative difference %.2e\n", (int)k, worst);
  EXPECT_LT(worst, 1e-12);
  // Every rank holds every column after the exchange.
  double mine = block.norm(), least = 0, most = 0;
  MPI_Allreduce(&mine, &least, 1, MPI_DOUBLE, MPI_MIN, PETSC_COMM_WORLD);
  MPI_Allreduce(&mine, &most, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_EQ(least, most);
  VecDestroy(&x);
}

// On several ranks rank 0 steps the flows for all (Shooting::Flow) and broadcasts them; the other
// ranks' contact solvers take no step meanwhile, so Flow ends by forgetting every rank's carried
// solver state (the predictor's history). The steps every rank takes next (the dense monodromy, the
// phase bisection of the Floquet multipliers) must then agree: after two flows and 40 more steps on
// every rank, the same contact passes and the same reactions on every rank, bit for bit. A guard:
// on this chain it also held without the reset, the fixed point reaching the same bits from
// either starting guess.
TEST(Shooting, StepsAfterAFlowAgreeOnEveryRank)
{
  Problem        chain([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  ShootingResult sr;
  chain.sh.Floquet().compute = PETSC_FALSE;
  ASSERT_EQ(chain.sh.Solve(chain.model, chain.eq, chain.ti, chain.est.U0, chain.est.dU0, chain.est.T0, sr), 0);
  PetscInt N, lo, hi;
  VecGetSize(chain.eq.U, &N);
  std::vector<double> z(2 * N, 0.0);
  if (Rank0()) z = sr.Z0;
  MPI_Bcast(z.data(), (int)(2 * N), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  Vec U0, dU0, U1, dU1;
  for (Vec *w : {&U0, &dU0, &U1, &dU1}) ASSERT_EQ(VecDuplicate(chain.eq.U, w), 0);
  ASSERT_EQ(VecGetOwnershipRange(U0, &lo, &hi), 0);
  for (PetscInt i = lo; i < hi; ++i) VecSetValue(U0, i, z[i], INSERT_VALUES), VecSetValue(dU0, i, z[N + i], INSERT_VALUES);
  VecAssemblyBegin(U0), VecAssemblyEnd(U0), VecAssemblyBegin(dU0), VecAssemblyEnd(dU0);
  // Two periods (Solve's last orbit, stepped on every rank, ended where the first one ends).
  Eigen::VectorXd r;
  ASSERT_EQ(chain.sh.Flow(U0, dU0, sr.period, U1, dU1, &r), 0);
  ASSERT_EQ(chain.sh.Flow(U1, dU1, sr.period, U0, dU0, &r), 0);
  VecCopy(U0, U1), VecCopy(dU0, dU1);
  StepInfo info;
  PetscInt passes[2] = {0, 0}; // the contact solver's passes in all, on this rank (and its negative)
  for (int i = 0; i < 40; ++i) {
    ASSERT_EQ(chain.ti.Step(U1, dU1, r, &info), 0);
    passes[0] += info.contact.iterations;
  }
  passes[1] = -passes[0];
  MPI_Allreduce(MPI_IN_PLACE, passes, 2, MPIU_INT, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_EQ(passes[0], -passes[1]); // the same starting guesses on every rank
  ASSERT_GT(r.size(), 0);
  Eigen::VectorXd least = r, most = r;
  MPI_Allreduce(MPI_IN_PLACE, least.data(), (int)r.size(), MPI_DOUBLE, MPI_MIN, PETSC_COMM_WORLD);
  MPI_Allreduce(MPI_IN_PLACE, most.data(), (int)r.size(), MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_EQ((most - least).cwiseAbs().maxCoeff(), 0.0);
  for (Vec *w : {&U0, &dU0, &U1, &dU1}) VecDestroy(w);
}

// Above -shoot_jacobian_dense_max, GMRES runs on exact tangent products preconditioned by the LU of
// the sliding linearisation's bordered Jacobian (-shoot_linear_pc), with each step's contact factor
// kept along the flow (-shoot_tangent_cache_mb). Newton must take the same iterates as with the
// factorised exact Jacobian (the Krylov tolerance apart), on both cycles of docs/method.md §8: one with
// separation, one with stick, where the linearisation is furthest from the cycle's tangent.
TEST(Shooting, LinearisedPreconditionerTakesTheDenseNewtonIterates)
{
  for (double V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    ShootingResult ref, lin;
    {
      Problem pr(p);
      ASSERT_TRUE(pr.est.found);
      pr.sh.Floquet().compute = PETSC_FALSE;
      ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, ref), 0);
    }
    {
      Problem pr(p);
      pr.sh.Floquet().compute = PETSC_FALSE;
      pr.sh.jacobian_dense_max = 1; // never the dense Jacobian
      pr.sh.ew                 = PETSC_FALSE; // linear solves as exact as the dense LU's, to compare iterates
      pr.sh.recycle            = 0;
      ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, lin), 0);
      // One tangent integration per GMRES iteration plus the preconditioner's period column per
      // Newton step; GMRES on the 7 unknowns ends within 7 iterations whatever the preconditioner.
      EXPECT_LE(lin.tangent_evaluations, 8 * (lin.corrections + 1)) << "V = " << V;
    }
    ASSERT_TRUE(ref.converged);
    ASSERT_TRUE(lin.converged) << "V = " << V << ": " << lin.reason;
    EXPECT_EQ(lin.iterations, ref.iterations) << "V = " << V;
    EXPECT_NEAR(lin.period / ref.period, 1.0, 1e-9) << "V = " << V;
    if (Rank0()) {
      double d = 0, n = 0;
      for (size_t i = 0; i < ref.Z0.size(); ++i) d += std::pow(lin.Z0[i] - ref.Z0[i], 2), n += std::pow(ref.Z0[i], 2);
      EXPECT_LT(std::sqrt(d / n), 1e-7) << "V = " << V;
    }
  }
}

// -shoot_ksp_eps1_stop: under Eisenstat-Walker with right preconditioning, the last Newton step
// short of eps1 stops GMRES once its true residual (the next iterate's residual to first order) is
// below 0.3 eps1 ||Z||; the next iterate then confirms. On the chain's cycle (GMRES on its bordered
// system): the same Newton iterations, both cycles within eps1, the same period to the cycles'
// residuals, and fewer tangent integrations with the stop than without it. Right preconditioning is
// the default under the linear preconditioner: no -shoot_ksp_pc_side here (left, the stop does not
// apply and the counts would be equal).
TEST(Shooting, KrylovStopsWhereTheNextIterateMeetsEps1)
{
  ShootingResult res[2];
  for (int stop = 0; stop < 2; ++stop) {
    Problem pr([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
    ASSERT_TRUE(pr.est.found);
    pr.sh.Floquet().compute = PETSC_FALSE;
    pr.sh.jacobian_dense_max = 1; // GMRES on products
    pr.sh.pre_periods        = 200; // from the flow near the cycle, as on the pads
    pr.sh.pre_tol            = 0.02;
    pr.sh.ksp_eps1_stop      = stop ? PETSC_TRUE : PETSC_FALSE;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, res[stop]), 0);
    ASSERT_TRUE(res[stop].converged) << "stop " << stop << ": " << res[stop].reason;
  }
  if (Rank0())
    std::printf("%d / %d Newton iterations, %d / %d tangent integrations, final ||H|| / ||Z0|| %.2e / %.2e (without / with the stop)\n",
                (int)res[0].iterations, (int)res[1].iterations, (int)res[0].tangent_evaluations, (int)res[1].tangent_evaluations,
                (double)res[0].residual, (double)res[1].residual);
  EXPECT_EQ(res[1].iterations, res[0].iterations);
  EXPECT_LT(res[1].tangent_evaluations, res[0].tangent_evaluations);
  for (const ShootingResult &r : res) EXPECT_LT(r.residual, 1e-5); // -shoot_eps1
  EXPECT_NEAR(res[1].period / res[0].period, 1.0, 1e-7);
}

// Krylov recycling (-shoot_recycle): the Ritz vectors of the earlier solves, with their products
// recomputed at the new iterate by one block tangent integration, make the preconditioner exact on
// their span. On the 7 unknowns of the 3-DOF cycle the recycled space soon spans nearly all of it:
// the same Newton iterates (it changes the Krylov space, not the tolerance), and fewer one-column
// tangent integrations than without recycling.
TEST(Shooting, RecycledKrylovSubspaceKeepsTheIteratesAndSavesTangentIntegrations)
{
  for (double V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    ShootingResult res[2];
    for (int r = 0; r < 2; ++r) {
      Problem pr(p);
      ASSERT_TRUE(pr.est.found);
      pr.sh.Floquet().compute = PETSC_FALSE;
      pr.sh.jacobian_dense_max = 1;
      pr.sh.ew                 = PETSC_FALSE;
      pr.sh.recycle            = r == 0 ? 0 : 32;
      ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, res[r]), 0);
      ASSERT_TRUE(res[r].converged) << "V = " << V << ", recycle " << pr.sh.recycle << ": " << res[r].reason;
    }
    if (Rank0())
      std::printf("V = %g: %d Newton iterations; %d tangent integrations without recycling, %d with (%d recycled columns)\n", V,
                  (int)res[1].iterations, (int)res[0].tangent_evaluations, (int)res[1].tangent_evaluations, (int)res[1].recycled_columns);
    EXPECT_EQ(res[1].iterations, res[0].iterations) << "V = " << V;
    EXPECT_NEAR(res[1].period / res[0].period, 1.0, 1e-9) << "V = " << V;
    EXPECT_GT(res[1].recycled_columns, 0) << "V = " << V;
    EXPECT_LT(res[1].tangent_evaluations, res[0].tangent_evaluations) << "V = " << V;
    if (Rank0()) {
      double d = 0, n = 0;
      for (size_t i = 0; i < res[0].Z0.size(); ++i) d += std::pow(res[1].Z0[i] - res[0].Z0[i], 2), n += std::pow(res[0].Z0[i], 2);
      EXPECT_LT(std::sqrt(d / n), 1e-7) << "V = " << V;
    }
  }
}

// With one phase on the dense back end the matrix-free route's products are exact step tangents
// along the flow from Z0 (no difference noise): its leading multipliers are the eigenvalues of the
// dense exact monodromy at Z0, to the eigensolver's tolerance, by SLEPc's Krylov-Schur (one column
// per tangent integration) and by the block Arnoldi (8 columns per integration, n = 72 > 4 x 8).
TEST(Shooting, MatrixFreeExactFloquetMatchesTheDenseExactMonodromy)
{
  ChainParams cp;
  cp.cells = 12;
  Problem pr([&](Model &m) { return BuildChain(PETSC_COMM_WORLD, cp, m); });
  pr.sh.Floquet().phases = 1;
  pr.sh.Floquet().nev    = 6;
  ShootingResult dense;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, dense), 0);
  pr.sh.Floquet().dense_max = 0;
  for (PetscInt block : {0, 8}) {
    ShootingResult mf;
    pr.sh.Floquet().block = block;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, mf), 0);
    EXPECT_EQ(mf.floquet_method, block ? "block Arnoldi on exact step tangents" : "SLEPc, matrix-free exact step tangents");
    ASSERT_GE(mf.floquet.size(), 5u);
    for (size_t i = 0; i < 5; ++i) {
      double best = 1e300;
      for (auto d : dense.floquet) best = std::min(best, std::abs(mf.floquet[i] - d));
      EXPECT_LT(best, 1e-7) << "block " << block << ": multiplier " << mf.floquet[i];
    }
  }
}

// -shoot_pre_periods with -shoot_pre_tol: periods of flow from the estimate until the return
// distance, corrected to first order in the period along the vector field, is below the tolerance.
// Reference: shooting from the estimate itself (no pre-periods). The pre-periods must stop early,
// their corrected period must be closer to the cycle's than the estimate's T0, and Newton must end
// on the same cycle.
TEST(Shooting, PrePeriodsStopAtTheReturnToleranceAndReachTheSameCycle)
{
  for (double V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    ShootingResult ref, pre;
    {
      Problem pr(p);
      pr.sh.Floquet().compute = PETSC_FALSE;
      ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, ref), 0);
    }
    Problem pr(p);
    pr.sh.Floquet().compute = PETSC_FALSE;
    pr.sh.pre_periods = 200;
    pr.sh.pre_tol     = 1e-3;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, pre), 0) << "V = " << V;
    EXPECT_GT(pre.pre_periods, 0);
    EXPECT_LT(pre.pre_periods, 200) << "V = " << V << ": the return distance never fell below 1e-3";
    EXPECT_LT(std::abs(pre.pre_period - ref.period), std::abs(pr.est.T0 - ref.period)) << "V = " << V;
    EXPECT_LT(std::abs(pre.pre_period / ref.period - 1.0), 1e-3) << "V = " << V;
    // Not 1e-10: the discrete cycle's period depends on where in a step its status changes fall,
    // so on the phase Newton settles at (2.9e-7 and 8.6e-7 at 1000 steps, docs/records.md "Continuation").
    EXPECT_NEAR(pre.period / ref.period, 1.0, 2e-6) << "V = " << V;
    EXPECT_LE(pre.iterations, ref.iterations) << "V = " << V;
  }
}

// -shoot_pre_drift: the pre-periods' flow keeps the period it runs over, and its step's set-up,
// while the period estimate differs from it by at most that times the last return distance.
// Case 1 at mu = 0.15 from a tenth of the estimate (the boost test's start: some 40 pre-periods),
// against a set-up at every pre-period (0): fewer set-ups, about as many pre-periods, and Newton on
// the same cycle.
TEST(Shooting, PrePeriodsKeepTheirStepSetUpWhileThePeriodBarelyMoves)
{
  ThreeDofParams p;
  p.mu = 0.15;
  ShootingResult res[2];
  for (int keep : {0, 1}) {
    Problem pr(p);
    ASSERT_TRUE(pr.est.found);
    Vec U0, dU0;
    ASSERT_EQ(TenthOfTheEstimate(pr, &U0, &dU0), 0);
    pr.sh.Floquet().compute = PETSC_FALSE;
    pr.sh.pre_periods       = 400;
    pr.sh.pre_tol           = 0.05;
    pr.sh.pre_drift         = keep ? 1e-2 : 0;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, U0, dU0, pr.est.T0, res[keep]), 0) << res[keep].reason;
    EXPECT_TRUE(res[keep].converged);
    VecDestroy(&U0), VecDestroy(&dU0);
  }
  std::printf("%d pre-periods, %d set-ups at every period; %d pre-periods, %d set-ups kept within 1e-2 e\n", (int)res[0].pre_periods,
              (int)res[0].setups, (int)res[1].pre_periods, (int)res[1].setups);
  EXPECT_GE(res[0].setups, res[0].pre_periods); // one a pre-period at 0
  EXPECT_LT(res[1].setups, res[0].setups / 2);
  EXPECT_NEAR(res[1].pre_periods, res[0].pre_periods, 0.2 * res[0].pre_periods);
  EXPECT_EQ(res[1].pre_retries, res[0].pre_retries);
  EXPECT_NEAR(res[1].period / res[0].period, 1.0, 2e-6); // the phase dependence, as above
  EXPECT_NEAR(res[1].frac_separated, res[0].frac_separated, 0.02);
}

// -shoot_pre_fp_tol: the pre-periods' flow solves its contact problems to a looser tolerance than
// the integrator's (-theta_fp_tol), which Newton's flows get back. Against pre-periods at the
// integrator's own tolerance: fewer contact iterations a step in them, the integrator's tolerance
// restored after, and Newton on the same cycle (within the discrete cycle's phase dependence, as above).
TEST(Shooting, PrePeriodsSolveTheirContactsLooselyAndNewtonAtTheIntegratorsTolerance)
{
  ThreeDofParams p;
  p.V = 3.0;
  ShootingResult res[2];
  for (int loose : {0, 1}) {
    Problem pr(p);
    pr.sh.Floquet().compute = PETSC_FALSE;
    pr.sh.pre_periods       = 200;
    pr.sh.pre_tol           = 1e-3;
    const PetscReal own     = pr.ti.FixedPointTolerance();
    EXPECT_EQ(own, 1e-12);
    pr.sh.pre_fp_tol = loose ? 1e-5 : own;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, res[loose]), 0) << res[loose].reason;
    EXPECT_TRUE(res[loose].converged);
    EXPECT_GT(res[loose].pre_periods, 0);
    EXPECT_EQ(pr.ti.FixedPointTolerance(), own) << "the integrator's tolerance was not restored after the pre-periods";
  }
  EXPECT_LT(res[1].pre_contact_iterations, res[0].pre_contact_iterations - 0.1);
  EXPECT_NEAR(res[1].period / res[0].period, 1.0, 2e-6);
  EXPECT_LE(std::abs(res[1].iterations - res[0].iterations), 1);
}

// Issue 19 item 4: steps per period and pre-periods follow from the model when not given. The
// 3-DOF cases keep what they were checked with (1000 steps, no pre-periods: the same iterates,
// bit for bit, as with both given); FE-sized models get 200 steps and up to 200 pre-periods to 0.02.
TEST(Shooting, DefaultsFollowTheModelAndLeaveTheThreeDofCasesAsTheyWere)
{
  EXPECT_EQ(Shooting::DefaultSteps(3), 1000);
  EXPECT_EQ(Shooting::DefaultSteps(99), 1000); // 2N + 1 = 199: dense bordered Jacobian
  EXPECT_EQ(Shooting::DefaultSteps(100), 200); // 201: GMRES on tangent products
  EXPECT_EQ(Shooting::DefaultSteps(180), 200); // the reduced small pad, as its transient
  EXPECT_EQ(Shooting::DefaultSteps(562), 200); // the reduced 2625-DOF pad
  // The trapezoidal rule turns x'' = -w^2 x by 2 atan(w h / 2) a step: the relative period error at
  // N_s steps is (2 pi / N_s) / (2 atan(pi / N_s)) - 1, about (2 pi / N_s)^2 / 12 (shooting.cpp).
  auto period_error = [](double ns) { return (2 * PETSC_PI / ns) / (2 * std::atan(PETSC_PI / ns)) - 1; };
  EXPECT_LT(period_error(200), 1e-4);
  EXPECT_NEAR(period_error(200), 8.2e-5, 0.1e-5);
  EXPECT_NEAR(period_error(1000), 3.3e-6, 0.1e-6);
  PetscInt  pp;
  PetscReal pt;
  Shooting::DefaultPrePeriods(3, &pp, &pt);
  EXPECT_EQ(pp, 0);
  EXPECT_EQ(pt, 0.05);
  Shooting::DefaultPrePeriods(180, &pp, &pt); // the reduced small pad: Newton converges from the estimate
  EXPECT_EQ(pp, 0);
  Shooting::DefaultPrePeriods(562, &pp, &pt);
  EXPECT_EQ(pp, 200);
  EXPECT_EQ(pt, 0.02);
  // The pre-periods' flow: every step on the models without default pre-periods, half above.
  EXPECT_EQ(Shooting::DefaultPreSteps(3, 1000), 1000);
  EXPECT_EQ(Shooting::DefaultPreSteps(180, 200), 200);
  EXPECT_EQ(Shooting::DefaultPreSteps(562, 200), 100);
  EXPECT_EQ(Shooting::DefaultPreSteps(562, 150), 100); // never below 100 a period (3.3e-4 in the period)
  EXPECT_NEAR(period_error(100), 3.3e-4, 0.1e-4);
  EXPECT_LT(period_error(100), 0.02 / 50); // far inside the pre-periods' return tolerance

  ThreeDofParams p;
  p.V = 0.75;
  ShootingResult dflt, given;
  {
    Problem pr(p);
    pr.sh.Floquet().compute = PETSC_FALSE;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, dflt), 0);
    EXPECT_EQ(pr.sh.steps, 1000);
    EXPECT_EQ(pr.sh.pre_periods, 0);
    EXPECT_EQ(pr.sh.pre_tol, 0.05);
  }
  Problem pr(p);
  pr.sh.Floquet().compute = PETSC_FALSE;
  pr.sh.steps       = 1000;
  pr.sh.pre_periods = 0;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, given), 0);
  // The same iterations to round-off: bit for bit on one rank; on two, components that are zero
  // up to round-off (1e-24 against -3e-24, seen in CI) come out of reductions in another order.
  EXPECT_EQ(dflt.iterations, given.iterations);
  EXPECT_NEAR(dflt.period / given.period, 1.0, 1e-14);
  ASSERT_EQ(dflt.Z0.size(), given.Z0.size());
  PetscReal scale = 0;
  for (PetscReal z : given.Z0) scale = std::max(scale, std::abs(z));
  for (size_t i = 0; i < given.Z0.size(); ++i) EXPECT_NEAR(dflt.Z0[i], given.Z0[i], 1e-13 * scale) << i;
}

// -shoot_pre_steps: the pre-periods run coarse until they return, then on the fine flow until they
// return again, so Newton starts from the fine flow. Case 1 at mu = 5 (impacts, two loops, the
// period moved beyond the bracket on the way): the coarse flow at 250 steps a period must measure
// the same period and lead Newton to the same cycle within the step's error. Not to the same
// discrete orbit: the discrete flow has periodic orbits whose impacts fall a fraction of a step
// apart, and Newton from the two starts converges to two of them (periods 3.9e-6 apart, the
// trapezoidal rule's own period error at 1000 steps being 3.3e-6; peak-to-peak 2e-4 apart).
TEST(Shooting, CoarsePrePeriodsEndOnTheFineFlowAndReachTheCycleWithinTheStepError)
{
  ThreeDofParams p; // case 1
  p.mu = 5;
  ShootingResult fine, coarse;
  for (PetscInt ps : {1000, 250}) {
    Problem pr(p);
    ASSERT_TRUE(pr.est.found);
    pr.sh.Floquet().compute = PETSC_FALSE;
    pr.sh.pre_periods       = 100;
    pr.sh.pre_steps         = ps;
    ShootingResult &sr      = ps == 1000 ? fine : coarse;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0) << sr.reason;
    EXPECT_TRUE(sr.converged);
    EXPECT_EQ(pr.sh.steps, 1000); // put back after the pre-periods
  }
  // The coarse flow ran, and the pre-periods ended on the fine one.
  EXPECT_EQ(fine.pre_coarse_periods, 0);
  EXPECT_GT(coarse.pre_coarse_periods, 0);
  EXPECT_LT(coarse.pre_coarse_periods, coarse.pre_periods);
  EXPECT_TRUE(coarse.bracket_recentred);
  EXPECT_NEAR(coarse.pre_measured_period / fine.pre_measured_period, 1.0, 1e-2);
  EXPECT_NEAR(coarse.period / fine.period, 1.0, 2e-5);
  // Z0 lies on the cycle at a phase the start sets: the cycles compared by period and extent.
  if (!Rank0()) return;
  ASSERT_EQ(coarse.peak_to_peak.size(), fine.peak_to_peak.size());
  for (size_t i = 0; i < fine.peak_to_peak.size(); ++i) EXPECT_NEAR(coarse.peak_to_peak[i] / fine.peak_to_peak[i], 1.0, 1e-3) << i;
}

// Issue 20 item 4: case 1 at mu = 5 settles on a cycle of 2.14 T_lin (two loops per period, their
// returns 2 % apart), beyond the bracket (T0/2, 2 T0) around the linear period, which Newton leaves from the
// energy estimate. The pre-periods measure the period of their motion at its returns to a Poincare
// section and move the start period and the bracket onto it; Newton must then converge there, to
// the period of a long transient at the same step (independent: mean-crossings of DOF 0 read by
// TransientAnalysis's summary, not the shooting's section).
TEST(Shooting, PrePeriodsMeasureAPeriodBeyondTheBracketAndConvergeThere)
{
  ThreeDofParams p; // case 1
  p.mu = 5;
  {
    Problem pr(p);
    ASSERT_TRUE(pr.est.found);
    pr.sh.Floquet().compute = PETSC_FALSE;
    ShootingResult sr;
    PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
    const PetscErrorCode e = pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr);
    PetscPopErrorHandler();
    EXPECT_NE(e, 0);
    EXPECT_NE(sr.reason.find("the period left"), std::string::npos) << sr.reason;
    EXPECT_FALSE(sr.bracket_recentred);
  }
  Problem pr(p);
  ASSERT_TRUE(pr.est.found);
  pr.sh.Floquet().compute = PETSC_FALSE;
  pr.sh.pre_periods = 100;
  ShootingResult sr;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, pr.est.U0, pr.est.dU0, pr.est.T0, sr), 0) << sr.reason;
  EXPECT_TRUE(sr.converged);
  EXPECT_TRUE(sr.bracket_recentred);
  EXPECT_LT(sr.pre_periods, 100);
  EXPECT_GT(sr.period, 2 * pr.est.T0); // outside the linear period's bracket
  EXPECT_NEAR(sr.pre_measured_period / sr.period, 1.0, 1e-2);
  EXPECT_NEAR(sr.bracket_centre / sr.period, 1.0, 1e-2);

  TransientAnalysis ta(PETSC_COMM_WORLD);
  ThetaIntegrator   ti2(PETSC_COMM_WORLD);
  ASSERT_EQ(ta.SetFromOptions(), 0);
  ASSERT_EQ(ti2.SetFromOptions(), 0);
  ta.h       = sr.period / pr.sh.steps; // equal steps: the discrete cycles are the same
  ta.periods = 400;                     // of T_lin; settled (state return < 1e-8) well before
  TransientResult tr;
  ASSERT_EQ(ta.Run(pr.model, pr.eq, pr.stab, ti2, tr), 0);
  if (!Rank0()) return;
  EXPECT_TRUE(tr.summary.settled);
  EXPECT_NEAR(tr.summary.period / sr.period, 1.0, 1e-6);
  for (int j = 0; j < 3; ++j) EXPECT_NEAR(tr.summary.peak_to_peak[j] / sr.peak_to_peak[j], 1.0, 1e-3) << "DOF " << j;
  EXPECT_GT(sr.frac_separated, 0.1);
  EXPECT_GT(sr.frac_stuck, 0.01);
}

// A start ten times below the energy estimate (case 1: no contact opens or sticks along its flow)
// lies where the period map is linear, and the only fixed point of a linear map is the sliding
// equilibrium Z_e: plain Newton goes there ("collapsed onto the sliding equilibrium"), and so does
// any globalisation on ||H||, which is 0 at Z_e. Deflated (-shoot_deflate_power 2, m = (d/d_0)^-2 + 1,
// with backtracking on ||m H||) it reaches the limit cycle: the one the transient settles on.
TEST(Shooting, DeflationTakesAStartInTheLinearRegimeToTheCycleNotTheEquilibrium)
{
  ThreeDofParams p; // case 1
  Problem        pr(p);
  ASSERT_TRUE(pr.est.found);
  Vec U0, dU0;
  ASSERT_EQ(TenthOfTheEstimate(pr, &U0, &dU0), 0);
  pr.sh.Floquet().compute = PETSC_FALSE;
  ShootingResult plain, defl;
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  const PetscErrorCode e = pr.sh.Solve(pr.model, pr.eq, pr.ti, U0, dU0, pr.est.T0, plain);
  PetscPopErrorHandler();
  EXPECT_NE(e, 0);
  EXPECT_FALSE(plain.converged);
  EXPECT_NE(plain.reason.find("collapsed onto the sliding equilibrium"), std::string::npos) << plain.reason;

  pr.sh.deflate_power = 2;
  pr.sh.deflate_shift = 1;
  ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, U0, dU0, pr.est.T0, defl), 0) << defl.reason;
  EXPECT_TRUE(defl.converged);
  EXPECT_LE(defl.iterations, 10); // measured 9
  EXPECT_LT(defl.residual, 1e-5);

  // The settled cycle of a transient of the same model at the same step.
  TransientAnalysis ta(PETSC_COMM_WORLD);
  ThetaIntegrator   ti2(PETSC_COMM_WORLD);
  ASSERT_EQ(ta.SetFromOptions(), 0);
  ASSERT_EQ(ti2.SetFromOptions(), 0);
  ta.h       = defl.period / pr.sh.steps;
  ta.periods = 120;
  TransientResult tr;
  ASSERT_EQ(ta.Run(pr.model, pr.eq, pr.stab, ti2, tr), 0);
  if (Rank0()) { // the orbit's summaries live on rank 0
    // Not the equilibrium: the cycle lifts off for about half of each period (README.md, "A worked
    // example": 48.5 %).
    EXPECT_GT(defl.frac_separated, 0.3);
    EXPECT_NEAR(tr.summary.period / defl.period, 1.0, 1e-4);
    for (int j = 0; j < 2; ++j) EXPECT_NEAR(tr.summary.peak_to_peak[j] / defl.peak_to_peak[j], 1.0, 1e-3) << "DOF " << j;
  }
  VecDestroy(&U0), VecDestroy(&dU0);
}

// -shoot_pre_boost near the threshold (case 1 at mu = 0.15: sigma = 3.03 1/s, sigma T = 0.034): from a
// start ten times below the energy estimate the flow gains 7 % of its energy a period, steadily, and
// returns within -shoot_pre_tol 0.05 after 5 periods only because it grows slowly. Newton from there
// heads for Z_e and fails; the plain flow then needs 64 more periods to 0.005 before Newton converges.
// Boosted, the pre-periods neither stop nor hand over while the flow grows at its linear rate; the drift
// runs 1 + b times faster, it hands over at 0.3 of the tolerance, and Newton converges from the first
// start on the same cycle.
TEST(Shooting, BoostedPrePeriodsLeaveTheLinearGrowthBeforeNewton)
{
  ThreeDofParams p; // case 1
  p.mu = 0.15;
  ShootingResult res[2];
  PetscInt       flow[2];
  for (int b : {0, 1}) {
    Problem pr(p);
    ASSERT_TRUE(pr.est.found);
    ASSERT_EQ(pr.stab.unstable.size(), 1u);
    Vec U0, dU0;
    ASSERT_EQ(TenthOfTheEstimate(pr, &U0, &dU0), 0);
    pr.sh.Floquet().compute = PETSC_FALSE;
    pr.sh.pre_periods       = 400;
    pr.sh.pre_tol           = 0.05;
    pr.sh.pre_boost         = b ? 10 : 0;
    ASSERT_EQ(pr.sh.Solve(pr.model, pr.eq, pr.ti, U0, dU0, pr.est.T0, res[b]), 0) << "boost " << b << ": " << res[b].reason;
    EXPECT_TRUE(res[b].converged);
    flow[b] = res[b].pre_periods + res[b].newton_evaluations;
    VecDestroy(&U0), VecDestroy(&dU0);
  }
  EXPECT_GE(res[0].pre_retries, 1) << "the plain flow's first start: Newton from the linear growth";
  EXPECT_EQ(res[1].pre_retries, 0) << "boosted: Newton converges from the first start";
  EXPECT_LT(res[1].pre_periods, res[0].pre_periods); // measured 36 against 69
  EXPECT_LT(flow[1], flow[0]);
  // The same cycle: the discrete one's period moves with the phase Newton settles at (2e-6, above).
  EXPECT_NEAR(res[1].period / res[0].period, 1.0, 2e-6);
  EXPECT_NEAR(res[1].frac_separated, res[0].frac_separated, 0.02);
}

// The verdict is only as good as the multipliers: a margin inside their error is "undecided".
// Cases: the 2625-DOF pad's cycle (0.9743, trivial 1 + 1.8e-3), the half brake's CB-30 cycle
// (1.000652, trivial 1 + 4.75e-4), and the same with a phase dependence of 1e-3.
TEST(Floquet, VerdictIsUndecidedWhenTheMarginIsWithinTheError)
{
  FloquetVerdictResult v = FloquetVerdict(0.9743, 1.8e-3);
  EXPECT_STREQ(v.word, "stable");
  EXPECT_NEAR(v.margin, 0.0257, 1e-12);
  EXPECT_EQ(v.error, 1.8e-3);
  EXPECT_STREQ(FloquetVerdict(1.000652, 4.75e-4).word, "unstable");
  v = FloquetVerdict(1.000652, 4.75e-4, 1e-3);
  EXPECT_STREQ(v.word, "undecided");
  EXPECT_EQ(v.error, 1e-3);
  EXPECT_STREQ(FloquetVerdict(0.9995, 1e-3).word, "undecided");
  EXPECT_STREQ(FloquetVerdict(1.0, 0.0).word, "undecided"); // exactly on the boundary: no verdict
}

// The report names a trivial multiplier that was not computed. The half brake's interface-reduced
// cycle (682 DOFs, block Arnoldi with -floquet_nev 4): the four largest are two pairs of modulus
// 0.99977 and 0.99972; the nearest to 1 is 1.28 away, so the trivial one lies below them. With the
// CB model's trivial 1.000804 the usual advice (refine the step) stands.
// -floquet_tol_error: block Arnoldi stops at a fraction of the trivial multiplier's distance from 1
// (the step's own error on every multiplier, the verdict's error bar) when that is above
// -floquet_tol, taking the Ritz value nearest 1 for the trivial one, at most 1e-4, and not at all
// when no Ritz value is within 0.1 of 1 (the trivial one not yet, or not, among them).
TEST(Floquet, ArnoldiStopsAtAFractionOfTheTrivialMultipliersError)
{
  using C = std::complex<PetscReal>;
  const std::vector<C> pad{C(1.000241, 0), C(0.9608, 0.01), C(0.9608, -0.01), C(0.95, 0)};
  EXPECT_NEAR(FloquetArnoldiTolerance(1e-8, 1e-2, pad), 1e-2 * 2.41e-4, 1e-16);
  EXPECT_DOUBLE_EQ(FloquetArnoldiTolerance(1e-8, 0.0, pad), 1e-8);          // off
  EXPECT_DOUBLE_EQ(FloquetArnoldiTolerance(1e-5, 1e-2, pad), 1e-5);         // tol is larger
  EXPECT_DOUBLE_EQ(FloquetArnoldiTolerance(1e-8, 1e-2, {C(0.98, 0), C(1.05, 0.02)}), 1e-4); // capped
  EXPECT_DOUBLE_EQ(FloquetArnoldiTolerance(1e-8, 1e-2, {C(1.3, 0), C(0.7, 0)}), 1e-8);       // none near 1
  EXPECT_DOUBLE_EQ(FloquetArnoldiTolerance(1e-8, 1e-2, {}), 1e-8);
}

TEST(Floquet, ArnoldiChecksSoonerWhereTheResidualsDecayReachesTheTolerance)
{
  // The cadence alone: every block up to 8, then ceil(count / 8) blocks apart (22 -> 26, 8 -> 10).
  EXPECT_EQ(FloquetNextCheck(3, 0, 0.0, 0.5, 1e-5), 4);
  EXPECT_EQ(FloquetNextCheck(8, 7, 0.2, 0.1, 1e-5), 10);  // 0.1 -> 1e-5 at 0.5 a block: 14 blocks on
  EXPECT_EQ(FloquetNextCheck(8, 0, 0.0, 0.1, 1e-5), 10);  // no check before
  EXPECT_EQ(FloquetNextCheck(22, 0, 0.0, 7e-5, 1.5e-5), 26);
  EXPECT_EQ(FloquetNextCheck(22, 19, 6e-5, 7e-5, 1.5e-5), 26); // not falling
  // pad_cycle.yaml's residuals: 6.33e-4 at 19 blocks, 7.02e-5 at 22 (0.48 a block): 1.5e-5 after
  // log(0.214) / log(0.48) = 2.1 blocks more, so 25.
  EXPECT_EQ(FloquetNextCheck(22, 19, 6.33e-4, 7.02e-5, 1.5e-5), 25);
  EXPECT_EQ(FloquetNextCheck(22, 19, 1e-2, 2e-5, 1.5e-5), 23); // at least one block
  EXPECT_EQ(FloquetNextCheck(40, 35, 1e-3, 9e-4, 1e-8), 46);    // slow decay: the cadence bounds it
}

// Past -floquet_max_dim only where the residuals are about to reach the tolerance: the size-1
// brake's 1.67e-3 at 35 blocks and 1.56e-4 at the cap, 40, fall 0.62 a block, so 7e-6 at 47
// (it converged at 46, 3.2e-6); a flat, rising or first check gives no reach.
TEST(Floquet, ArnoldiGoesPastItsCapOnlyWhereTheResidualsReachTheTolerance)
{
  EXPECT_EQ(FloquetBlocksToReach(40, 35, 1.67e-3, 1.56e-4, 7e-6), 47);
  EXPECT_EQ(FloquetBlocksToReach(40, 35, 1.0e-2, 9.6e-3, 7e-6), 925); // 0.992 a block: far past 60, the default extension
  EXPECT_EQ(FloquetBlocksToReach(40, 35, 1e-2, 1e-2, 1e-5), 0);             // flat
  EXPECT_EQ(FloquetBlocksToReach(40, 35, 1e-3, 1e-2, 1e-5), 0);             // rising
  EXPECT_EQ(FloquetBlocksToReach(40, 0, 0.0, 1e-2, 1e-5), 0);               // no check before
  EXPECT_EQ(FloquetBlocksToReach(40, 35, 1e-3, 1e-6, 1e-5), 0);             // already there
}

TEST(Floquet, ReportSaysWhenTheTrivialMultiplierIsNotAmongThoseComputed)
{
  auto report = [](const std::vector<std::complex<PetscReal>> &L, PetscInt trivial) {
    Shooting      sh(PETSC_COMM_WORLD);
    ShootingResult res;
    res.floquet         = L;
    res.trivial         = trivial;
    res.floquet_method  = "block Arnoldi on exact step tangents";
    res.floquet_phases  = 1;
    res.floquet_verdict = "undecided";
    const std::string path = ::testing::TempDir() + "floquet_report.txt";
    PetscViewer       v;
    PetscCallAbort(PETSC_COMM_WORLD, PetscViewerASCIIOpen(PETSC_COMM_WORLD, path.c_str(), &v));
    PetscCallAbort(PETSC_COMM_WORLD, sh.Floquet().View(res, v));
    PetscCallAbort(PETSC_COMM_WORLD, PetscViewerDestroy(&v));
    std::ifstream     in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  const std::string missing = report({{0.182179, -0.983032}, {0.182179, 0.983032}, {0.176539, -0.984006}, {0.176539, 0.984006}}, 0);
  if (Rank0()) {
    EXPECT_NE(missing.find("WARNING: no multiplier within 0.1 of 1 among the 4 computed"), std::string::npos) << missing;
    EXPECT_NE(missing.find("raise -floquet_nev"), std::string::npos);
    EXPECT_EQ(missing.find("refine -shoot_steps"), std::string::npos);
  }
  const std::string found = report({{1.000804, 0}, {0.118039, 0.992348}, {0.118039, -0.992348}, {-0.210687, 0.976530}}, 0);
  if (Rank0()) {
    EXPECT_EQ(found.find("WARNING: no multiplier"), std::string::npos) << found;
    EXPECT_NE(found.find("refine -shoot_steps"), std::string::npos);
  }
}

TEST(Shooting, ModalTangentFlowEqualsTheNodalOne)
{
  // Step tangents in the modal coordinates of (K, M) (-theta_modal_tangent; the chain's C = c I is
  // diagonal there) against the nodal ones, on the 4-contact chain's cycle (closed, sticking and
  // sliding points): a block of 5 columns with the period derivative, and one column. The two differ
  // by the round-off of the basis (measured 7.7e-14 and 5.1e-14 relative).
  Problem        chain([](Model &m) { return BuildChain(PETSC_COMM_WORLD, ChainParams{}, m); });
  ShootingResult sr;
  chain.sh.Floquet().compute = PETSC_FALSE;
  ASSERT_EQ(chain.sh.Solve(chain.model, chain.eq, chain.ti, chain.est.U0, chain.est.dU0, chain.est.T0, sr), 0);
  PetscInt N;
  VecGetSize(chain.eq.U, &N);
  const Eigen::Index k = 5;
  Eigen::MatrixXd    dZ0 = Eigen::MatrixXd::Random(2 * N, k);
  Eigen::RowVectorXd dT  = Eigen::RowVectorXd::Random(k) * sr.period;
  MPI_Bcast(dZ0.data(), (int)dZ0.size(), MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  MPI_Bcast(dT.data(), (int)k, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  Vec x;
  ASSERT_EQ(CycleStart(chain, sr, &x), 0);
  Eigen::MatrixXd nodal[2], modal[2];
  bool            on = true;
  for (const char *mode : {"false", "true"}) {
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-theta_modal_tangent", mode), 0);
    ASSERT_EQ(chain.ti.SetFromOptions(), 0);
    Eigen::MatrixXd *out = mode[0] == 't' ? modal : nodal;
    ASSERT_EQ(chain.sh.TangentFlow(x, dZ0, dT, out[0]), 0);
    ASSERT_EQ(chain.sh.TangentFlow(x, dZ0.col(2), dT.segment(2, 1), out[1]), 0);
    ASSERT_EQ(chain.ti.ModalTangent(&on), 0);
    EXPECT_EQ(on, mode[0] == 't');
  }
  // auto: on 12 DOFs with 3 n_c = 12 and a dense H^T the modal products, (2 * 12 + 4) * 12 + 24 =
  // 360 multiply-adds a column and step, cost 0.58 of the nodal 2 * 144 + 144 + (12 + 4) * 12 = 624.
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-theta_modal_tangent", "auto"), 0);
  ASSERT_EQ(chain.ti.SetFromOptions(), 0);
  ASSERT_EQ(chain.ti.ModalTangent(&on), 0);
  EXPECT_TRUE(on);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-theta_modal_tangent"), 0);
  ASSERT_EQ(chain.ti.SetFromOptions(), 0);
  const double block = (modal[0] - nodal[0]).norm() / nodal[0].norm(), one = (modal[1] - nodal[1]).norm() / nodal[1].norm();
  if (Rank0()) std::printf("modal against nodal tangents: block of %d %.2e, one column %.2e\n", (int)k, block, one);
  EXPECT_LT(block, 1e-12);
  EXPECT_LT(one, 1e-12);
  VecDestroy(&x);
}

TEST(Shooting, TangentsInFloatAgreeWithDouble)
{
  // -theta_tangent_single: the tangents' products with their dense step matrices in float, and the
  // closed points' step factors computed and kept in float. Nodal: P1 - I, P2 and Y; modal: H^T Phi
  // and its normal rows, and with the dense G (a damping the modes do not diagonalise) G - I and
  // G (H^T Phi)^T too. On the 4-contact chain's cycle, a block of 5
  // columns and one column against the double tangents: float's round-off carried over a period
  // (measured 2.7e-6 to 2.2e-5 relative, by the case and the random directions). The flows stay in
  // double: Newton converges to the same cycle (to its tolerance: its path differs with the
  // Jacobian, measured up to 1.8e-8), and the Floquet multipliers (the chain's dense monodromy, from
  // the same tangents) move by 2e-7 to 1.1e-6. With P1 itself rounded, they had moved by 7.9e-6.
  struct Case {
    const char *name, *modal;
    bool        dense;
  };
  for (const Case &c : {Case{"nodal", "false", false}, Case{"diagonal modal", "true", false}, Case{"dense modal", "true", true}}) {
    std::srand(11);
    Problem chain([&c](Model &m) {
      PetscCall(BuildChain(PETSC_COMM_WORLD, ChainParams{}, m));
      return c.dense ? test::NonProportionalDamping(m) : PetscErrorCode(0);
    });
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-theta_modal_tangent", c.modal), 0);
    Eigen::MatrixXd    dZ0, block[2], one[2];
    Eigen::RowVectorXd dT;
    RandomDirections(chain, 5, dZ0, dT);
    ShootingResult sr[2];
    for (int single = 0; single < 2; ++single) {
      ASSERT_EQ(PetscOptionsSetValue(nullptr, "-theta_tangent_single", single ? "1" : "0"), 0);
      ASSERT_EQ(chain.ti.SetFromOptions(), 0);
      ASSERT_EQ(chain.sh.Solve(chain.model, chain.eq, chain.ti, chain.est.U0, chain.est.dU0, chain.est.T0, sr[single]), 0);
      ASSERT_TRUE(sr[single].converged);
      ASSERT_GE(sr[single].floquet.size(), 4u);
      bool on = false;
      ASSERT_EQ(chain.ti.ModalTangent(&on), 0);
      EXPECT_EQ(on, c.modal[0] == 't');
      EXPECT_EQ(chain.ti.ModalDense(), c.dense);
      Vec x;
      ASSERT_EQ(CycleStart(chain, sr[0], &x), 0);
      ASSERT_EQ(chain.sh.TangentFlow(x, dZ0, dT * sr[0].period, block[single]), 0);
      ASSERT_EQ(chain.sh.TangentFlow(x, dZ0.col(2), (dT * sr[0].period).segment(2, 1), one[single]), 0);
      VecDestroy(&x);
    }
    ASSERT_EQ(PetscOptionsClearValue(nullptr, "-theta_tangent_single"), 0);
    ASSERT_EQ(PetscOptionsClearValue(nullptr, "-theta_modal_tangent"), 0);
    ASSERT_EQ(chain.ti.SetFromOptions(), 0);
    const double db = (block[1] - block[0]).norm() / block[0].norm(), d1 = (one[1] - one[0]).norm() / one[0].norm();
    const double dp = std::abs(sr[1].period - sr[0].period) / sr[0].period;
    double       dl = 0;
    for (size_t i = 0; i < 4; ++i) dl = std::max(dl, std::abs(sr[1].floquet[i] - sr[0].floquet[i]));
    if (Rank0())
      std::printf("%s tangents, float against double: block of 5 %.2e, one column %.2e; cycle's period %.2e, multipliers %.2e\n", c.name, db, d1,
                  dp, dl);
    EXPECT_GT(db, 1e-10) << c.name; // the float products were taken
    EXPECT_LT(db, 1e-4) << c.name;
    EXPECT_LT(d1, 1e-4) << c.name;
    EXPECT_LT(dp, 1e-7) << c.name;
    EXPECT_LT(dl, 1e-5) << c.name;
  }
}

TEST(Shooting, ModalTangentTakesTheDenseGWhereTheModesDoNotDiagonaliseC)
{
  // A damping that (K, M)'s modes do not diagonalise: the modal tangents then take the dense
  // G = A_m^-1, where they cost less than 0.8 of the nodal products (N = 72 with 4 contacts:
  // 72^2 + 28 * 72 + 144 = 7 344 multiply-adds a column and step against 11 264) or are asked for.
  ChainParams cp;
  cp.cells         = 24;
  cp.contact_every = 6;
  Model model;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, cp, model), 0);
  ASSERT_EQ(test::NonProportionalDamping(model), 0);
  ThetaIntegrator ti(PETSC_COMM_WORLD);
  bool            on = false;
  ASSERT_EQ(ti.SetFromOptions(), 0);
  ASSERT_EQ(ti.SetUp(model, 1e-5), 0);
  EXPECT_FALSE(ti.ModalStep()); // one step size: the dense modal step reads more words a step
  ASSERT_EQ(ti.ModalTangent(&on), 0);
  EXPECT_TRUE(on);
  EXPECT_TRUE(ti.ModalDense());
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-theta_modal_tangent", "false"), 0);
  ASSERT_EQ(ti.SetFromOptions(), 0);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-theta_modal_tangent"), 0);
  ASSERT_EQ(ti.ModalTangent(&on), 0);
  EXPECT_FALSE(on);
  // Shooting sets up a step size per period (SetManySetUps): the step is modal too, with G.
  ThetaIntegrator tis(PETSC_COMM_WORLD);
  ASSERT_EQ(tis.SetFromOptions(), 0);
  tis.SetManySetUps(true);
  ASSERT_EQ(tis.SetUp(model, 1e-5), 0);
  EXPECT_TRUE(tis.ModalStep());
  EXPECT_TRUE(tis.ModalDense());
  // The same chain with C = c I (proportional to M): the diagonal modal tangents.
  Model model2;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, cp, model2), 0);
  ThetaIntegrator ti2(PETSC_COMM_WORLD);
  ASSERT_EQ(ti2.SetFromOptions(), 0);
  ASSERT_EQ(ti2.SetUp(model2, 1e-5), 0);
  ASSERT_EQ(ti2.ModalTangent(&on), 0);
  EXPECT_TRUE(on);
  EXPECT_FALSE(ti2.ModalDense());
  // The basis is kept while M, K, C are unchanged (summed once per set-up, not per call): after C
  // changes in place to the non-diagonalisable one, the next set-up must see it.
  ASSERT_EQ(MatCopy(model.C, model2.C, SAME_NONZERO_PATTERN), 0);
  ASSERT_EQ(ti2.SetUp(model2, 1e-5), 0);
  ASSERT_EQ(ti2.ModalTangent(&on), 0);
  EXPECT_TRUE(on);
  EXPECT_TRUE(ti2.ModalDense());
}

TEST(Shooting, DenseModalStepAndTangentsGiveTheNodalCycle)
{
  // The 4-contact chain with a damping its modes do not diagonalise, shot with the modal step and
  // tangents on the dense G (-theta_modal_step true, -theta_modal_tangent true) and with the nodal
  // ones: the same cycle, and along it the same tangents (a block of 5 columns with the period
  // derivative, and one column), to the round-off of the basis.
  Problem chain([](Model &m) {
    PetscCall(BuildChain(PETSC_COMM_WORLD, ChainParams{}, m));
    return test::NonProportionalDamping(m);
  });
  chain.sh.Floquet().compute = PETSC_FALSE;
  const Eigen::Index k = 5;
  Eigen::MatrixXd    dZ0;
  Eigen::RowVectorXd dT;
  RandomDirections(chain, k, dZ0, dT);
  ShootingResult  sr[2];
  Eigen::MatrixXd block[2], one[2];
  for (int modal = 0; modal < 2; ++modal) {
    for (const char *o : {"-theta_modal_step", "-theta_modal_tangent"}) ASSERT_EQ(PetscOptionsSetValue(nullptr, o, modal ? "true" : "false"), 0);
    ASSERT_EQ(chain.ti.SetFromOptions(), 0);
    ASSERT_EQ(chain.sh.Solve(chain.model, chain.eq, chain.ti, chain.est.U0, chain.est.dU0, chain.est.T0, sr[modal]), 0);
    ASSERT_TRUE(sr[modal].converged);
    EXPECT_EQ(chain.ti.ModalStep(), modal == 1);
    Vec x;
    ASSERT_EQ(CycleStart(chain, sr[0], &x), 0);
    ASSERT_EQ(chain.sh.TangentFlow(x, dZ0, dT * sr[0].period, block[modal]), 0);
    ASSERT_EQ(chain.sh.TangentFlow(x, dZ0.col(2), (dT * sr[0].period).segment(2, 1), one[modal]), 0);
    bool on = false;
    ASSERT_EQ(chain.ti.ModalTangent(&on), 0);
    EXPECT_EQ(on, modal == 1);
    EXPECT_EQ(chain.ti.ModalDense(), modal == 1);
    VecDestroy(&x);
  }
  for (const char *o : {"-theta_modal_step", "-theta_modal_tangent"}) ASSERT_EQ(PetscOptionsClearValue(nullptr, o), 0);
  ASSERT_EQ(chain.ti.SetFromOptions(), 0);
  const double db = (block[1] - block[0]).norm() / block[0].norm(), d1 = (one[1] - one[0]).norm() / one[0].norm();
  const double dp = std::abs(sr[1].period - sr[0].period) / sr[0].period;
  if (Rank0()) std::printf("dense modal against nodal: period %.2e, tangents: block of %d %.2e, one column %.2e\n", dp, (int)k, db, d1);
  EXPECT_LT(dp, 1e-10);
  EXPECT_LT(db, 1e-11);
  EXPECT_LT(d1, 1e-11);
}
