// The synthetic multi-contact chain: several points with their own sliding directions and
// speeds, H not the identity. Checked against dense references that share no code with the
// library's reduction (bordered QZ of (4.4)), and through the stability map.
#include "dense.h"
#include "squeal/app/pipeline.h"
#include "squeal/model/builders.h"
#include "squeal/stability/stability.h"
#include "squeal/stability/sweep.h"

#include <gtest/gtest.h>

#include <algorithm>

using namespace squeal;

namespace {

void ExpectInReference(const StabilityResult &res, const std::vector<std::complex<double>> &ref, double rtol)
{
  ASSERT_FALSE(res.modes.empty());
  for (const Mode &m : res.modes) {
    const std::complex<double> l(m.sigma, m.omega);
    double                     best = 1e300;
    for (auto r : ref) best = std::min(best, std::abs(l - r));
    EXPECT_LE(best, rtol * std::abs(l)) << "eigenvalue " << l << " not in the dense reference";
  }
}

} // namespace

TEST(Chain, EquilibriumAndEigenvaluesMatchDenseReference)
{
  ChainParams p;
  p.cells = 5;
  Model model;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, p, model), 0);
  ASSERT_EQ(model.contacts.Size(), 5);
  EquilibriumSolver eqs(PETSC_COMM_WORLD);
  StabilitySolver   stab(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  StabilityResult    res;
  ASSERT_EQ(eqs.Solve(model, eq), 0);
  ASSERT_EQ(stab.Solve(model, eq, res), 0);
  EXPECT_TRUE(eq.released.empty());

  const Eigen::MatrixXd M = test::ToDense(model.M), C = test::ToDense(model.C), K = test::ToDense(model.K);
  const Eigen::VectorXd U = test::ToDense(eq.U), F = test::ToDense(model.F);
  const PetscInt        N = model.Size();
  const Eigen::MatrixXd Hn = test::DenseColumns(model.contacts, N, kN), Ht = test::DenseColumns(model.contacts, N, kT);
  Eigen::VectorXd       Nv(model.contacts.Size());
  for (PetscInt c = 0; c < model.contacts.Size(); ++c) Nv(c) = eq.N[c];
  // (3.1): K U = F + (H_n + mu H_t) N and H_n^T U = 0.
  EXPECT_LT((K * U - F - (Hn + p.cell.mu * Ht) * Nv).norm(), 1e-9 * F.norm());
  EXPECT_LT((Hn.transpose() * U).norm(), 1e-14);
  for (PetscInt c = 0; c < model.contacts.Size(); ++c) EXPECT_GT(eq.N[c], 0);

  ExpectInReference(res, test::BorderedReference(M, C, K, model.contacts, eq.N), 1e-8);
  EXPECT_FALSE(res.unstable.empty());
}

TEST(Chain, LiftedPointIsReleasedAndReported)
{
  ChainParams p;
  p.cells = 4;
  Model model;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, p, model), 0);
  // Pull the first cell away from the surface instead of pressing it on.
  PetscInt rstart, rend;
  ASSERT_EQ(VecGetOwnershipRange(model.F, &rstart, &rend), 0);
  if (2 >= rstart && 2 < rend) {
    ASSERT_EQ(VecSetValue(model.F, 2, +400.0, INSERT_VALUES), 0);
  }
  ASSERT_EQ(VecAssemblyBegin(model.F), 0);
  ASSERT_EQ(VecAssemblyEnd(model.F), 0);

  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  StabilitySolver    stab(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  StabilityResult    res;
  ASSERT_EQ(eqs.Solve(model, eq), 0);
  ASSERT_EQ(eq.released, std::vector<PetscInt>{0});
  EXPECT_GT(eq.gap[0], 0);
  EXPECT_EQ(eq.N[0], 0);
  for (PetscInt c : eq.active) EXPECT_GT(eq.N[c], 0);
  ASSERT_EQ(stab.Solve(model, eq, res), 0);

  // Reference with the released point removed from the contact set.
  ContactSet closed = model.contacts;
  closed.points.erase(closed.points.begin());
  std::vector<double> Nc(eq.N.begin() + 1, eq.N.end());
  ExpectInReference(res,
                    test::BorderedReference(test::ToDense(model.M), test::ToDense(model.C), test::ToDense(model.K), closed, Nc),
                    1e-8);
}

// The guard's eigenvalues (SolveUpTo) by LAPACK on the whole reduced problem: every one of the
// 2 n_r in the bordered QZ reference (which shares no code with the reduction), and the same set
// as the eigensolver's route (-stab_guard_dense_max 0) when that one is grown to all of them.
TEST(Chain, GuardsDenseEigenvaluesAreTheReferencesAndTheEigensolvers)
{
  ChainParams p;
  p.cells = 5;
  Model model;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, p, model), 0);
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  ASSERT_EQ(eqs.Solve(model, eq), 0);
  ASSERT_TRUE(eq.released.empty());
  const PetscReal everything = 1e9; // Hz, above the whole spectrum
  StabilityResult dense, pep;
  {
    StabilitySolver stab(PETSC_COMM_WORLD);
    ASSERT_EQ(stab.SolveUpTo(model, eq, everything, dense), 0);
  }
  {
    struct Option { // cleared also when an assertion returns early
      Option() { PetscOptionsSetValue(nullptr, "-stab_guard_dense_max", "0"); }
      ~Option() { PetscOptionsClearValue(nullptr, "-stab_guard_dense_max"); }
    } zero;
    StabilitySolver stab(PETSC_COMM_WORLD);
    ASSERT_EQ(stab.SolveUpTo(model, eq, everything, pep), 0);
  }
  // The routes taken: LAPACK's eigenvalues carry no backward error, the eigensolver's do.
  for (const Mode &m : dense.modes) ASSERT_EQ(m.error, 0.0);
  EXPECT_TRUE(std::any_of(pep.modes.begin(), pep.modes.end(), [](const Mode &m) { return m.error > 0; }));

  const PetscInt n_r = model.Size() - model.contacts.Size(); // one pivot per closed point
  EXPECT_TRUE(dense.all_eigenvalues);
  EXPECT_EQ(dense.n_r, n_r);
  EXPECT_TRUE(pep.all_eigenvalues);
  ExpectInReference(dense, test::BorderedReference(test::ToDense(model.M), test::ToDense(model.C), test::ToDense(model.K), model.contacts, eq.N),
                    1e-8); // the reference's own accuracy on this chain (as Chain.EquilibriumAndEigenvaluesMatchDenseReference)
  // Complex pairs once, real eigenvalues each: 2 n_r in all.
  PetscInt count = 0;
  for (const Mode &m : dense.modes) count += m.Oscillatory() ? 2 : 1;
  EXPECT_EQ(count, 2 * n_r);
  ASSERT_EQ(dense.modes.size(), pep.modes.size());
  for (size_t i = 0; i < dense.modes.size(); ++i) {
    const std::complex<double> a(dense.modes[i].sigma, dense.modes[i].omega), b(pep.modes[i].sigma, pep.modes[i].omega);
    EXPECT_LE(std::abs(a - b), 1e-8 * std::abs(b)) << "mode " << i;
  }
  ASSERT_FALSE(dense.unstable.empty());
  EXPECT_EQ(dense.unstable, pep.unstable);
}

TEST(Sweep, CriticalMuOfReferenceCases)
{
  struct Case {
    const char *friction;
    double      V, mu_c;
  } cases[] = {{"planar", 3.0, 0.143068}, {"planar", 0.75, 0.146899}, {"rectilinear", 3.0, 0.141601}};
  for (const Case &c : cases) {
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-contact_friction", c.friction), 0);
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-contact_v", std::to_string(c.V).c_str()), 0);
    Pipeline pl(PETSC_COMM_WORLD); // the program's route: the points' models from the options
    ASSERT_EQ(pl.BuildModel(), 0);
    ASSERT_EQ(pl.SetFromOptions(), 0);
    SweepResult r;
    ASSERT_EQ(pl.Sweep(r), 0);
    ASSERT_EQ(r.critical_mu.size(), 1u);
    // docs/method.md §8 gives mu_c to 6 digits (bisection to 1e-8).
    EXPECT_NEAR(r.critical_mu[0], c.mu_c, 1e-6) << c.friction << " V = " << c.V;
    EXPECT_GT(r.coalescence_frequency[0], 85.0);
    EXPECT_LT(r.coalescence_frequency[0], 95.0);
    // Below mu_c stable, above unstable, on the grid itself.
    for (size_t i = 0; i < r.mu.size(); ++i) {
      if (r.mu[i] < c.mu_c - 1e-3) {
        EXPECT_LT(r.MaxSigma(0, i), 0) << "mu = " << r.mu[i];
      } else if (r.mu[i] > c.mu_c + 1e-3) {
        EXPECT_GT(r.MaxSigma(0, i), 0) << "mu = " << r.mu[i];
      }
    }
  }
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-contact_friction"), 0);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-contact_v"), 0);
}

TEST(Sweep, UndampedPlanarCriticalMuIsKtbOverKnb)
{
  // c = 0: mu_c = K_tb / K_nb (docs/method.md §4.5), independent of V.
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-model_c", "0"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-sweep_v_n", "2"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-sweep_v_min", "0.75"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-sweep_v_max", "3"), 0);
  Pipeline pl(PETSC_COMM_WORLD); // the program's route: the points' models from the options
  ASSERT_EQ(pl.BuildModel(), 0);
  ASSERT_EQ(pl.SetFromOptions(), 0);
  SweepResult r;
  ASSERT_EQ(pl.Sweep(r), 0);
  ThreeDofParams p;
  PetscReal      Kx[3][3], K[3][3];
  ThreeDofStiffness(p, Kx, K);
  ASSERT_EQ(r.critical_mu.size(), 2u);
  for (double mc : r.critical_mu) EXPECT_NEAR(mc, K[0][1] / K[2][1], 1e-6);
  for (const char *o : {"-model_c", "-sweep_v_n", "-sweep_v_min", "-sweep_v_max"}) ASSERT_EQ(PetscOptionsClearValue(nullptr, o), 0);
}

// The positive definiteness of M is checked by the LDL^T pivots; a lumped (diagonal) mass is
// definite by its positive diagonal, and the LDL^T was not free: MUMPS's PORD ordering of the
// edgeless graph took 61 s of a 30000-cell chain's set-up, during which no signal was seen.
TEST(Chain, LumpedMassIsCheckedByItsDiagonal)
{
  // The diagonal path of Model::Validate: a positive lumped mass accepted, the same mass scaled by
  // -1 refused by name. (Its cost on 30000 cells, 68 s -> 1.2 s, is a measurement for
  // docs/records.md, not a timed test.)
  ChainParams p;
  p.cells = 2000;
  Model model;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, p, model), 0); // validates M, K, C and the contacts
  ASSERT_EQ(MatScale(model.M, -1.0), 0);
  ASSERT_EQ(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr), 0);
  const PetscErrorCode ierr = model.Validate();
  ASSERT_EQ(PetscPopErrorHandler(), 0);
  EXPECT_NE(ierr, 0);
}
