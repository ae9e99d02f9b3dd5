// Many contacts on the sparse back end (issue 10): the sparse Delassus matrix with (S8) by one more
// solve must give the same discrete step as the dense W with the stored Y = A^-1 H, and as the
// dense back end (Eigen, replicated), on a chain whose points open, close, stick and slip.
#include "dense.h"
#include "squeal/integration/theta.h"
#include "squeal/model/builders.h"
#include "squeal/stability/stability.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

using namespace squeal;

namespace {

struct Stepper {
  ThetaIntegrator ti{PETSC_COMM_WORLD};
  Vec             U = nullptr, dU = nullptr;
  Eigen::VectorXd r;
  ~Stepper()
  {
    VecDestroy(&U);
    VecDestroy(&dU);
  }
};

// dense_max, delassus_max, drop: which path; all start from the equilibrium with the same
// velocity pattern, large enough to lift points off.
void Start(Stepper &s, const Model &model, const SlidingEquilibrium &eq, PetscInt dense_max, PetscInt delassus_max, PetscReal drop,
           PetscReal h, const char *parallel_solver = "auto")
{
  PetscCallAbort(PETSC_COMM_WORLD, s.ti.SetFromOptions());
  PetscCallAbort(PETSC_COMM_WORLD, s.ti.SetParallelSolver(parallel_solver, 1e-13));
  PetscCallAbort(PETSC_COMM_WORLD, s.ti.SetDenseMax(dense_max));
  PetscCallAbort(PETSC_COMM_WORLD, s.ti.SetDelassusMax(delassus_max, drop));
  PetscCallAbort(PETSC_COMM_WORLD, s.ti.SetUp(model, h));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(eq.U, &s.U));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(eq.U, &s.dU));
  PetscCallAbort(PETSC_COMM_WORLD, VecCopy(eq.U, s.U));
  PetscInt     lo, hi;
  PetscScalar *du;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetOwnershipRange(s.dU, &lo, &hi));
  PetscCallAbort(PETSC_COMM_WORLD, VecGetArray(s.dU, &du));
  for (PetscInt i = lo; i < hi; ++i) du[i - lo] = 0.5 * std::sin(0.7 * i);
  // Every third point starts carried along by the surface, 0.3 mm behind its sliding equilibrium
  // (the springs pull less than mu N): these stick first.
  PetscScalar *u;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetArray(s.U, &u));
  for (PetscInt c = 0; c < model.contacts.Size(); c += 3)
    for (int k = 0; k < 3; ++k) {
      const PetscInt d = model.contacts.points[c].nodes[0].dofs[k];
      if (d < lo || d >= hi) continue;
      du[d - lo] = model.contacts.Speed(c) * model.contacts.points[c].t[k];
      u[d - lo] -= 3e-4 * model.contacts.points[c].t[k];
    }
  PetscCallAbort(PETSC_COMM_WORLD, VecRestoreArray(s.U, &u));
  PetscCallAbort(PETSC_COMM_WORLD, VecRestoreArray(s.dU, &du));
  const PetscInt nc = model.contacts.Size();
  s.r.setZero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) s.r[3 * c + kT] = model.contacts.Mu() * eq.N[c], s.r[3 * c + kN] = eq.N[c];
}

} // namespace

TEST(ContactsAtScale, SparseDelassusStepMatchesDenseWAndDenseBackEnd)
{
  ChainParams p;
  p.cells         = 200; // N = 600
  p.contact_every = 2;   // 100 points, 3 n_c = 300
  p.gamma_step    = 360.0 / p.cells;
  p.speed_step    = 1.0 / p.cells;
  p.cell.V        = 0.75; // the stick-slip case's speed: points stick as well as lift off
  Model model;
  ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, p, model), 0);
  const PetscInt nc = model.contacts.Size();
  ASSERT_EQ(nc, 100);
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  SlidingEquilibrium eq;
  ASSERT_EQ(eqs.Solve(model, eq), 0);

  const PetscReal h = 5e-5; // 160 steps: 8 ms, about one period of a cell
  // Reference: dense back end (Eigen LLT, dense W); then the sparse back end with the dense W and
  // Y, and with the sparse W (default drop tolerance, and exact non-zeros only).
  // On several ranks the sparse back end solves redundantly by default (auto: every rank's own
  // Cholesky of the whole A); the exact-non-zero stepper uses CG + block Jacobi (cg) and the last
  // one MUMPS's distributed LU (direct), so that all three parallel solvers are checked.
  Stepper ref, ysp, wsp, wex, wdir;
  Start(ref, model, eq, 100000, 100000, 1e-15, h);
  Start(ysp, model, eq, 0, 100000, 1e-15, h);
  Start(wsp, model, eq, 0, 0, 1e-15, h);
  Start(wex, model, eq, 0, 0, 0.0, h, "cg");
  Start(wdir, model, eq, 0, 0, 1e-15, h, "direct");
  ASSERT_TRUE(ref.ti.Dense());
  ASSERT_FALSE(ysp.ti.Dense());
  ASSERT_FALSE(ysp.ti.SparseDelassus());
  ASSERT_TRUE(wsp.ti.SparseDelassus());
  ASSERT_TRUE(wex.ti.SparseDelassus());
  // The chain's W is numerically banded: far fewer entries than the dense 300 x 300.
  EXPECT_LT(wsp.ti.DelassusSparse().nonZeros(), 9 * 3 * nc * 3);
  // Same matrix as the dense back end's W where kept (the reference shares no code with the solves).
  const Eigen::MatrixXd Wd = Eigen::MatrixXd(wex.ti.DelassusSparse());
  EXPECT_LT((Wd - ref.ti.Delassus()).cwiseAbs().maxCoeff(), 1e-12 * ref.ti.Delassus().cwiseAbs().maxCoeff());

  std::vector<int> st_prev, st;
  ref.ti.Contact().Status(ref.r, st_prev);
  PetscInt opened = 0, closed = 0, slips = 0, sticks = 0;
  double   worst[4] = {0, 0, 0, 0};
  StepInfo info;
  for (int i = 0; i < 160; ++i) {
    for (Stepper *s : {&ref, &ysp, &wsp, &wex, &wdir}) {
      ASSERT_EQ(s->ti.Step(s->U, s->dU, s->r, &info), 0);
      ASSERT_TRUE(info.contact.converged) << "step " << i;
    }
    ref.ti.Contact().Status(ref.r, st);
    for (PetscInt c = 0; c < nc; ++c) {
      opened += st_prev[c] != kOpen && st[c] == kOpen;
      closed += st_prev[c] == kOpen && st[c] != kOpen;
      slips += st[c] == kSlip;
      sticks += st[c] == kStick;
    }
    st_prev = st;
    if (i % 20 != 19) continue;
    const Eigen::VectorXd U0 = test::ToDense(ref.U), dU0 = test::ToDense(ref.dU);
    const double          rs = ref.r.cwiseAbs().maxCoeff();
    int                   k  = 0;
    for (Stepper *s : {&ysp, &wsp, &wex, &wdir}) {
      const double eu = (test::ToDense(s->U) - U0).cwiseAbs().maxCoeff() / U0.cwiseAbs().maxCoeff();
      const double ev = (test::ToDense(s->dU) - dU0).cwiseAbs().maxCoeff() / dU0.cwiseAbs().maxCoeff();
      const double er = (s->r - ref.r).cwiseAbs().maxCoeff() / rs;
      worst[k] = std::max({worst[k], eu, ev, er});
      ++k;
    }
  }
  // Points lift off and land again, stick and slip: every branch of the local solve is exercised.
  EXPECT_GT(opened, 10);
  EXPECT_GT(closed, 10);
  EXPECT_GT(slips, 0);
  EXPECT_GT(sticks, 0);
  EXPECT_LT(worst[0], 1e-10) << "sparse back end, dense W and Y against the dense back end";
  EXPECT_LT(worst[1], 1e-10) << "sparse W (drop 1e-15), (S8) by a solve, against the dense back end";
  EXPECT_LT(worst[2], 1e-10) << "sparse W (exact non-zeros), (S8) by a solve, -theta_parallel_solver cg, against the dense back end";
  EXPECT_LT(worst[3], 1e-10) << "sparse W, -theta_parallel_solver direct (MUMPS on several ranks), against the dense back end";
  PetscCallAbort(PETSC_COMM_WORLD, PetscPrintf(PETSC_COMM_WORLD,
                                               "ContactsAtScale: %d openings, %d closings, %d stick and %d slip point-steps; "
                                               "max relative differences %.2e %.2e %.2e %.2e\n",
                                               (int)opened, (int)closed, (int)sticks, (int)slips, worst[0], worst[1], worst[2],
                                               worst[3]));
}
