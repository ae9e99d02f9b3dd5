// The one-step local contact problem (docs/method.md §2, §5 (S6)-(S7)): the semi-smooth Newton of
// LocalContactSolver against problems built from a known solution (every state of a point: open,
// stick, slip, planar and rectilinear; several points coupled through a random SPD W, dense and
// sparse), against the fixed point along a sequence of problems whose statuses change, the fallback
// to the fixed point, and whole transients with -theta_contact_solver ssn against fp.
#include "dense.h"
#include "squeal/contact/local_solver.h"
#include "squeal/core/hypot.h"
#include "squeal/integration/theta.h"
#include "squeal/model/builders.h"
#include "squeal/integration/transient.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

using namespace squeal;

namespace {

ContactSet MakeSet(PetscInt nc, PetscReal mu, FrictionLaw law, std::mt19937 &gen)
{
  ContactSet                             cs;
  std::uniform_real_distribution<double> u(0.5, 1.5);
  cs.SetFriction(mu, 2.0);
  cs.law = law;
  cs.points.resize(nc);
  for (auto &p : cs.points) p.speed_factor = u(gen);
  return cs;
}

// Random SPD W with a dominant diagonal (unique solution for moderate mu), optionally block banded
// (points more than `band` apart uncoupled) for the sparse overload.
Eigen::MatrixXd RandomW(PetscInt nc, std::mt19937 &gen, PetscInt band = -1)
{
  std::normal_distribution<double> n(0, 1);
  const Eigen::Index               m = 3 * nc;
  Eigen::MatrixXd                  B(m, m);
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < m; ++j) B(i, j) = (band < 0 || std::abs(i / 3 - j / 3) <= band) ? n(gen) : 0.0;
  Eigen::MatrixXd W = 0.3 * B * B.transpose() / m;
  if (band >= 0) // B B^T widens the band: cut back to it (the diagonal shift keeps it SPD)
    for (Eigen::Index i = 0; i < m; ++i)
      for (Eigen::Index j = 0; j < m; ++j)
        if (std::abs(i / 3 - j / 3) > band) W(i, j) = 0;
  W += Eigen::MatrixXd::Identity(m, m) * (1.0 + W.cwiseAbs().rowwise().sum().maxCoeff());
  return W; // 1/kg: a few kg per point
}

enum State { kOpenS, kStickS, kSlipS };

// A problem whose solution is r*: each point given a state, r* and the end velocity v* chosen to
// satisfy that state's law exactly, then w_f = v* - h W r* and gap0 = -h v*_n for closed points.
struct Problem {
  Eigen::VectorXd w_f, gap0, r;
};

Problem Construct(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, const std::vector<State> &states, std::mt19937 &gen)
{
  std::uniform_real_distribution<double> u(0.2, 1.0), s(-1, 1);
  const PetscInt                         nc = cs.Size();
  const bool                             rect = cs.law == FrictionLaw::Rectilinear;
  Eigen::VectorXd                        r = Eigen::VectorXd::Zero(3 * nc), v(3 * nc), gap0(nc);
  for (PetscInt c = 0; c < nc; ++c) {
    const Eigen::Index o = 3 * c;
    const double       V = cs.Speed(c);
    v[o + kN]            = s(gen);
    if (states[c] == kOpenS) { // r = 0, end gap g = gap0 + h v_n > 0
      v[o + kT]  = V + s(gen);
      v[o + kB]  = s(gen);
      gap0[c]    = -h * v[o + kN] + 1e-4 * u(gen);
      continue;
    }
    gap0[c]   = -h * v[o + kN]; // closed: end gap 0
    r[o + kN] = 1000 * u(gen);
    const double a = cs.Mu() * r[o + kN];
    if (states[c] == kStickS) { // zero slip, |r_T| < mu r_n
      v[o + kT] = V;
      v[o + kB] = rect ? s(gen) : 0.0; // rectilinear: b is frictionless, its velocity free
      const double ang = M_PI * s(gen), f = 0.8 * u(gen);
      r[o + kT] = a * f * std::cos(ang);
      r[o + kB] = rect ? 0.0 : a * f * std::sin(ang);
      if (rect) r[o + kT] = a * 0.9 * s(gen);
    } else { // slip s != 0, r_T = -mu r_n s / |s| (rectilinear: -mu r_n sign(s_t), r_b = 0)
      const double st = s(gen) + (s(gen) > 0 ? 0.3 : -0.3), sb = s(gen);
      v[o + kT] = V + st;
      v[o + kB] = sb;
      if (rect) r[o + kT] = -a * (st > 0 ? 1 : -1);
      else {
        const double m = std::hypot(st, sb);
        r[o + kT]      = -a * st / m;
        r[o + kB]      = -a * sb / m;
      }
    }
  }
  return {v - h * W * r, gap0, r};
}

// W = B B^T / m plus 2 % of its mean diagonal, B m x m standard normal: every point coupled to every
// other nearly as strongly as to itself, where Gauss-Seidel is slow.
Eigen::MatrixXd CoupledW(PetscInt m, std::mt19937 &gen)
{
  std::normal_distribution<double> n(0, 1);
  Eigen::MatrixXd                  B(m, m);
  for (auto &x : B.reshaped()) x = n(gen);
  Eigen::MatrixXd W = B * B.transpose() / m;
  W += 0.02 * W.diagonal().mean() * Eigen::MatrixXd::Identity(m, m);
  return W;
}

double RelErr(const Eigen::VectorXd &a, const Eigen::VectorXd &b) { return (a - b).lpNorm<Eigen::Infinity>() / (1 + b.lpNorm<Eigen::Infinity>()); }

struct Solved {
  Eigen::VectorXd r;
  LocalSolveInfo  info;
};

Solved SolveOne(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, const Problem &pb, const Eigen::VectorXd &r0, bool newton,
           bool sparse = false, PetscInt newton_max_it = 30)
{
  LocalContactSolver ls;
  if (sparse) ls.Setup(cs, Eigen::SparseMatrix<PetscReal>(W.sparseView()), h, 1.0);
  else ls.Setup(cs, W, h, 1.0);
  ls.SetTolerances(1e-14, 100000, 1.0);
  if (newton) ls.SetSolver(ContactSolver::kNewton, newton_max_it);
  Solved s{r0, {}};
  s.info = ls.Solve(pb.w_f, pb.gap0, s.r);
  EXPECT_EQ(ls.Fallbacks(), s.info.fallback ? 1 : 0);
  return s;
}

void ExpectStates(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, const Eigen::VectorXd &r, const std::vector<State> &states)
{
  LocalContactSolver ls;
  ls.Setup(cs, W, h, 1.0);
  std::vector<int> st;
  ls.Status(r, st);
  for (size_t c = 0; c < states.size(); ++c)
    EXPECT_EQ(st[c], states[c] == kOpenS ? kOpen : states[c] == kStickS ? kStick : kSlip) << "point " << c;
}

} // namespace

// One point in each state and law, from a cold (zero) and a far start: Newton, the fixed point and
// the constructed solution agree to 1e-12.
TEST(LocalSolver, NewtonMatchesConstructedSolutionOnePoint)
{
  std::mt19937 gen(1);
  const double h = 1e-4;
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear})
    for (State st : {kOpenS, kStickS, kSlipS})
      for (int start = 0; start < 2; ++start) {
        const ContactSet      cs = MakeSet(1, 0.3, law, gen);
        const Eigen::MatrixXd W  = RandomW(1, gen);
        const Problem         pb = Construct(cs, W, h, {st}, gen);
        const Eigen::VectorXd r0 = start ? Eigen::VectorXd(Eigen::Vector3d(-500, 800, 3000)) : Eigen::VectorXd::Zero(3);
        const Solved          n = SolveOne(cs, W, h, pb, r0, true), f = SolveOne(cs, W, h, pb, r0, false);
        SCOPED_TRACE(::testing::Message() << FrictionLawName(law) << " state " << st << " start " << start);
        EXPECT_TRUE(n.info.converged);
        EXPECT_FALSE(n.info.fallback);
        EXPECT_LT(RelErr(n.r, pb.r), 1e-12);
        EXPECT_LT(RelErr(f.r, pb.r), 1e-12);
        EXPECT_LT(RelErr(n.r, f.r), 1e-12);
        ExpectStates(cs, W, h, n.r, {st});
      }
}

// Many coupled points in mixed states through a dense random SPD W, dense and sparse overloads.
TEST(LocalSolver, NewtonMatchesConstructedSolutionMixedStates)
{
  std::mt19937 gen(7);
  const double h = 1e-4;
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear})
    for (PetscInt band : {-1, 2}) {
      const PetscInt        nc = 24;
      const ContactSet      cs = MakeSet(nc, 0.3, law, gen);
      const Eigen::MatrixXd W  = RandomW(nc, gen, band);
      std::vector<State>    states(nc);
      for (PetscInt c = 0; c < nc; ++c) states[c] = State(c % 3);
      std::shuffle(states.begin(), states.end(), gen);
      const Problem pb = Construct(cs, W, h, states, gen);
      Eigen::VectorXd r0 = Eigen::VectorXd::Zero(3 * nc);
      for (PetscInt c = 0; c < nc; ++c) r0[3 * c + kN] = 500; // all points pressed, none in its final state
      SCOPED_TRACE(::testing::Message() << FrictionLawName(law) << " band " << band);
      const Solved f = SolveOne(cs, W, h, pb, r0, false);
      EXPECT_TRUE(f.info.converged);
      EXPECT_LT(RelErr(f.r, pb.r), 1e-12);
      for (bool sparse : {false, true}) {
        if (sparse && band < 0) continue;
        const Solved n = SolveOne(cs, W, h, pb, r0, true, sparse);
        EXPECT_TRUE(n.info.converged) << "sparse " << sparse;
        EXPECT_FALSE(n.info.fallback) << "sparse " << sparse;
        EXPECT_LT(RelErr(n.r, pb.r), 1e-12) << "sparse " << sparse;
        EXPECT_LT(RelErr(n.r, f.r), 1e-12) << "sparse " << sparse;
        EXPECT_LT(n.info.iterations, f.info.iterations) << "sparse " << sparse;
        ExpectStates(cs, W, h, n.r, states);
      }
    }
}

// A sequence of problems, each warm-started from the last solution, whose points change state
// (open -> stick -> slip -> open ...): Newton and the fixed point agree at every one.
TEST(LocalSolver, NewtonFollowsTransitionsLikeFixedPoint)
{
  std::mt19937 gen(11);
  const double   h  = 1e-4;
  const PetscInt nc = 9;
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    const ContactSet      cs = MakeSet(nc, 0.4, law, gen);
    const Eigen::MatrixXd W  = RandomW(nc, gen);
    LocalContactSolver    fp, nw;
    fp.Setup(cs, W, h, 1.0), nw.Setup(cs, W, h, 1.0);
    fp.SetTolerances(1e-14, 100000, 1.0), nw.SetTolerances(1e-14, 100000, 1.0);
    nw.SetSolver(ContactSolver::kNewton);
    Eigen::VectorXd rf = Eigen::VectorXd::Zero(3 * nc), rn = rf;
    int             changes = 0;
    std::vector<State> prev(nc, kOpenS);
    for (int k = 0; k < 12; ++k) {
      std::vector<State> states(nc);
      for (PetscInt c = 0; c < nc; ++c) states[c] = State((c + k) % 3);
      for (PetscInt c = 0; c < nc; ++c) changes += states[c] != prev[c];
      prev             = states;
      const Problem pb = Construct(cs, W, h, states, gen);
      const LocalSolveInfo fi = fp.Solve(pb.w_f, pb.gap0, rf), ni = nw.Solve(pb.w_f, pb.gap0, rn);
      EXPECT_TRUE(fi.converged && ni.converged) << "problem " << k;
      EXPECT_LT(RelErr(rn, pb.r), 1e-12) << FrictionLawName(law) << " problem " << k;
      EXPECT_LT(RelErr(rn, rf), 1e-12) << FrictionLawName(law) << " problem " << k;
      EXPECT_LT((nw.Velocity() - fp.Velocity()).lpNorm<Eigen::Infinity>(), 1e-12 * (1 + fp.Velocity().lpNorm<Eigen::Infinity>()));
    }
    EXPECT_GE(changes, 11 * nc); // every point changes state at every problem but the first
    EXPECT_EQ(nw.NewtonSolves(), 12);
    EXPECT_GE(nw.Factorisations(), 1);
    EXPECT_LE(nw.Factorisations(), nw.NewtonSteps());
    EXPECT_EQ(nw.Fallbacks(), 0) << FrictionLawName(law);
  }
}

// Dense W: the Newton system solved through the condensed S (Woodbury on G = P Q, the default) and
// through the LU of J itself take the same steps: the same number of Newton steps and factorisations
// from a far start and along a sequence of problems whose points change state (every state, both
// laws), and the same reactions to 1e-12. A fresh factor at every solve's start (SetNewtonRefactor(0))
// gives the same reactions in fewer steps a solve.
TEST(LocalSolver, CondensedNewtonStepsAreThoseOfTheWholeJacobian)
{
  std::mt19937 gen(23);
  const double   h  = 1e-4;
  const PetscInt nc = 24;
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    SCOPED_TRACE(FrictionLawName(law));
    const ContactSet      cs = MakeSet(nc, 0.3, law, gen);
    const Eigen::MatrixXd W  = RandomW(nc, gen);
    LocalContactSolver    whole, cond, fresh;
    for (LocalContactSolver *ls : {&whole, &cond, &fresh}) {
      ls->Setup(cs, W, h, 1.0);
      ls->SetTolerances(1e-14, 100000, 1.0);
      ls->SetSolver(ContactSolver::kNewton);
    }
    whole.SetNewtonCondensed(false);
    fresh.SetNewtonRefactor(0);
    EXPECT_FALSE(whole.NewtonCondensed());
    EXPECT_TRUE(cond.NewtonCondensed());
    Eigen::VectorXd rw = Eigen::VectorXd::Zero(3 * nc);
    for (PetscInt c = 0; c < nc; ++c) rw[3 * c + kN] = 500; // pressed, none in its final state
    Eigen::VectorXd rc = rw, rf = rw;
    for (int k = 0; k < 10; ++k) {
      std::vector<State> states(nc);
      for (PetscInt c = 0; c < nc; ++c) states[c] = State((c + k / 2) % 3); // a change every other problem
      Problem pb = Construct(cs, W, h, states, gen);
      const LocalSolveInfo iw = whole.Solve(pb.w_f, pb.gap0, rw), ic = cond.Solve(pb.w_f, pb.gap0, rc), i_f = fresh.Solve(pb.w_f, pb.gap0, rf);
      EXPECT_TRUE(iw.converged && ic.converged && i_f.converged) << "problem " << k;
      EXPECT_EQ(ic.iterations, iw.iterations) << "problem " << k;
      EXPECT_LT(RelErr(rc, pb.r), 1e-12) << "problem " << k;
      EXPECT_LT(RelErr(rc, rw), 1e-12) << "problem " << k;
      EXPECT_LT(RelErr(rf, pb.r), 1e-12) << "problem " << k;
      EXPECT_LT((cond.Velocity() - whole.Velocity()).lpNorm<Eigen::Infinity>(), 1e-12 * (1 + whole.Velocity().lpNorm<Eigen::Infinity>()));
    }
    EXPECT_EQ(cond.NewtonSteps(), whole.NewtonSteps());
    EXPECT_EQ(cond.Factorisations(), whole.Factorisations());
    EXPECT_EQ(cond.Fallbacks() + whole.Fallbacks() + fresh.Fallbacks(), 0);
    EXPECT_GE(fresh.Factorisations(), fresh.NewtonSolves() - 1);
    EXPECT_LT(fresh.NewtonSteps(), cond.NewtonSteps());
    PetscPrintf(PETSC_COMM_WORLD, "%s: Newton steps %d (kept factor), %d (fresh at each solve), factorisations %d, %d\n", FrictionLawName(law),
                (int)cond.NewtonSteps(), (int)fresh.NewtonSteps(), (int)cond.Factorisations(), (int)fresh.Factorisations());
  }
}

// Newton made to fail (one iteration from a far start; a W whose Newton system is singular):
// the fixed point from the starting guess gives exactly its own result, and the fallback is counted.
TEST(LocalSolver, NewtonFailureFallsBackToFixedPoint)
{
  std::mt19937 gen(3);
  const double   h  = 1e-4;
  const PetscInt nc = 6;
  const ContactSet      cs = MakeSet(nc, 0.3, FrictionLaw::Planar, gen);
  const Eigen::MatrixXd W  = RandomW(nc, gen);
  std::vector<State>    states(nc);
  for (PetscInt c = 0; c < nc; ++c) states[c] = State(c % 3);
  const Problem   pb = Construct(cs, W, h, states, gen);
  const Eigen::VectorXd r0 = Eigen::VectorXd::Constant(3 * nc, 300.0);
  const Solved    f = SolveOne(cs, W, h, pb, r0, false), n = SolveOne(cs, W, h, pb, r0, true, false, 1);
  EXPECT_TRUE(n.info.fallback);
  EXPECT_TRUE(n.info.converged);
  EXPECT_EQ(n.r, f.r); // the fixed point's own iterates
  EXPECT_EQ(n.info.iterations, f.info.iterations + 1);

  // Two identical points: W singular, so is J on closed points; the dense LU gives non-finite steps.
  ContactSet      cs2 = MakeSet(2, 0.3, FrictionLaw::Planar, gen);
  Eigen::MatrixXd W2(6, 6);
  W2 << W.topLeftCorner(3, 3), W.topLeftCorner(3, 3), W.topLeftCorner(3, 3), W.topLeftCorner(3, 3);
  cs2.points[1].speed_factor = cs2.points[0].speed_factor;
  Problem pb2;
  pb2.w_f  = Eigen::VectorXd::Zero(6);
  pb2.gap0 = Eigen::VectorXd::Constant(2, -1e-6); // both pressed in: both closed at the solution
  for (int c = 0; c < 2; ++c) pb2.w_f[3 * c + kT] = cs2.Speed(c) + 0.5;
  const Solved f2 = SolveOne(cs2, W2, h, pb2, Eigen::VectorXd::Zero(6), false), n2 = SolveOne(cs2, W2, h, pb2, Eigen::VectorXd::Zero(6), true);
  EXPECT_TRUE(f2.info.converged);
  PetscPrintf(PETSC_COMM_WORLD, "singular W: Newton %s after %d iterations\n", n2.info.fallback ? "fell back to the fixed point" : "converged",
              (int)(n2.info.iterations - (n2.info.fallback ? f2.info.iterations : 1)));
  if (n2.info.fallback) {
    EXPECT_EQ(n2.r, f2.r);
  }
  // Either way the reactions are a solution: equal loads sharing the impulse (W r is what is fixed).
  EXPECT_LT(RelErr(W2 * n2.r, W2 * f2.r), 1e-12);
}

// A smooth trajectory of problems (w_f turning slowly about a constructed problem of 40 coupled
// points, mostly sliding, a few stuck or open), each solve warm-started from the last solution as
// the integrator does: the fixed point with and without the extrapolated start, Newton with plain
// chord steps and with Anderson mixing + the extrapolated start, and the fixed point with mixed
// passes + the extrapolated start (dense and sparse W), all agree to 1e-12 at every problem; the
// extrapolation saves fixed-point passes, and Anderson + extrapolation Newton steps.
// A start that is not the last solution restarts the history: the same bits as a fresh solver.
TEST(LocalSolver, AndersonAndPredictorFollowASmoothTrajectory)
{
  std::mt19937 gen(5);
  const double   h  = 1e-4;
  const PetscInt nc = 40, steps = 60;
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    SCOPED_TRACE(FrictionLawName(law));
    const ContactSet      cs = MakeSet(nc, 0.3, law, gen);
    const Eigen::MatrixXd W  = RandomW(nc, gen);
    std::vector<State>    states(nc, kSlipS);
    for (PetscInt c = 0; c < nc; c += 7) states[c] = c % 2 ? kStickS : kOpenS;
    const Problem pb = Construct(cs, W, h, states, gen);
    std::normal_distribution<double> n(0, 1);
    Eigen::VectorXd                  dir(3 * nc);
    for (auto &x : dir) x = n(gen);
    dir *= 0.05 * pb.w_f.norm() / dir.norm();
    // 0: fixed point, previous reactions; 1: fixed point, quadratic extrapolation; 2: Newton, plain
    // chord steps; 3: Newton, Anderson (5) + quadratic extrapolation; 4 and 5: fixed point, mixed
    // passes (5) + quadratic extrapolation, on the dense and on the sparse W.
    constexpr int      K = 6;
    LocalContactSolver ls[K];
    Eigen::VectorXd    r[K];
    long               its[K] = {0, 0, 0, 0, 0, 0};
    for (int k = 0; k < K; ++k) {
      if (k == 5) ls[k].Setup(cs, Eigen::SparseMatrix<PetscReal>(W.sparseView()), h, 1.0);
      else ls[k].Setup(cs, W, h, 1.0);
      ls[k].SetTolerances(1e-14, 100000, 1.0);
      if (k == 2 || k == 3) ls[k].SetSolver(ContactSolver::kNewton, 30, k == 3 ? 5 : 0);
      if (k >= 4) ls[k].SetFixedPointAnderson(5);
      ls[k].SetPredictor(k % 2 || k >= 4 ? 2 : 0);
      r[k] = pb.r;
    }
    for (PetscInt i = 0; i < steps; ++i) {
      const Eigen::VectorXd w_f = pb.w_f + std::sin(2 * M_PI * i / 40.0) * dir;
      for (int k = 0; k < K; ++k) {
        const LocalSolveInfo info = ls[k].Solve(w_f, pb.gap0, r[k]);
        ASSERT_TRUE(info.converged) << "solver " << k << " problem " << i;
        EXPECT_FALSE(info.fallback) << "solver " << k << " problem " << i;
        its[k] += info.iterations;
        if (k) {
          EXPECT_LT(RelErr(r[k], r[0]), 1e-12) << "solver " << k << " problem " << i;
        }
      }
    }
    PetscPrintf(PETSC_COMM_WORLD,
                "%s, %d problems: fixed-point passes %ld -> %ld with the extrapolation; Newton iterations (+ passes) %ld -> %ld with "
                "Anderson and the extrapolation (%d mixed steps, %d factorisations); passes %ld (dense), %ld (sparse) mixed\n",
                FrictionLawName(law), (int)steps, its[0], its[1], its[2], its[3], (int)ls[3].MixedSteps(), (int)ls[3].Factorisations(),
                its[4], its[5]);
    EXPECT_LT(its[1], its[0]);
    EXPECT_LT(its[3], its[2]);
    EXPECT_LE(its[4], its[1]); // W diagonally dominant: few passes, which mixing barely cuts (next test)
    EXPECT_GT(ls[4].MixedPasses(), 0);
    EXPECT_EQ(ls[1].MixedPasses(), 0);
    EXPECT_NEAR((double)its[5], (double)its[4], 0.02 * its[4]); // the same passes, summed in another order
    EXPECT_GT(ls[3].MixedSteps(), 0);
    EXPECT_EQ(ls[2].MixedSteps(), 0);
    // Another start: no extrapolation from the history (the same bits as a solver without one).
    LocalContactSolver fresh;
    fresh.Setup(cs, W, h, 1.0);
    fresh.SetTolerances(1e-14, 100000, 1.0);
    fresh.SetPredictor(2);
    Eigen::VectorXd a = Eigen::VectorXd::Zero(3 * nc), b = a;
    ls[1].Solve(pb.w_f, pb.gap0, a);
    fresh.Solve(pb.w_f, pb.gap0, b);
    EXPECT_EQ(a, b);
  }
}

// Mixed fixed-point passes (SetFixedPointAnderson) where Gauss-Seidel is slow: W = B B^T with a
// small diagonal shift, strongly coupled like the Delassus operator of a reduced FE model (the
// size-2 brake's needs 82 passes per step). On problems with every state, planar and rectilinear,
// dense and sparse W: the same reactions as the plain passes to 1e-12, the constructed solution
// to 1e-10, the result a pass's own output (same stopping test), and at least 25 % fewer passes.
TEST(LocalSolver, MixedPassesWhereGaussSeidelIsSlow)
{
  std::mt19937 gen(11);
  const double          h  = 1e-4;
  const PetscInt        nc = 30, m = 3 * nc;
  const Eigen::MatrixXd W  = CoupledW(m, gen);
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    SCOPED_TRACE(FrictionLawName(law));
    const ContactSet cs = MakeSet(nc, 0.3, law, gen);
    long             passes[3] = {0, 0, 0};
    for (int k = 0; k < 6; ++k) {
      std::vector<State> states(nc);
      for (PetscInt c = 0; c < nc; ++c) states[c] = c % 5 == k % 5 ? State((c + k) % 3) : kSlipS;
      const Problem   pb = Construct(cs, W, h, states, gen);
      Eigen::VectorXd r[3];
      for (int j = 0; j < 3; ++j) { // plain, mixed dense, mixed sparse
        LocalContactSolver ls;
        if (j == 2) ls.Setup(cs, Eigen::SparseMatrix<PetscReal>(W.sparseView()), h, 1.0);
        else ls.Setup(cs, W, h, 1.0);
        ls.SetTolerances(1e-14, 100000, 1.0);
        if (j) ls.SetFixedPointAnderson(5);
        r[j]                      = Eigen::VectorXd::Zero(m);
        const LocalSolveInfo info = ls.Solve(pb.w_f, pb.gap0, r[j]);
        ASSERT_TRUE(info.converged) << "solver " << j << " problem " << k;
        EXPECT_LE(info.residual, 1e-14);
        passes[j] += info.iterations;
        EXPECT_LT(RelErr(r[j], pb.r), 1e-10) << "solver " << j << " problem " << k;
        if (j) {
          EXPECT_LT(RelErr(r[j], r[0]), 1e-12) << "solver " << j << " problem " << k;
          EXPECT_GT(ls.MixedPasses(), 0);
        }
      }
    }
    // Capped at 3 passes (not converged): the last pass's output, so inside the friction set.
    {
      std::vector<State> states(nc, kSlipS);
      const Problem      pb = Construct(cs, W, h, states, gen);
      LocalContactSolver ls;
      ls.Setup(cs, W, h, 1.0);
      ls.SetTolerances(1e-14, 3, 1.0);
      ls.SetFixedPointAnderson(5);
      Eigen::VectorXd      r    = Eigen::VectorXd::Zero(m);
      const LocalSolveInfo info = ls.Solve(pb.w_f, pb.gap0, r);
      EXPECT_FALSE(info.converged);
      EXPECT_EQ(info.iterations, 3);
      for (PetscInt c = 0; c < nc; ++c) {
        const PetscReal rn = r[3 * c + kN], rt = r[3 * c + kT], rb = r[3 * c + kB];
        EXPECT_GE(rn, 0.0) << "point " << c;
        EXPECT_LE(std::hypot(rt, rb), cs.Mu() * rn * (1 + 1e-12)) << "point " << c;
      }
    }
    PetscPrintf(PETSC_COMM_WORLD, "%s, 6 problems on a strongly coupled W: fixed-point passes %ld plain, %ld mixed (dense), %ld (sparse)\n",
                FrictionLawName(law), passes[0], passes[1], passes[2]);
    EXPECT_LT(passes[1], 0.75 * passes[0]);
    EXPECT_NEAR((double)passes[2], (double)passes[1], 0.05 * passes[1]);
  }
}

// SetFixedPointSingle: the passes read h W rounded to float. On every state (open, stick, slip, each
// law), mixed and plain, from zero and from a start 1e-3 off the solution, at the transient's 1e-12:
// the constructed solution; the double passes' reactions; the velocity left for the caller is
// w_f + h W r of the result with the double W; and the result passes the double passes' stopping test
// (one exact pass from it changes it by at most the tolerance), which on this W needs products with
// the double h W during the solves. Not taken on a sparse W, below the size asked, or on entries
// float cannot hold.
TEST(LocalSolver, PassesOnAFloatWSolveWhatTheDoublePassesSolve)
{
  std::mt19937 gen(31);
  const double          h  = 1e-4, tol = 1e-12;
  const PetscInt        nc = 30, m = 3 * nc;
  const Eigen::MatrixXd W  = CoupledW(m, gen);
  std::normal_distribution<double> noise(0, 1);
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    SCOPED_TRACE(FrictionLawName(law));
    const ContactSet cs = MakeSet(nc, 0.3, law, gen);
    PetscInt         refreshes = 0;
    for (int k = 0; k < 6; ++k) {
      std::vector<State> states(nc);
      for (PetscInt c = 0; c < nc; ++c) states[c] = c % 5 == k % 5 ? State((c + k) % 3) : kSlipS;
      const Problem pb = Construct(cs, W, h, states, gen);
      Eigen::VectorXd near = pb.r;
      for (auto &x : near) x *= 1 + 1e-3 * noise(gen);
      for (PetscInt depth : {0, 5})
        for (int start = 0; start < 2; ++start) {
          SCOPED_TRACE("problem " + std::to_string(k) + ", mixing depth " + std::to_string(depth) + (start ? ", start near" : ", start 0"));
          Eigen::VectorXd r[2];
          for (int j = 0; j < 2; ++j) { // double, float
            LocalContactSolver ls;
            ls.Setup(cs, W, h, 1.0);
            ls.SetTolerances(tol, 100000, 1.0);
            ls.SetFixedPointAnderson(depth);
            ASSERT_EQ(ls.SetFixedPointSingle(j ? m : 0), j == 1);
            r[j]                      = start ? near : Eigen::VectorXd::Zero(m);
            const LocalSolveInfo info = ls.Solve(pb.w_f, pb.gap0, r[j]);
            ASSERT_TRUE(info.converged);
            EXPECT_LE(info.residual, tol);
            EXPECT_LT(RelErr(r[j], pb.r), 1e-9);
            const Eigen::VectorXd v = pb.w_f + h * W * r[j];
            EXPECT_LT((ls.Velocity() - v).norm(), 1e-13 * v.norm());
            if (j == 0) continue;
            refreshes += ls.Refreshes();
            LocalContactSolver exact; // one double pass from the result
            exact.Setup(cs, W, h, 1.0);
            exact.SetTolerances(tol, 1, 1.0);
            Eigen::VectorXd      r1  = r[1];
            const LocalSolveInfo one = exact.Solve(pb.w_f, pb.gap0, r1);
            EXPECT_LE(one.residual, tol);
          }
          EXPECT_LT(RelErr(r[1], r[0]), 1e-11);
        }
    }
    PetscPrintf(PETSC_COMM_WORLD, "%s, 24 solves on a strongly coupled W with h W in float: %" PetscInt_FMT " products with the double h W besides the first\n",
                FrictionLawName(law), refreshes);
    EXPECT_GT(refreshes, 0);
  }
  const ContactSet   cs = MakeSet(nc, 0.3, FrictionLaw::Planar, gen);
  LocalContactSolver ls;
  ls.Setup(cs, W, h, 1.0);
  EXPECT_FALSE(ls.SetFixedPointSingle(m + 1));
  EXPECT_FALSE(ls.SetFixedPointSingle(0));
  EXPECT_TRUE(ls.SetFixedPointSingle(m));
  ls.Setup(cs, W, h, 1.0); // a new Setup drops it
  EXPECT_FALSE(ls.FixedPointSingle());
  ls.Setup(cs, Eigen::MatrixXd(1e36 * W), h, 1.0);
  EXPECT_FALSE(ls.SetFixedPointSingle(1));
  ls.Setup(cs, W, h, 1.0);
  ls.SetFixedPointSymmetric(true); // the sweeps read the double W
  EXPECT_FALSE(ls.SetFixedPointSingle(1));
  ls.Setup(cs, Eigen::SparseMatrix<PetscReal>(W.sparseView()), h, 1.0);
  EXPECT_FALSE(ls.SetFixedPointSingle(1));
}

// SetFixedPointSymmetric: symmetric Gauss-Seidel sweeps, each reading half of W. On every state
// (open, stick, slip, each law) against the constructed solution and the forward passes; the
// velocity left for the caller (Velocity()) is w_f + h W r of the result, whether the last sweep ran
// forward or backward; capped, the output lies in the friction set with its velocity consistent.
TEST(LocalSolver, SymmetricSweepsSolveWhatThePassesSolve)
{
  std::mt19937 gen(23);
  const double          h  = 1e-4;
  const PetscInt        nc = 30, m = 3 * nc;
  const Eigen::MatrixXd W  = CoupledW(m, gen);
  for (FrictionLaw law : {FrictionLaw::Planar, FrictionLaw::Rectilinear}) {
    SCOPED_TRACE(FrictionLawName(law));
    const ContactSet cs = MakeSet(nc, 0.3, law, gen);
    bool             parity[2] = {false, false}; // sweeps ended forward (odd count) / backward (even)
    long             count[2]  = {0, 0};
    for (int k = 0; k < 6; ++k) {
      std::vector<State> states(nc);
      for (PetscInt c = 0; c < nc; ++c) states[c] = c % 5 == k % 5 ? State((c + k) % 3) : kSlipS;
      const Problem   pb = Construct(cs, W, h, states, gen);
      Eigen::VectorXd r[2];
      for (int j = 0; j < 2; ++j) { // forward passes (mixed, the default), symmetric sweeps
        LocalContactSolver ls;
        ls.Setup(cs, W, h, 1.0);
        ls.SetTolerances(1e-14, 100000, 1.0);
        ls.SetFixedPointAnderson(5);
        ls.SetFixedPointSymmetric(j == 1);
        r[j]                      = Eigen::VectorXd::Zero(m);
        const LocalSolveInfo info = ls.Solve(pb.w_f, pb.gap0, r[j]);
        ASSERT_TRUE(info.converged) << "solver " << j << " problem " << k;
        EXPECT_LT(RelErr(r[j], pb.r), 1e-10) << "solver " << j << " problem " << k;
        const Eigen::VectorXd v = pb.w_f + h * W * r[j];
        EXPECT_LT((ls.Velocity() - v).norm(), 1e-12 * v.norm()) << "solver " << j << " problem " << k;
        if (j == 1) parity[info.iterations % 2] = true;
        count[j] += info.iterations;
      }
      EXPECT_LT(RelErr(r[1], r[0]), 1e-12) << "problem " << k;
    }
    EXPECT_TRUE(parity[0] && parity[1]) << "the sweeps never ended in one of the two directions";
    PetscPrintf(PETSC_COMM_WORLD, "%s, 6 problems on a strongly coupled W: %ld mixed forward passes, %ld symmetric sweeps (each half of W)\n",
                FrictionLawName(law), count[0], count[1]);
    for (PetscInt cap : {3, 4}) {
      std::vector<State> states(nc, kSlipS);
      const Problem      pb = Construct(cs, W, h, states, gen);
      LocalContactSolver ls;
      ls.Setup(cs, W, h, 1.0);
      ls.SetTolerances(1e-14, cap, 1.0);
      ls.SetFixedPointSymmetric(true);
      Eigen::VectorXd      r    = Eigen::VectorXd::Zero(m);
      const LocalSolveInfo info = ls.Solve(pb.w_f, pb.gap0, r);
      EXPECT_FALSE(info.converged);
      EXPECT_EQ(info.iterations, cap);
      for (PetscInt c = 0; c < nc; ++c) {
        const PetscReal rn = r[3 * c + kN], rt = r[3 * c + kT], rb = r[3 * c + kB];
        EXPECT_GE(rn, 0.0) << "point " << c;
        EXPECT_LE(std::hypot(rt, rb), cs.Mu() * rn * (1 + 1e-12)) << "point " << c;
      }
      const Eigen::VectorXd v = pb.w_f + h * W * r;
      EXPECT_LT((ls.Velocity() - v).norm(), 1e-12 * v.norm()) << "capped at " << cap;
    }
  }
}

// Whole transients through ThetaIntegrator: -theta_contact_solver ssn against fp on the 3-DOF
// (separation/slip and stick/slip cases, run-time-sized dense kernel) and on a 6-cell chain on the
// dense and the sparse back end (dense and sparse W): the same states to round-off.
TEST(LocalSolver, ThetaSsnMatchesFixedPoint)
{
  struct Case {
    bool    chain;
    double  V;
    PetscInt dense_max, delassus_max;
  };
  for (const Case cse : {Case{false, 3.0, 200, -1}, Case{false, 0.75, 200, -1}, Case{true, 0, 200, -1}, Case{true, 0, 0, 1000},
                         Case{true, 0, 0, 0}}) {
    Model model;
    if (cse.chain) {
      ChainParams p;
      p.cells = 6;
      ASSERT_EQ(BuildChain(PETSC_COMM_WORLD, p, model), 0);
    } else {
      ThreeDofParams p;
      p.V = cse.V;
      ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
    }
    EquilibriumSolver  eqs(PETSC_COMM_WORLD);
    SlidingEquilibrium eq;
    ASSERT_EQ(eqs.Solve(model, eq), 0);
    const PetscInt nc = model.contacts.Size(), N = model.Size();
    test::Integration run[4]; // fp, ssn, fp in symmetric sweeps, fp on h W in float
    for (int k = 0; k < 4; ++k) {
      ASSERT_EQ(run[k].ti.SetFromOptions(), 0);
      ASSERT_EQ(run[k].ti.SetDenseMax(cse.dense_max), 0);
      ASSERT_EQ(run[k].ti.SetDelassusMax(cse.delassus_max, 0.0), 0);
      ASSERT_EQ(run[k].ti.SetContactSolver(k == 1 ? "ssn" : "fp", 30), 0);
      run[k].ti.SetFixedPointSymmetric(k == 2 ? PETSC_TRUE : PETSC_FALSE);
      run[k].ti.SetFixedPointSingle(k == 3 ? 1 : 0);
      ASSERT_EQ(run[k].ti.SetUp(model, 1e-5), 0);
      ASSERT_EQ(VecDuplicate(eq.U, &run[k].U), 0);
      ASSERT_EQ(VecCopy(eq.U, run[k].U), 0);
      ASSERT_EQ(VecDuplicate(eq.U, &run[k].dU), 0);
      // Away from the equilibrium: lift-off and impacts (3-DOF case 1, the chain), stick (case 2).
      Eigen::VectorXd dU0(N);
      for (PetscInt i = 0; i < N; ++i) dU0[i] = 0.3 * std::sin(1.0 + 2.0 * i);
      if (!cse.chain) {
        // Element by element: a Vector3d assigned to the dynamic vector trips GCC 12's -Warray-bounds.
        const double a[2][3] = {{0.4, -0.3, 0.25}, {cse.V, 0, 0.02}};
        for (int i = 0; i < 3; ++i) dU0[i] = a[cse.V > 1 ? 0 : 1][i];
      }
      std::vector<PetscInt> idx(N);
      for (PetscInt i = 0; i < N; ++i) idx[i] = i;
      PetscInt lo, hi;
      ASSERT_EQ(VecGetOwnershipRange(run[k].dU, &lo, &hi), 0);
      for (PetscInt i = lo; i < hi; ++i) ASSERT_EQ(VecSetValue(run[k].dU, i, dU0[i], INSERT_VALUES), 0);
      ASSERT_EQ(VecAssemblyBegin(run[k].dU), 0);
      ASSERT_EQ(VecAssemblyEnd(run[k].dU), 0);
      run[k].r = Eigen::VectorXd::Zero(3 * nc);
      for (PetscInt c = 0; c < nc; ++c) run[k].r[3 * c + kN] = eq.N[c], run[k].r[3 * c + kT] = model.contacts.Mu() * eq.N[c];
    }
    ASSERT_EQ(run[1].ti.Contact().Solver(), ContactSolver::kNewton);
    ASSERT_FALSE(run[1].ti.FixedSizeKernel());
    ASSERT_EQ(run[0].ti.SparseDelassus(), run[1].ti.SparseDelassus());
    const PetscInt steps = 3000;
    double         maxdiff = 0, scale = 0, maxdiff_sym = 0, maxdiff_single = 0;
    long           its[4] = {0, 0, 0, 0};
    int            seen[3] = {0, 0, 0};
    std::vector<int> status;
    for (PetscInt i = 0; i < steps; ++i) {
      StepInfo info[4];
      for (int k = 0; k < 4; ++k) {
        ASSERT_EQ(run[k].ti.Step(run[k].U, run[k].dU, run[k].r, &info[k]), 0);
        ASSERT_TRUE(info[k].contact.converged);
        its[k] += info[k].contact.iterations;
      }
      const Eigen::VectorXd a = test::ToDense(run[0].dU), b = test::ToDense(run[1].dU);
      maxdiff = std::max(maxdiff, (a - b).lpNorm<Eigen::Infinity>());
      maxdiff_sym = std::max(maxdiff_sym, (a - test::ToDense(run[2].dU)).lpNorm<Eigen::Infinity>());
      maxdiff_single = std::max(maxdiff_single, (a - test::ToDense(run[3].dU)).lpNorm<Eigen::Infinity>());
      scale   = std::max(scale, a.lpNorm<Eigen::Infinity>());
      run[0].ti.Contact().Status(run[0].r, status);
      for (int s : status) ++seen[s];
    }
    EXPECT_LT(maxdiff, 1e-9 * scale) << "chain " << cse.chain << " V " << cse.V << " dense_max " << cse.dense_max;
    EXPECT_LT(maxdiff_sym, 1e-9 * scale) << "symmetric sweeps: chain " << cse.chain << " V " << cse.V << " dense_max " << cse.dense_max;
    // The sweeps run where W is dense and the kernel run-time-sized: the 6-cell chain on the dense back end.
    // The float passes run on a dense W on run-time sizes: the chain but on a sparse W. The states
    // are those of the double passes to the fixed point's tolerance.
    EXPECT_EQ(run[3].ti.Contact().FixedPointSingle(), cse.chain && cse.delassus_max != 0);
    EXPECT_LT(maxdiff_single, 1e-11 * scale) << "h W in float: chain " << cse.chain << " dense_max " << cse.dense_max;
    if (cse.chain && cse.dense_max) {
      EXPECT_NE(its[2], its[0]);
    }
    EXPECT_EQ(run[1].ti.Contact().NewtonSolves(), steps);
    EXPECT_EQ(run[1].ti.Contact().Fallbacks(), 0);
    PetscPrintf(PETSC_COMM_WORLD,
                "%s%s: open/stick/slip %d/%d/%d, iterations per step fp %.2f ssn %.2f (Newton %.2f, %d factorisations, fallbacks %d), "
                "largest |dU| difference %.2e of %.2e; symmetric sweeps %.2f per step, %.2e; h W in float %.2f per step, %.2e\n",
                cse.chain ? "chain 6" : "3-DOF", cse.chain ? (cse.dense_max ? " dense" : cse.delassus_max ? " sparse, dense W" : " sparse W") : (cse.V > 1 ? " case 1" : " case 2"),
                seen[0], seen[1], seen[2], (double)its[0] / steps, (double)its[1] / steps,
                (double)run[1].ti.Contact().NewtonSteps() / steps, (int)run[1].ti.Contact().Factorisations(),
                (int)run[1].ti.Contact().Fallbacks(), maxdiff, scale, (double)its[2] / steps, maxdiff_sym, (double)its[3] / steps, maxdiff_single);
  }
}

TEST(LocalSolver, BadContactSolverOptionIsRejected)
{
  ThetaIntegrator ti(PETSC_COMM_WORLD);
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  EXPECT_NE(ti.SetContactSolver("newton", 30), 0);
  EXPECT_NE(ti.SetContactSolver("ssn", 0), 0);
  EXPECT_NE(ti.SetContactSolver("ssn", 30, -1), 0);
  EXPECT_NE(ti.SetContactSolver("ssn", 30, 9), 0);
  PetscPopErrorHandler();
  EXPECT_EQ(ti.SetContactSolver("auto", 5), 0);
}

// core/hypot.h: the hypot of the friction projection against libm's (bit for bit, also where it
// is written out, HypotWrittenOut()) and both against sqrt(x^2 + y^2) in long double, within
// 1 ulp, over magnitudes from subnormal to huge, ratios across the algorithm's branch (2 |y| = h)
// and cut-off (|y| = 2^-54 |x|), and the special values.
TEST(LocalSolver, HypotIsLibmHypot)
{
  std::mt19937                           gen(11);
  std::uniform_real_distribution<double> mant(1.0, 2.0), sgn(-1.0, 1.0);
  std::uniform_int_distribution<int>     ex(-1074, 1023), near(-60, 60);
  const auto ulp_err = [](double v, double x, double y) {
    const long double ref = std::sqrt((long double)x * x + (long double)y * y);
    const double      r   = (double)ref;
    if (!std::isfinite(r)) return std::isinf(v) ? 0.0L : 1e9L;
    const double u = std::nextafter(r, INFINITY) - r;
    return std::abs((long double)v - ref) / (long double)(u > 0 ? u : 1e-300);
  };
  long        n = 0, inlined = 0;
  long double worst = 0;
  const auto  check = [&](double x, double y) {
    const double v = Hypot(x, y), ref = std::hypot(x, y);
    EXPECT_EQ(std::memcmp(&v, &ref, sizeof v), 0) << std::hexfloat << x << " " << y << ": " << v << " against libm " << ref;
    const double fx = std::abs(x), fy = std::abs(y), ax = std::max(fx, fy), ay = std::min(fx, fy);
    inlined += ax <= 0x1p+511 && ay >= 0x1p-459 && ay > ax * 0x1p-54;
    // The reference: x^2 + y^2 in long double (x87: a 64-bit mantissa and exponents to +-16383, so
    // every double squares without overflow or underflow, to 2^-64 relative).
    worst = std::max(worst, ulp_err(v, x, y));
    ++n;
  };
  for (int i = 0; i < 400000; ++i) {
    const int    e1 = i % 4 == 0 ? ex(gen) : near(gen), e2 = i % 3 == 0 ? e1 - (int)(gen() % 70) : e1 + near(gen) / 20;
    const double x  = std::ldexp(mant(gen), std::clamp(e1, -1074, 1023)) * (sgn(gen) < 0 ? -1 : 1);
    const double y  = std::ldexp(mant(gen), std::clamp(e2, -1074, 1023)) * (sgn(gen) < 0 ? -1 : 1);
    check(x, y);
    check(y, x);
  }
  // Near the two branches of the correction (h close to 2 ay: ay / ax close to 1 / sqrt(3)) and the cut-off.
  for (int i = 0; i < 100000; ++i) {
    const double x = mant(gen) * std::ldexp(1.0, near(gen));
    check(x, x / std::sqrt(3.0) * (1 + 1e-6 * sgn(gen)));
    check(x, x * 0x1p-54 * (1 + 1e-3 * sgn(gen)));
    check(x, x * (1 + 1e-3 * sgn(gen)));
    // around the range's bounds (2^-459 for the smaller, 2^511 for the larger magnitude)
    const int b = i % 2 ? -459 : 511, k1 = (int)(gen() % 7) - 3, k2 = (int)(gen() % 7) - 3;
    check(std::ldexp(mant(gen), b + k1), std::ldexp(mant(gen), b + k2));
  }
  const double specials[] = {0.0, -0.0, 1.0, 0x1p-1074, 0x1p-511, 0x1p-459, 0x1p+511, 0x1.fffffffffffffp+1023, INFINITY, -INFINITY, NAN, 3.0, 4.0};
  for (double x : specials)
    for (double y : specials) {
      const double v = Hypot(x, y), ref = std::hypot(x, y);
      if (std::isnan(ref)) EXPECT_TRUE(std::isnan(v)) << x << " " << y;
      else EXPECT_EQ(v, ref) << x << " " << y;
    }
  EXPECT_EQ(Hypot(3.0, 4.0), 5.0);
  EXPECT_LE(worst, 1.0) << "largest error of Hypot in ulp";
  EXPECT_GT(inlined, n / 2); // the test reaches the written-out range
  PetscPrintf(PETSC_COMM_WORLD, "Hypot: %ld pairs, %ld in the written-out range, largest error %.3Lf ulp (written out: %s; bit for bit against libm)\n", n, inlined, worst,
              HypotWrittenOut() ? "yes" : "no, libm's hypot");
}
