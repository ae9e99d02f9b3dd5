// The non-smooth theta-method: linear accuracy and order against the exact solution, inelastic
// impact, stick, both reference limit cycles with their energy balance, and extreme settings.
#include "dense.h"
#include "squeal/integration/monodromy.h"
#include "squeal/integration/transient.h"
#include "squeal/model/builders.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <random>

using namespace squeal;

namespace {

// Exact state of M u'' + C u' + K u = F at time t from (u0, v0): z = z_s + V e^{D t} V^-1 (z0 - z_s).
Eigen::VectorXd ExactLinear(const Eigen::MatrixXd &M, const Eigen::MatrixXd &C, const Eigen::MatrixXd &K, const Eigen::VectorXd &F,
                            const Eigen::VectorXd &z0, double t)
{
  const Eigen::Index n = M.rows();
  Eigen::MatrixXd    A = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  A.topRightCorner(n, n)    = Eigen::MatrixXd::Identity(n, n);
  A.bottomLeftCorner(n, n)  = -M.inverse() * K;
  A.bottomRightCorner(n, n) = -M.inverse() * C;
  Eigen::VectorXd zs        = Eigen::VectorXd::Zero(2 * n);
  zs.head(n)                = K.ldlt().solve(F);
  Eigen::EigenSolver<Eigen::MatrixXd> es(A);
  const Eigen::MatrixXcd              V = es.eigenvectors();
  Eigen::VectorXcd                    e = (es.eigenvalues() * t).array().exp();
  const Eigen::VectorXcd              c = V.partialPivLu().solve((z0 - zs).cast<std::complex<double>>());
  return zs + (V * (e.asDiagonal() * c)).real();
}

struct Run {
  Model           model;
  ThetaIntegrator ti{PETSC_COMM_WORLD};
};

void SetState(Vec v, const Eigen::VectorXd &x)
{
  PetscInt lo, hi;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetOwnershipRange(v, &lo, &hi));
  for (PetscInt i = lo; i < hi; ++i) PetscCallAbort(PETSC_COMM_WORLD, VecSetValue(v, i, x[i], INSERT_VALUES));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyBegin(v));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyEnd(v));
}

double LinearError(double theta, PetscInt steps, bool dense)
{
  ThreeDofParams p;
  Model          model;
  PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, p, model));
  model.contacts.points.clear(); // no contact: a linear ODE
  ThetaIntegrator ti(PETSC_COMM_WORLD);
  PetscCallAbort(PETSC_COMM_WORLD, ti.SetFromOptions());
  PetscCallAbort(PETSC_COMM_WORLD, ti.SetTheta(theta));
  PetscCallAbort(PETSC_COMM_WORLD, ti.SetDenseMax(dense ? 1000 : 0));
  const double T = 0.005;
  PetscCallAbort(PETSC_COMM_WORLD, ti.SetUp(model, T / steps));
  Eigen::VectorXd z0(6);
  z0 << 1e-3, -2e-3, 5e-4, 0.1, 0.3, -0.2;
  Vec U, dU;
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(model.F, &U));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(model.F, &dU));
  SetState(U, z0.head(3));
  SetState(dU, z0.tail(3));
  Eigen::VectorXd r(0);
  StepInfo        info;
  for (PetscInt i = 0; i < steps; ++i) PetscCallAbort(PETSC_COMM_WORLD, ti.Step(U, dU, r, &info));
  Eigen::VectorXd z(6);
  z << test::ToDense(U), test::ToDense(dU);
  const Eigen::VectorXd ex = ExactLinear(test::ToDense(model.M), test::ToDense(model.C), test::ToDense(model.K),
                                         test::ToDense(model.F), z0, T);
  PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&U));
  PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&dU));
  return (z.head(3) - ex.head(3)).norm() / ex.head(3).norm();
}

// The 24-cell chain of the back-end comparisons below (N = 72, a contact on every cell, rotated
// frames, so 1 to 2 non-zeros in a row of H^T), from its sliding equilibrium with a velocity
// pattern that opens and slides points, set up in two integrators (prefix null: the default
// "theta_") at h = 2e-6 on the dense back end.
void ChainRuns(Model &model, SlidingEquilibrium &eq, Eigen::VectorXd &v0, test::Integration (&run)[2], const char *const (&prefix)[2],
               bool nonproportional = false)
{
  ChainParams cp;
  cp.cells  = 24;
  cp.cell.V = 0.75;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, cp, model), 0);
  if (nonproportional) {
    ASSERT_EQ(test::NonProportionalDamping(model), 0);
  }
  EquilibriumSolver eqs(PETSC_COMM_WORLD);
  ASSERT_EQ(eqs.Solve(model, eq), 0);
  const PetscInt N = model.Size(), nc = model.contacts.Size();
  ASSERT_EQ(N, 72);
  ASSERT_EQ(nc, 24);
  v0.resize(N);
  for (PetscInt i = 0; i < N; ++i) v0[i] = i % 3 == 2 ? 0.05 * std::sin(1.3 * (double)i) : 0.6 * std::sin(0.7 * (double)i + 0.3);
  for (PetscInt c = 0; c < nc; c += 2) // every other point starts at its surface's speed
    for (int a = 0; a < 3; ++a) v0[3 * c + a] = model.contacts.Speed(c) * model.contacts.points[(size_t)c].t[a];
  for (int k = 0; k < 2; ++k) {
    if (prefix[k]) {
      ASSERT_EQ(run[k].ti.SetOptionsPrefix(prefix[k]), 0);
    }
    ASSERT_EQ(run[k].ti.SetFromOptions(), 0);
    ASSERT_EQ(run[k].ti.SetDenseMax(200), 0); // the dense back end also under -theta_dense_max 0 (ctest unit_tests_np2_sparse)
    ASSERT_EQ(run[k].ti.SetUp(model, 2e-6), 0);
    ASSERT_EQ(VecDuplicate(eq.U, &run[k].U), 0);
    ASSERT_EQ(VecCopy(eq.U, run[k].U), 0);
    ASSERT_EQ(VecDuplicate(eq.U, &run[k].dU), 0);
    SetState(run[k].dU, v0);
    run[k].r.setZero(3 * nc);
    for (PetscInt c = 0; c < nc; ++c) run[k].r[3 * c + kN] = eq.N[(size_t)c];
  }
}

} // namespace

TEST(Theta, LinearConvergenceOrders)
{
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  for (bool dense : {true, false}) {
    if (dense && size > 1) continue; // the dense back end is a one-rank path
    for (double theta : {0.5, 1.0}) {
      const double e1 = LinearError(theta, 400, dense), e2 = LinearError(theta, 800, dense), e3 = LinearError(theta, 1600, dense);
      const double order = std::log2(e2 / e3);
      const double expected = theta == 0.5 ? 2.0 : 1.0;
      EXPECT_NEAR(order, expected, 0.1) << "theta " << theta << (dense ? " dense" : " sparse") << " errors " << e1 << " " << e2 << " " << e3;
      EXPECT_NEAR(std::log2(e1 / e2), expected, 0.15);
      if (theta == 0.5) {
        EXPECT_LT(e3, 1e-5);
      }
    }
  }
}

TEST(Theta, DroppedMassStopsAtImpact)
{
  ThreeDofParams p;
  p.mu = 0; // frictionless: the tangential motion decouples only through K
  Model model;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  ThetaIntegrator ti(PETSC_COMM_WORLD);
  ASSERT_EQ(ti.SetFromOptions(), 0);
  const double h = 1e-5;
  ASSERT_EQ(ti.SetUp(model, h), 0);
  Vec U, dU;
  ASSERT_EQ(VecDuplicate(model.F, &U), 0);
  ASSERT_EQ(VecDuplicate(model.F, &dU), 0);
  Eigen::Vector3d u0(0, 0, 1e-4), v0(0, 0, -1.0); // 0.1 mm above, falling at 1 m/s
  SetState(U, u0);
  SetState(dU, v0);
  Eigen::VectorXd r = Eigen::VectorXd::Zero(3);
  StepInfo        info;
  bool            touched = false;
  PetscInt        impact  = -1;
  for (PetscInt i = 0; i < 3000; ++i) {
    ASSERT_EQ(ti.Step(U, dU, r, &info), 0);
    ASSERT_TRUE(info.contact.converged);
    Eigen::VectorXd g, v;
    ASSERT_EQ(ti.Local(U, g), 0);
    ASSERT_EQ(ti.Local(dU, v), 0);
    if (!touched && r[kN] > 0) touched = true, impact = i;
    if (touched && i > impact) {
      // No bounce: the impact step ends on the surface (modified gap 0); from the next step on the
      // normal velocity is zero and the mass stays on the surface.
      EXPECT_NEAR(v[kN], 0.0, 1e-9) << "step " << i;
      EXPECT_NEAR(g[kN], 0.0, 1e-12) << "step " << i;
      EXPECT_GT(r[kN], 0.0) << "step " << i;
    }
  }
  EXPECT_TRUE(touched);
  EXPECT_NEAR(impact * h, 1e-4, 2 * h); // free fall of 0.1 mm at ~1 m/s
  VecDestroy(&U);
  VecDestroy(&dU);
}

namespace {

TransientResult RunTransient(const ThreeDofParams &p, PetscReal periods, PetscErrorCode *ierr = nullptr)
{
  Model model;
  PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, p, model));
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  StabilitySolver    stab(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  StabilityResult    sr;
  PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(model, eq));
  PetscCallAbort(PETSC_COMM_WORLD, stab.Solve(model, eq, sr));
  ThetaIntegrator   ti(PETSC_COMM_WORLD);
  TransientAnalysis ta(PETSC_COMM_WORLD);
  PetscCallAbort(PETSC_COMM_WORLD, ti.SetFromOptions());
  PetscCallAbort(PETSC_COMM_WORLD, ta.SetFromOptions());
  ta.periods    = periods;
  ta.keep_every = 5;
  TransientResult res;
  PetscCallAbort(PETSC_COMM_WORLD, PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  PetscErrorCode e = ta.Run(model, eq, sr, ti, res);
  PetscCallAbort(PETSC_COMM_WORLD, PetscPopErrorHandler());
  if (ierr) *ierr = e;
  else EXPECT_EQ(e, 0);
  return res;
}

} // namespace

TEST(Transient, Case1SeparationSlipLimitCycle)
{
  ThreeDofParams p; // V = 3
  TransientResult r = RunTransient(p, 100);
  PetscMPIInt     rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank) return; // the summary lives on rank 0
  EXPECT_GT(r.summary.frac_separated, 0.1);
  EXPECT_EQ(r.summary.frac_stuck, 0.0);
  EXPECT_NEAR(r.summary.period, 0.01082, 0.0003); // a nonlinear cycle near the linear period 0.010905
  EXPECT_LT(r.summary.energy_defect, 1e-8);
  EXPECT_EQ(r.summary.fp_capped, 0);
}

TEST(Transient, Case2StickSlipLimitCycle)
{
  ThreeDofParams p;
  p.V              = 0.75;
  TransientResult r = RunTransient(p, 100);
  PetscMPIInt     rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank) return;
  EXPECT_GT(r.summary.frac_stuck, 0.02);
  EXPECT_EQ(r.summary.frac_separated, 0.0);
  // In stick the slip velocity is zero (H = I: local = DOF velocities) and r_T is inside the disc.
  PetscInt stuck = 0;
  for (size_t k = 0; k < r.t.size(); ++k) {
    if (r.status[k] != kStick) continue;
    ++stuck;
    const double *v = &r.V[3 * k], *rr = &r.R[3 * k];
    EXPECT_NEAR(v[kT] - p.V, 0.0, 1e-9 * p.V) << "t = " << r.t[k];
    EXPECT_NEAR(v[kB], 0.0, 1e-9 * p.V) << "t = " << r.t[k];
    EXPECT_LT(std::hypot(rr[kT], rr[kB]), p.mu * rr[kN]);
  }
  EXPECT_GT(stuck, 100);
  EXPECT_LT(r.summary.energy_defect, 1e-8);
  EXPECT_EQ(r.summary.fp_capped, 0);
}

TEST(Transient, NoFrictionDecaysToEquilibrium)
{
  ThreeDofParams p;
  p.mu              = 0;
  PetscErrorCode  e = 0;
  // With mu = 0 every mode is stable: start from the lowest mode instead.
  TransientResult r = RunTransient(p, 60, &e);
  ASSERT_EQ(e, 0);
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank) return;
  const size_t n = r.t.size();
  double       first = 0, last = 0;
  for (size_t k = 0; k < n / 20; ++k)
    for (int j = 0; j < 3; ++j) first = std::max(first, std::abs(r.V[3 * k + j]));
  for (int j = 0; j < 3; ++j) last = std::max(last, std::abs(r.V[(n - 1) * 3 + j]));
  EXPECT_GT(first, 0.0);
  EXPECT_LT(last, 1e-3 * first); // every mode damped (sigma <= -10 1/s over 0.65 s)
  EXPECT_EQ(r.summary.frac_separated, 0.0);
}

// The energy bookkeeping of a run, recorded at every step, against sums written out here on the
// records alone with dense M, C, K, F and H: E = (V^T M V + U^T K U) / 2, and step by step
// W_damping += dq^T C dq / h, W_reactions += (H^T dq) . R, W_load += F . dq with dq = U_{k+1} - U_k;
// and every recorded status against LocalContactSolver::Status of the recorded reactions. Each
// bookkeeping path: the fixed-size dense one (3-DOF, one rank), the PETSc one with the dense
// run-time-sized step (-theta_fixed_size false) and with the sparse back end (on several ranks:
// the PETSc one throughout).
TEST(Transient, EnergyColumnsAndStatusesMatchDenseSumsOfTheRecords)
{
  for (PetscReal V : {3.0, 0.75})
    for (int path = 0; path < 3; ++path) {
      ThreeDofParams p;
      p.V = V;
      Model model;
      ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
      EquilibriumSolver  eqs(PETSC_COMM_WORLD);
      StabilitySolver    stab(PETSC_COMM_WORLD);
      SlidingEquilibrium eq;
      StabilityResult    sr;
      ASSERT_EQ(eqs.Solve(model, eq), 0);
      ASSERT_EQ(stab.Solve(model, eq, sr), 0);
      ThetaIntegrator   ti(PETSC_COMM_WORLD);
      TransientAnalysis ta(PETSC_COMM_WORLD);
      ASSERT_EQ(PetscOptionsSetValue(nullptr, "-ledger_fixed_size", "false"), 0);
      if (path == 1) {
        ASSERT_EQ(ti.SetOptionsPrefix("ledger_"), 0);
      }
      ASSERT_EQ(ti.SetFromOptions(), 0);
      ASSERT_EQ(PetscOptionsClearValue(nullptr, "-ledger_fixed_size"), 0);
      // Each path whatever the command line says (unit_tests_np2_sparse gives -theta_dense_max 0).
      ASSERT_EQ(ti.SetDenseMax(path == 2 ? 0 : 200), 0);
      ta.periods    = 25; // growth, then impacts, separation and (V = 0.75) stick
      ta.keep_every = 1;
      TransientResult r;
      ASSERT_EQ(ta.Run(model, eq, sr, ti, r), 0);
      EXPECT_EQ(ti.Dense(), path < 2);
      EXPECT_EQ(ti.FixedSizeKernel(), path == 0);
      const Eigen::MatrixXd M = test::ToDense(model.M), C = test::ToDense(model.C), K = test::ToDense(model.K);
      const Eigen::VectorXd F = test::ToDense(model.F);
      Eigen::MatrixXd       Ht(3, 3);
      for (int d = 0; d < 3; ++d) Ht.row(d) = test::DenseColumns(model.contacts, 3, d).col(0).transpose();
      PetscMPIInt rank;
      MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
      if (rank) continue; // the records live on rank 0
      const size_t n = r.t.size();
      ASSERT_EQ(n, (size_t)r.steps + 1);
      auto Uk = [&](size_t k) { return Eigen::Map<const Eigen::Vector3d>(&r.U[3 * k]); };
      auto Vk = [&](size_t k) { return Eigen::Map<const Eigen::Vector3d>(&r.V[3 * k]); };
      auto Rk = [&](size_t k) { return Eigen::Map<const Eigen::Vector3d>(&r.R[3 * k]); };
      double Wc = 0, WR = 0, WF = 0, Emax = 0, err[4] = {0, 0, 0, 0};
      int    seen[3] = {0, 0, 0};
      std::vector<int> st;
      for (size_t k = 0; k < n; ++k) {
        if (k > 0) {
          const Eigen::Vector3d dq = Uk(k) - Uk(k - 1);
          Wc += dq.dot(C * dq) / r.h;
          WR += (Ht * dq).dot(Rk(k));
          WF += F.dot(dq);
          ti.Contact().Status(Eigen::VectorXd(Rk(k)), st);
          ASSERT_EQ(r.status[k], st[0]) << "record " << k;
          seen[st[0]]++;
        }
        const double E = 0.5 * Vk(k).dot(M * Vk(k)) + 0.5 * Uk(k).dot(K * Uk(k));
        Emax           = std::max(Emax, std::abs(E));
        const double *e = &r.energy[4 * k], ref[4] = {E, Wc, WR, WF};
        for (int j = 0; j < 4; ++j) err[j] = std::max(err[j], std::abs(e[j] - ref[j]));
      }
      for (int j = 0; j < 4; ++j) EXPECT_LT(err[j], 1e-12 * Emax) << "V = " << V << ", path " << path << ", column " << j;
      EXPECT_GT(seen[kOpen] + seen[kSlip], 1000);
      if (V < 1) EXPECT_GT(seen[kStick], 100);
      else EXPECT_GT(seen[kOpen], 1000);
    }
}

// The dense step's kernel compiled for the 3-DOF sizes (with its inline Vec array access) against
// the run-time-sized kernel (-theta_fixed_size false) and the sparse back end (PETSc KSP, another
// code path): same states to round-off and the same fixed-point passes through impacts, stick,
// slip and separation, on both reference cases; and every step marks U and dU as changed
// (PETSc's cached norms are not reused).
TEST(Theta, FixedSizeKernelMatchesRunTimeSizesAndSparseBackEnd)
{
  for (PetscReal V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    Model model;
    ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
    EquilibriumSolver  eqs(PETSC_COMM_WORLD);
    SlidingEquilibrium eq;
    ASSERT_EQ(eqs.Solve(model, eq), 0);
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-gen_fixed_size", "false"), 0);
    // The fixed-size kernels start from the previous reactions and run plain passes; so do the
    // others here (-theta_contact_predict 0, -theta_fp_anderson 0), as the passes are compared.
    for (const char *o : {"-gen_contact_predict", "-theta_contact_predict", "-gen_fp_anderson", "-theta_fp_anderson"})
      ASSERT_EQ(PetscOptionsSetValue(nullptr, o, "0"), 0);
    test::Integration run[3]; // fixed sizes, run-time sizes, sparse back end
    const double h = 1e-5;
    for (int k = 0; k < 3; ++k) {
      if (k == 1) {
        ASSERT_EQ(run[k].ti.SetOptionsPrefix("gen_"), 0);
      }
      ASSERT_EQ(run[k].ti.SetFromOptions(), 0);
      ASSERT_EQ(run[k].ti.SetDenseMax(k == 2 ? 0 : 200), 0);
      ASSERT_EQ(run[k].ti.SetUp(model, h), 0);
      ASSERT_EQ(VecDuplicate(eq.U, &run[k].U), 0);
      ASSERT_EQ(VecCopy(eq.U, run[k].U), 0);
      ASSERT_EQ(VecDuplicate(eq.U, &run[k].dU), 0);
      // Case 1 far from the equilibrium (lift-off, impacts); case 2 starting at the belt's speed (stick).
      SetState(run[k].dU, V > 1 ? Eigen::Vector3d(0.4, -0.3, 0.25) : Eigen::Vector3d(V, 0, 0.02));
      // Filled entry by entry: GCC 12 with AVX flags the fixed-to-dynamic copy of a Vector3d
      // temporary as a 32-byte read of 24 bytes (-Warray-bounds) on a path Eigen never takes.
      run[k].r.resize(3);
      run[k].r << p.mu * eq.N[0], 0, eq.N[0];
    }
    ASSERT_TRUE(run[0].ti.FixedSizeKernel());
    ASSERT_FALSE(run[1].ti.FixedSizeKernel());
    ASSERT_FALSE(run[2].ti.Dense());
    ASSERT_EQ(PetscOptionsClearValue(nullptr, "-gen_fixed_size"), 0);
    for (const char *o : {"-gen_contact_predict", "-theta_contact_predict", "-gen_fp_anderson", "-theta_fp_anderson"})
      ASSERT_EQ(PetscOptionsClearValue(nullptr, o), 0);
    std::vector<int> status;
    int              seen[3] = {0, 0, 0};
    double           max_gen = 0, max_sparse = 0;
    for (PetscInt i = 0; i < 4000; ++i) {
      StepInfo  info[3];
      PetscReal norm, dnorm;
      ASSERT_EQ(VecNorm(run[0].U, NORM_2, &norm), 0); // cached by PETSc until the Vec's state changes
      ASSERT_EQ(VecNorm(run[0].dU, NORM_2, &dnorm), 0);
      for (int k = 0; k < 3; ++k) ASSERT_EQ(run[k].ti.Step(run[k].U, run[k].dU, run[k].r, &info[k]), 0);
      Eigen::VectorXd z[3];
      for (int k = 0; k < 3; ++k) {
        z[k].resize(6);
        z[k] << test::ToDense(run[k].U) / 1e-4, test::ToDense(run[k].dU); // displacements in 0.1 mm, velocities in m/s
      }
      ASSERT_EQ(VecNorm(run[0].U, NORM_2, &norm), 0);
      ASSERT_EQ(VecNorm(run[0].dU, NORM_2, &dnorm), 0);
      ASSERT_NEAR(norm, 1e-4 * z[0].head(3).norm(), 1e-14 * norm) << "stale norm of U after step " << i;
      ASSERT_NEAR(dnorm, z[0].tail(3).norm(), 1e-14 * dnorm) << "stale norm of dU after step " << i;
      ASSERT_EQ(info[0].contact.iterations, info[1].contact.iterations) << "step " << i;
      max_gen    = std::max(max_gen, (z[0] - z[1]).lpNorm<Eigen::Infinity>());
      max_sparse = std::max(max_sparse, (z[0] - z[2]).lpNorm<Eigen::Infinity>());
      run[0].ti.Contact().Status(run[0].r, status);
      ++seen[status[0]];
    }
    EXPECT_LT(max_gen, 1e-11) << "V = " << V;
    EXPECT_LT(max_sparse, 1e-9) << "V = " << V;
    EXPECT_GT(seen[V > 1 ? kOpen : kStick], 0) << "V = " << V;
    EXPECT_GT(seen[kSlip], 0) << "V = " << V;
    PetscPrintf(PETSC_COMM_WORLD, "V = %.2f: open / stick / slip steps %d / %d / %d, largest difference to run-time sizes %.2e, to the sparse back end %.2e\n",
                (double)V, seen[kOpen], seen[kStick], seen[kSlip], max_gen, max_sparse);
  }
}

// Issue 22 item 3: the 3-DOF fast path reads PETSc 3.18's private Vec layout; the public-API path
// (-theta_native_arrays 0, or a build with -DSQUEAL_PETSC_PRIVATE=OFF) must give the same steps to
// the bit, and both must leave PETSc's cached norms invalid after a step (the state increase).
TEST(Theta, NativeArraysAndPublicApiGiveTheSameSteps)
{
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (size > 1) GTEST_SKIP() << "the fast path is for one rank";
  Eigen::VectorXd out[2];
  for (int native = 0; native < 2; ++native) {
    ThreeDofParams p; // case 1: separation and slip
    Model          model;
    PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, p, model));
    PetscCallAbort(PETSC_COMM_WORLD, PetscOptionsSetValue(nullptr, "-theta_native_arrays", native ? "1" : "0"));
    ThetaIntegrator ti(PETSC_COMM_WORLD);
    PetscCallAbort(PETSC_COMM_WORLD, ti.SetFromOptions());
    PetscCallAbort(PETSC_COMM_WORLD, PetscOptionsClearValue(nullptr, "-theta_native_arrays"));
    PetscCallAbort(PETSC_COMM_WORLD, ti.SetUp(model, 0.0109 / 500));
    Vec U, dU;
    PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(model.F, &U));
    PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(model.F, &dU));
    Eigen::VectorXd u0(3), v0(3);
    u0 << 2e-3, -1e-3, -1e-4, v0 << 0.5, -0.2, 0.1;
    SetState(U, u0);
    SetState(dU, v0);
    Eigen::VectorXd r(3);
    r.setZero();
    StepInfo  info;
    PetscReal before, after;
    for (PetscInt i = 0; i < 2000; ++i) {
      PetscCallAbort(PETSC_COMM_WORLD, VecNorm(U, NORM_2, &before)); // cached by PETSc until U's state changes
      PetscCallAbort(PETSC_COMM_WORLD, ti.Step(U, dU, r, &info));
      PetscCallAbort(PETSC_COMM_WORLD, VecNorm(U, NORM_2, &after));
      ASSERT_DOUBLE_EQ(after, test::ToDense(U).norm()) << "stale cached norm at step " << i << " (native " << native << ")";
    }
    out[native].resize(6);
    out[native] << test::ToDense(U), test::ToDense(dU);
    EXPECT_GT(out[native].head(3).norm(), 0);
    PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&U));
    PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&dU));
  }
  for (int i = 0; i < 6; ++i) EXPECT_EQ(out[0][i], out[1][i]) << "component " << i;
}

TEST(Theta, SparseHTransposeGivesTheDenseStepsAndTangents)
{
  // H^T by its non-zeros (-theta_h_storage, auto above N = 64 at <= 10 % non-zeros) in (S5), the gaps,
  // the local velocities and the step tangent, against the dense H^T: a 24-cell chain (N = 72, a
  // contact on every cell, rotated frames, so 1 to 2 non-zeros in a row of 72), 3000 steps from
  // its equilibrium with a velocity pattern that opens and slides points, and at every 100th step a
  // tangent of one column and of a block of four. Equal to round-off (measured: bit for bit, as a
  // row's one or two products summed with exact zeros give the same sum).
  Model              model;
  SlidingEquilibrium eq;
  Eigen::VectorXd    v0;
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-hd_h_storage", "dense"), 0);
  test::Integration run[2]; // auto (sparse here), dense
  ASSERT_NO_FATAL_FAILURE(ChainRuns(model, eq, v0, run, {nullptr, "hd_"}));
  const PetscInt N = model.Size();
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-hd_h_storage"), 0);
  ASSERT_TRUE(run[0].ti.Dense() && run[1].ti.Dense());
  ASSERT_TRUE(run[0].ti.SparseHt());
  ASSERT_FALSE(run[1].ti.SparseHt());
  std::vector<int> status;
  int              seen[3] = {0, 0, 0};
  double           worst_state = 0, worst_tangent = 0;
  Eigen::VectorXd  vloc[2];
  for (PetscInt i = 0; i < 3000; ++i) {
    StepInfo info[2];
    for (int k = 0; k < 2; ++k) ASSERT_EQ(run[k].ti.Step(run[k].U, run[k].dU, run[k].r, &info[k]), 0);
    const Eigen::VectorXd u0 = test::ToDense(run[0].U), u1 = test::ToDense(run[1].U);
    const Eigen::VectorXd v0s = test::ToDense(run[0].dU), v1s = test::ToDense(run[1].dU);
    worst_state = std::max({worst_state, (u0 - u1).norm() / u1.norm(), (v0s - v1s).norm() / v1s.norm()});
    run[0].ti.Contact().Status(run[0].r, status);
    for (int s : status) ++seen[s];
    if (i % 100 != 99) continue;
    for (int k = 0; k < 2; ++k) ASSERT_EQ(run[k].ti.Local(run[k].dU, vloc[k]), 0);
    worst_state = std::max(worst_state, (vloc[0] - vloc[1]).norm() / vloc[1].norm());
    for (Eigen::Index cols : {1, 4}) {
      Eigen::MatrixXd dU[2], ddU[2];
      dU[0] = Eigen::MatrixXd::Random(N, cols), ddU[0] = Eigen::MatrixXd::Random(N, cols);
      dU[1] = dU[0], ddU[1] = ddU[0];
      // Both tangents along the dense run's step: the flows differ by round-off only.
      for (int k = 0; k < 2; ++k) ASSERT_EQ(run[k].ti.StepTangent(run[1].r, vloc[1], dU[k], ddU[k]), 0);
      worst_tangent = std::max({worst_tangent, (dU[0] - dU[1]).norm() / dU[1].norm(), (ddU[0] - ddU[1]).norm() / ddU[1].norm()});
    }
  }
  PetscPrintf(PETSC_COMM_WORLD, "open / stick / slip point-steps %d / %d / %d; sparse against dense H^T: states %.2e, tangents %.2e\n", seen[kOpen],
              seen[kStick], seen[kSlip], worst_state, worst_tangent);
  EXPECT_GT(seen[kOpen], 0);
  EXPECT_GT(seen[kSlip], 0);
  EXPECT_LT(worst_state, 1e-10);
  EXPECT_LT(worst_tangent, 1e-12);
}

class ModalStep : public ::testing::TestWithParam<bool> {};

TEST_P(ModalStep, GivesTheNodalStepsTangentsAndSources)
{
  // With GetParam(): a damping the modes do not diagonalise (C = diag(c_i), c_i varying), where the
  // modal step takes the dense G = A_m^-1 (theta_modal.cpp) instead of the diagonal P1, P2.
  const bool dense = GetParam();
  // The step in the modal coordinates of (K, M) (-theta_modal_step; the chain's C = c I is diagonal
  // there) against the nodal one: a 24-cell chain (N = 72, rotated frames), 3000 steps from its
  // equilibrium with a velocity pattern that opens and slides points, a jump of the state half-way
  // (the modal kernel must take q from the new U, not keep its own), the h-source of the period
  // tangent before any nodal matrix exists on the modal side, then nodal tangents (formed on
  // demand there) every 100th step. Equal to round-off.
  Model              model;
  SlidingEquilibrium eq;
  Eigen::VectorXd    v0;
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-ms_modal_step", "true"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-ns_modal_step", "false"), 0);
  test::Integration run[2]; // modal, nodal
  ASSERT_NO_FATAL_FAILURE(ChainRuns(model, eq, v0, run, {"ms_", "ns_"}, dense));
  const PetscInt N = model.Size();
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-ms_modal_step"), 0);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-ns_modal_step"), 0);
  ASSERT_TRUE(run[0].ti.ModalStep());
  ASSERT_FALSE(run[1].ti.ModalStep());
  ASSERT_EQ(run[0].ti.ModalDense(), dense);
  // The same Delassus matrix from (H^T Phi) diag(1/a) (H^T Phi)^T as from H^T A^-1 H.
  EXPECT_LT((run[0].ti.Delassus() - run[1].ti.Delassus()).norm(), 1e-13 * run[1].ti.Delassus().norm());
  std::vector<int> status;
  int              seen[3] = {0, 0, 0};
  double           worst_state = 0, worst_tangent = 0, worst_source = -1;
  Eigen::VectorXd  vloc[2], Ui[2], dUi[2];
  for (PetscInt i = 0; i < 3000; ++i) {
    if (i == 1500)
      for (int k = 0; k < 2; ++k) SetState(run[k].dU, 0.5 * v0); // both jump to the same new state
    StepInfo info[2];
    for (int k = 0; k < 2; ++k) {
      Ui[k] = test::ToDense(run[k].U), dUi[k] = test::ToDense(run[k].dU);
      ASSERT_EQ(run[k].ti.Step(run[k].U, run[k].dU, run[k].r, &info[k]), 0);
    }
    const Eigen::VectorXd u0 = test::ToDense(run[0].U), u1 = test::ToDense(run[1].U);
    const Eigen::VectorXd v0s = test::ToDense(run[0].dU), v1s = test::ToDense(run[1].dU);
    worst_state = std::max({worst_state, (u0 - u1).norm() / u1.norm(), (v0s - v1s).norm() / v1s.norm()});
    run[0].ti.Contact().Status(run[0].r, status);
    for (int s : status) ++seen[s];
    if (i == 40) {
      // dU^{i+1}/dh at the nodal run's step, by Phi diag(1/a) (Phi^T q + (H^T Phi)^T r) on the modal side.
      Eigen::VectorXd c[2];
      for (int k = 0; k < 2; ++k) ASSERT_EQ(run[k].ti.StepTangentSource(Ui[1], dUi[1], v1s, run[1].r, c[k]), 0);
      worst_source = (c[0] - c[1]).norm() / c[1].norm();
    }
    if (i % 100 != 99) continue;
    for (int k = 0; k < 2; ++k) ASSERT_EQ(run[k].ti.Local(run[k].dU, vloc[k]), 0);
    Eigen::MatrixXd dU[2], ddU[2];
    dU[0] = Eigen::MatrixXd::Random(N, 3), ddU[0] = Eigen::MatrixXd::Random(N, 3);
    dU[1] = dU[0], ddU[1] = ddU[0];
    for (int k = 0; k < 2; ++k) ASSERT_EQ(run[k].ti.StepTangent(run[1].r, vloc[1], dU[k], ddU[k]), 0);
    worst_tangent = std::max({worst_tangent, (dU[0] - dU[1]).norm() / dU[1].norm(), (ddU[0] - ddU[1]).norm() / ddU[1].norm()});
  }
  PetscPrintf(PETSC_COMM_WORLD, "open / stick / slip point-steps %d / %d / %d; modal against nodal step: states %.2e, h-source %.2e, tangents %.2e\n",
              seen[kOpen], seen[kStick], seen[kSlip], worst_state, worst_source, worst_tangent);
  EXPECT_GT(seen[kOpen], 0);
  EXPECT_GT(seen[kSlip], 0);
  EXPECT_LT(worst_state, 1e-10);
  EXPECT_GE(worst_source, 0);
  EXPECT_LT(worst_source, 1e-12);
  EXPECT_LT(worst_tangent, 1e-12);
  EXPECT_TRUE(run[0].ti.ModalStep()); // the nodal tangents did not switch the step
}

INSTANTIATE_TEST_SUITE_P(Theta, ModalStep, ::testing::Values(false, true), [](const auto &info) { return info.param ? "DenseG" : "DiagonalC"; });

TEST(Theta, StepTangentMatchesCentralDifferencesOfTheStepOnEveryStatus)
{
  // The exact step tangent (statuses held, the closed points' system in 3 n_stick + 2 n_slip
  // unknowns, planar, or 2 n_stick + n_slip, rectilinear) against central differences of the
  // nonlinear step itself, on a 24-cell chain whose points open, stick and slip (rotated frames,
  // a speed of their own each), for both friction laws: one random direction at every 40th of
  // 1200 steps where no point changes status within the differences.
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    ChainParams cp;
    cp.cells    = 24;
    cp.cell.V   = 0.75;
    cp.cell.law = law;
    Model model;
    ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, cp, model), 0);
    EquilibriumSolver  eqs(PETSC_COMM_WORLD);
    SlidingEquilibrium eq;
    ASSERT_EQ(eqs.Solve(model, eq), 0);
    // Twice the friction of the equilibrium: the points started at their surface's speed stick.
    model.contacts.SetFriction(2 * model.contacts.Mu(), model.contacts.V());
    const PetscInt N = model.Size(), nc = model.contacts.Size();
    test::Integration run;
    ASSERT_EQ(run.ti.SetFromOptions(), 0);
    ASSERT_EQ(run.ti.SetDenseMax(200), 0); // the dense back end also under -theta_dense_max 0
    ASSERT_EQ(run.ti.SetFixedPoint(1e-15, 100000), 0); // the differences' noise: tol / eps
    ASSERT_EQ(run.ti.SetUp(model, 2e-6), 0);
    ASSERT_TRUE(run.ti.Dense());
    Eigen::VectorXd v0(N);
    for (PetscInt i = 0; i < N; ++i) v0[i] = i % 3 == 2 ? 0.05 * std::sin(1.3 * (double)i) : 0.6 * std::sin(0.7 * (double)i + 0.3);
    for (PetscInt c = 0; c < nc; c += 2) // every other point starts at its surface's speed
      for (int a = 0; a < 3; ++a) v0[3 * c + a] = model.contacts.Speed(c) * model.contacts.points[(size_t)c].t[a];
    ASSERT_EQ(VecDuplicate(eq.U, &run.U), 0);
    ASSERT_EQ(VecCopy(eq.U, run.U), 0);
    ASSERT_EQ(VecDuplicate(eq.U, &run.dU), 0);
    SetState(run.dU, v0);
    run.r.setZero(3 * nc);
    for (PetscInt c = 0; c < nc; ++c) run.r[3 * c + kN] = eq.N[(size_t)c];
    Vec U, dU;
    ASSERT_EQ(VecDuplicate(eq.U, &U), 0);
    ASSERT_EQ(VecDuplicate(eq.U, &dU), 0);
    std::mt19937                     gen(7);
    std::normal_distribution<double> nd;
    std::vector<int>                 base, other;
    StepInfo                         info;
    int                              seen[3] = {0, 0, 0}, checked = 0;
    double                           worst   = 0;
    for (PetscInt i = 0; i < 1200; ++i) {
      if (i % 40 != 39 && i >= 4) {
        ASSERT_EQ(run.ti.Step(run.U, run.dU, run.r, &info), 0);
        continue;
      }
      const Eigen::VectorXd u = test::ToDense(run.U), v = test::ToDense(run.dU), r = run.r;
      ASSERT_EQ(run.ti.Step(run.U, run.dU, run.r, &info), 0);
      run.ti.Contact().Status(run.r, base);
      Eigen::VectorXd vloc;
      ASSERT_EQ(run.ti.Local(run.dU, vloc), 0);
      Eigen::VectorXd du(N), dv(N);
      // A closed point's reaction answers a displacement change over h^2 (the impact law): a
      // displacement direction of a velocity change's size over one step keeps both in the
      // statuses' reach.
      const double sv = v.norm() / std::sqrt((double)N);
      for (PetscInt j = 0; j < N; ++j) du[j] = 2e-6 * sv * nd(gen), dv[j] = sv * nd(gen);
      Eigen::MatrixXd tU = du, tdU = dv;
      ASSERT_EQ(run.ti.StepTangent(run.r, vloc, tU, tdU), 0);
      const double    eps = 1e-7;
      Eigen::VectorXd z[2];
      bool            same = true;
      for (int s = 0; s < 2; ++s) {
        const double    e  = s == 0 ? eps : -eps;
        Eigen::VectorXd rr = r;
        SetState(U, u + e * du);
        SetState(dU, v + e * dv);
        ASSERT_EQ(run.ti.Step(U, dU, rr, &info), 0);
        run.ti.Contact().Status(rr, other);
        same = same && other == base;
        z[s].resize(2 * N);
        z[s] << test::ToDense(U), test::ToDense(dU);
      }
      if (!same) continue;
      Eigen::VectorXd t(2 * N);
      t << tU.col(0), tdU.col(0);
      const Eigen::VectorXd fd = (z[0] - z[1]) / (2 * eps);
      worst = std::max(worst, (t - fd).norm() / fd.norm());
      for (int st : base) ++seen[st];
      ++checked;
    }
    PetscPrintf(PETSC_COMM_WORLD, "%s: %d steps, open / stick / slip point-steps %d / %d / %d; tangent against central differences %.2e\n",
                law == FrictionLaw::Planar ? "planar" : "rectilinear", checked, seen[kOpen], seen[kStick], seen[kSlip], worst);
    EXPECT_GE(checked, 20);
    EXPECT_GT(seen[kOpen], 0);
    EXPECT_GT(seen[kStick], 0);
    EXPECT_GT(seen[kSlip], 0);
    EXPECT_LT(worst, 1e-6);
    VecDestroy(&U), VecDestroy(&dU);
  }
}

// The sliding linearisation's monodromy (integration/monodromy.h) by binary powering through BLAS
// against the step tangent multiplied in one step at a time (Eigen): the 24-cell chain (2N = 144),
// 1, 6 and 200 steps (the last two start the powering with a copy of a power, not a product).
TEST(Theta, LinearMonodromyIsTheStepTangentToTheStepsPower)
{
  Model              model;
  SlidingEquilibrium eq;
  Eigen::VectorXd    v0;
  test::Integration  run[2];
  ASSERT_NO_FATAL_FAILURE(ChainRuns(model, eq, v0, run, {nullptr, nullptr}));
  const Eigen::Index N = model.Size(), n2 = 2 * N;
  const Eigen::VectorXd r0 = run[0].r; // the equilibrium's reactions: every point closed and sliding
  Eigen::MatrixXd dU = Eigen::MatrixXd::Zero(N, n2), ddU = Eigen::MatrixXd::Zero(N, n2);
  dU.leftCols(N).setIdentity();
  ddU.rightCols(N).setIdentity();
  ASSERT_EQ(run[0].ti.StepTangent(r0, Eigen::VectorXd::Zero(r0.size()), dU, ddU), 0);
  Eigen::MatrixXd S(n2, n2);
  S << dU, ddU;
  for (PetscInt steps : {1, 6, 200}) {
    Eigen::MatrixXd ref = Eigen::MatrixXd::Identity(n2, n2), P;
    for (PetscInt i = 0; i < steps; ++i) ref = S * ref;
    ASSERT_EQ(LinearMonodromy(run[0].ti, r0, steps, P), 0);
    ASSERT_EQ(P.rows(), n2);
    EXPECT_LT((P - ref).norm(), 1e-12 * ref.norm()) << steps << " steps";
    // The products shared by the ranks of the model's communicator (each forms a block of columns;
    // the dense back end holds the whole model on every rank): the same power on every rank.
    Eigen::MatrixXd Ps;
    ASSERT_EQ(LinearMonodromy(run[0].ti, r0, steps, Ps, model.comm()), 0);
    EXPECT_LT((Ps - ref).norm(), 1e-12 * ref.norm()) << steps << " steps, split";
    // Polled for signals (shooting's linear preconditioner): the same products, in column slices.
    Eigen::MatrixXd Pp;
    ASSERT_EQ(LinearMonodromy(run[0].ti, r0, steps, Pp, model.comm(), "the test's monodromy"), 0);
    EXPECT_LT((Pp - ref).norm(), 1e-12 * ref.norm()) << steps << " steps, polled";
    // In single precision (-shoot_linear_pc_single), split and polled as shooting runs it: float's
    // rounding, about 1e-7 a product, grown by the powering's 9 products (200 steps), not more.
    Eigen::MatrixXd Pf;
    ASSERT_EQ(LinearMonodromy(run[0].ti, r0, steps, Pf, model.comm(), "the test's monodromy", true), 0);
    const double ef = (Pf - ref).norm() / ref.norm();
    EXPECT_LT(ef, 1e-5) << steps << " steps, single";
    EXPECT_GT((Pf - Pp).norm(), 0.0) << steps << " steps: not the single-precision products";
  }
}
