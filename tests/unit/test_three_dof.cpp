// The reference 3-DOF system against closed forms (docs/method.md §3.2, §4.2, §8) and dense solves.
#include "dense.h"
#include "squeal/model/builders.h"
#include "squeal/stability/stability.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace squeal;

namespace {

constexpr double kDeg = M_PI / 180.0;

struct Solved {
  SlidingEquilibrium eq;
  StabilityResult    res;
};

void Solve(Model &model, Solved &s, MPI_Comm comm = PETSC_COMM_WORLD)
{
  EquilibriumSolver eqs(comm);
  StabilitySolver   stab(comm);
  ASSERT_EQ(eqs.SetFromOptions(), 0);
  ASSERT_EQ(stab.SetFromOptions(), 0);
  ASSERT_EQ(eqs.Solve(model, s.eq), 0);
  ASSERT_EQ(stab.Solve(model, s.eq, s.res), 0);
}

// Eigenvalues of the 4x4 companion matrix of the reduced QEP written out by hand from
// docs/method.md §4.2 (M_r = m I, C_r = diag(c, c + mu N / V), K_r from K's entries): no library code.
std::vector<std::complex<double>> CompanionReference(const ThreeDofParams &p)
{
  PetscReal Kx[3][3], K[3][3];
  ThreeDofStiffness(p, Kx, K);
  const double a  = std::tan(p.alpha * kDeg) * std::cos(p.gamma * kDeg) + std::tan(p.beta * kDeg) * std::sin(p.gamma * kDeg);
  const double N  = p.Fn / (1 - p.mu * a);
  const double db = p.law == FrictionLaw::Planar ? p.mu * N / p.V : 0.0;
  Eigen::Matrix2d Mr = p.m * Eigen::Matrix2d::Identity(), Cr, Kr;
  Cr << p.c, 0, 0, p.c + db;
  Kr << K[0][0] - p.mu * K[2][0], K[0][1] - p.mu * K[2][1], K[1][0], K[1][1];
  Eigen::Matrix4d A = Eigen::Matrix4d::Zero();
  A.topRightCorner<2, 2>()    = Eigen::Matrix2d::Identity();
  A.bottomLeftCorner<2, 2>()  = -Mr.inverse() * Kr;
  A.bottomRightCorner<2, 2>() = -Mr.inverse() * Cr;
  Eigen::EigenSolver<Eigen::Matrix4d> es(A);
  std::vector<std::complex<double>>   out;
  for (int i = 0; i < 4; ++i)
    if (es.eigenvalues()(i).imag() >= 0) out.push_back(es.eigenvalues()(i));
  std::sort(out.begin(), out.end(), [](auto x, auto y) { return x.imag() < y.imag(); });
  return out;
}

void ExpectMatches(const StabilityResult &res, const std::vector<std::complex<double>> &ref, double rtol)
{
  ASSERT_EQ(res.modes.size(), ref.size());
  // Match each to its nearest reference: ordering by omega is not stable when two modes share
  // omega to round-off (rectilinear friction).
  for (size_t i = 0; i < ref.size(); ++i) {
    const std::complex<double> l(res.modes[i].sigma, res.modes[i].omega);
    size_t                     j = 0;
    for (size_t k = 1; k < ref.size(); ++k)
      if (std::abs(l - ref[k]) < std::abs(l - ref[j])) j = k;
    EXPECT_LE(std::abs(l - ref[j]), rtol * std::abs(ref[j])) << "mode " << i << ": " << l << " vs " << ref[j];
    EXPECT_LT(res.modes[i].error, 1e-10);
  }
}

} // namespace

TEST(ThreeDof, EquilibriumMatchesClosedForm)
{
  ThreeDofParams p;
  Model          model;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  Solved s;
  Solve(model, s);
  // (3.2) and the reference figures of docs/method.md §8.
  EXPECT_NEAR(s.eq.N[0], 338.1197846482994, 1e-9);
  const Eigen::VectorXd U = test::ToDense(s.eq.U);
  EXPECT_NEAR(U(0), 5.128039786740352e-4, 1e-15);
  EXPECT_NEAR(U(1), 8.595508503744157e-05, 1e-15);
  EXPECT_NEAR(U(2), 0.0, 1e-15);
  // R = K U - F = B_mu N = (mu N, 0, N).
  const Eigen::VectorXd R = test::ToDense(s.eq.R);
  EXPECT_NEAR(R(0), 0.5 * s.eq.N[0], 1e-9);
  EXPECT_NEAR(R(1), 0.0, 1e-9);
  EXPECT_NEAR(R(2), s.eq.N[0], 1e-9);
}

TEST(ThreeDof, PlanarEigenvaluesMatchDenseCompanionAndReference)
{
  for (double V : {3.0, 0.75}) {
    ThreeDofParams p;
    p.V = V;
    Model model;
    ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
    Solved s;
    Solve(model, s);
    ExpectMatches(s.res, CompanionReference(p), 1e-8);
    ASSERT_EQ(s.res.unstable.size(), 1u);
    const Mode &u = s.res.modes[s.res.unstable[0]];
    const double T_talk = V == 3.0 ? 0.0109 : 0.0107;
    EXPECT_NEAR(u.Period(), T_talk, 0.005 * T_talk); // the seed talk's figure, 0.5 %
    const double sigma_ref = V == 3.0 ? 55.34326434704188 : 30.640192768076844;
    EXPECT_NEAR(u.sigma, sigma_ref, 1e-8 * sigma_ref);
  }
}

TEST(ThreeDof, RectilinearPeriodDoesNotDependOnV)
{
  std::vector<double> periods;
  for (double V : {3.0, 0.75, 0.01}) {
    ThreeDofParams p;
    p.V   = V;
    p.law = FrictionLaw::Rectilinear;
    Model model;
    ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
    Solved s;
    Solve(model, s);
    ExpectMatches(s.res, CompanionReference(p), 1e-8);
    ASSERT_EQ(s.res.unstable.size(), 1u);
    periods.push_back(s.res.modes[s.res.unstable[0]].Period());
  }
  EXPECT_NEAR(periods[0], 0.011005381390328039, 1e-12);
  EXPECT_NEAR(periods[1], periods[0], 1e-12);
  EXPECT_NEAR(periods[2], periods[0], 1e-12);
}

TEST(ThreeDof, ReductionMatchesBorderedQZ)
{
  // The finite eigenvalues of the bordered QEP (4.4), by QZ, check the elimination itself.
  ThreeDofParams p;
  Model          model;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  Solved s;
  Solve(model, s);
  auto all = test::BorderedReference(test::ToDense(model.M), test::ToDense(model.C), test::ToDense(model.K), model.contacts,
                                     s.eq.N);
  ASSERT_EQ(all.size(), 4u);
  std::vector<std::complex<double>> ref(all.begin() + 2, all.end()); // omega > 0 members
  ExpectMatches(s.res, ref, 1e-8);
}

TEST(ThreeDof, SpringFrameGivesSameEigenvalues)
{
  // U in the springs' frame (x, y, n) with H = R_gamma^T: the general path, same physics.
  ThreeDofParams p;
  Model          a, b;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, a), 0);
  p.spring_frame = true;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, b), 0);
  Solved sa, sb;
  Solve(a, sa);
  Solve(b, sb);
  ASSERT_EQ(sa.res.modes.size(), sb.res.modes.size());
  for (size_t i = 0; i < sa.res.modes.size(); ++i) {
    EXPECT_NEAR(sa.res.modes[i].sigma, sb.res.modes[i].sigma, 1e-9 * sa.res.modes[i].omega);
    EXPECT_NEAR(sa.res.modes[i].omega, sb.res.modes[i].omega, 1e-9 * sa.res.modes[i].omega);
  }
  EXPECT_NEAR(sa.eq.N[0], sb.eq.N[0], 1e-9);
}

TEST(ThreeDof, TraceIdentity)
{
  // Sum of all 2(N - n_c) eigenvalues' real parts = -tr(M_r^{-1} C_r) = -(2c + mu N / V) / m.
  ThreeDofParams p;
  Model          model;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  Solved s;
  Solve(model, s);
  double sum = 0;
  for (const Mode &m : s.res.modes) sum += (m.omega > 0 ? 2 : 1) * m.sigma;
  EXPECT_NEAR(sum, -(2 * p.c + p.mu * s.eq.N[0] / p.V) / p.m, 1e-9);
}

TEST(ThreeDof, ModeNormalisedOnTangentialComponent)
{
  ThreeDofParams p;
  Model          model;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  Solved s;
  Solve(model, s);
  const Mode           &u  = s.res.modes[s.res.unstable[0]];
  const Eigen::VectorXd re = test::ToDense(u.phi_re), im = test::ToDense(u.phi_im);
  EXPECT_NEAR(re(0), 1.0, 1e-14); // phi_t = 1 exactly, as in the reference
  EXPECT_NEAR(im(0), 0.0, 1e-14);
  EXPECT_NEAR(re(2), 0.0, 1e-14); // closed contact: no normal motion
  EXPECT_NEAR(im(2), 0.0, 1e-14);
  // The mode solves the full QEP with the reaction eliminated: row b has no reaction term.
  PetscReal Kx[3][3], K[3][3];
  ThreeDofStiffness(p, Kx, K);
  const std::complex<double> l(u.sigma, u.omega);
  const std::complex<double> phi_t(re(0), im(0)), phi_b(re(1), im(1));
  const std::complex<double> row_b = (l * l * p.m + l * (p.c + p.mu * s.eq.N[0] / p.V)) * phi_b + K[1][0] * phi_t + K[1][1] * phi_b;
  EXPECT_LT(std::abs(row_b), 1e-8 * std::abs(l * l) * std::abs(phi_t));
}

TEST(ThreeDof, FileRoundTripGivesSameEigenvalues)
{
  for (const char *fmt : {"bin", "mtx"}) {
    ThreeDofParams p;
    Model          built, read;
    ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, built), 0);
    const std::string dir = testing::TempDir() + "squeal_roundtrip_" + fmt;
    ASSERT_EQ(built.Export(dir.c_str(), fmt), 0);
    FileModelSpec fs;
    fs.mass      = dir + "/M." + fmt;
    fs.damping   = dir + "/C." + fmt;
    fs.stiffness = dir + "/K." + fmt;
    fs.load      = dir + "/F.bin";
    fs.contacts  = dir + "/contacts.txt";
    fs.mu        = p.mu;
    fs.V         = p.V;
    ASSERT_EQ(BuildFromFiles(PETSC_COMM_WORLD, fs, read), 0);
    Solved a, b;
    Solve(built, a);
    Solve(read, b);
    ASSERT_EQ(a.res.modes.size(), b.res.modes.size());
    for (size_t i = 0; i < a.res.modes.size(); ++i) {
      EXPECT_NEAR(a.res.modes[i].sigma, b.res.modes[i].sigma, 1e-12 * a.res.modes[i].omega) << fmt;
      EXPECT_NEAR(a.res.modes[i].omega, b.res.modes[i].omega, 1e-12 * a.res.modes[i].omega) << fmt;
    }
  }
}

TEST(ThreeDof, StableBelowCriticalMu)
{
  ThreeDofParams p;
  p.mu = 0.14; // critical mu is 0.143068 at V = 3
  Model model;
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  Solved s;
  Solve(model, s);
  EXPECT_TRUE(s.res.unstable.empty());
  EXPECT_LT(s.res.MaxOscillatorySigma(), 0.0);
}
