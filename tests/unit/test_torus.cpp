// The invariant torus (issue 19 item 2) on a system whose torus is known in closed form: two
// Hopf normal forms with amplitude-dependent frequency (shear), and two damped coordinates, mixed
// by a fixed linear map. Every orbit tends to the torus r1 = r2 = 1 with frequencies
// omega1 / 2 pi and omega2 / 2 pi, and the flow is exact (no integrator):
//   r^2(t) = 1 / (1 + c e^{-2 lambda t}), c = 1 / r0^2 - 1,
//   phi(t) = phi0 + omega t + beta / (2 lambda) ln((1 + c e^{-2 lambda t}) / (1 + c)).
#include "squeal/torus/torus.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace squeal;

namespace {

struct TwoOscillators {
  double          w1, w2, lambda1 = 60, lambda2 = 40, beta1 = 80, beta2 = -50, sigma1 = 300, sigma2 = 150;
  Eigen::MatrixXd A, Ainv;

  TwoOscillators(double f1, double f2) : w1(2 * M_PI * f1), w2(2 * M_PI * f2)
  {
    A = Eigen::MatrixXd::Identity(6, 6);
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) A(i, j) += 0.3 * std::sin(1.7 * i + 2.3 * j + 0.5);
    Ainv = A.inverse();
  }
  static void Osc(double x, double y, double w, double lambda, double beta, double t, double &x1, double &y1)
  {
    const double r0 = std::hypot(x, y), c = 1 / (r0 * r0) - 1, E = std::exp(-2 * lambda * t);
    const double r   = 1 / std::sqrt(1 + c * E);
    const double phi = std::atan2(y, x) + w * t + beta / (2 * lambda) * std::log((1 + c * E) / (1 + c));
    x1 = r * std::cos(phi), y1 = r * std::sin(phi);
  }
  void Flow(const Eigen::VectorXd &z0, double t, Eigen::VectorXd &z1) const
  {
    const Eigen::VectorXd w = Ainv * z0;
    Eigen::VectorXd       v(6);
    Osc(w[0], w[1], w1, lambda1, beta1, t, v[0], v[1]);
    Osc(w[2], w[3], w2, lambda2, beta2, t, v[2], v[3]);
    v[4] = w[4] * std::exp(-sigma1 * t), v[5] = w[5] * std::exp(-sigma2 * t);
    z1   = A * v;
  }
};

// The torus from a stroboscopic sequence of a transient, at a start period 0.3 % off.
void SolveAndCheck(double f1, double f2, double rho_exact, bool precondition = false, PetscInt *krylov = nullptr)
{
  const TwoOscillators sys(f1, f2);
  TorusSolver          solver(PETSC_COMM_WORLD);
  solver.points = 9;
  solver.rtol   = 1e-10;
  ASSERT_EQ(solver.SetFromOptions(), 0);
  TorusSolver::FlowFn flow = [&](const Eigen::VectorXd &z0, PetscReal T, Eigen::VectorXd &z1) -> PetscErrorCode {
    sys.Flow(z0, T, z1);
    return 0;
  };
  const double    T0 = 1 / (f1 * 1.003);
  Eigen::VectorXd w(6), z, z1;
  w << 1.2, 0.3, -0.2, 0.6, 0.05, -0.04; // off the torus: the first periods are the start-up
  z = sys.A * w;
  sys.Flow(z, 20 / f1, z1);
  z = z1;
  const int       K = 120;
  Eigen::MatrixXd Y(6, K);
  for (int k = 0; k < K; ++k) {
    Y.col(k) = z;
    sys.Flow(z, T0, z1);
    z = z1;
  }
  const double rho0 = TorusSolver::EstimateRotation(Y);
  EXPECT_NEAR(std::min(rho0, 1 - rho0), std::min(rho_exact, 1 - rho_exact), 0.01);
  const Eigen::MatrixXd circle = TorusSolver::FitCircle(Y, rho0, solver.points);
  TorusResult           res;
  // The preconditioner's monodromy: central differences of the flow at one point of the start circle only.
  Eigen::MatrixXd mono(6, 6);
  for (int i = 0; i < 6; ++i) {
    Eigen::VectorXd zp = circle.col(0), zm = circle.col(0), fp, fm;
    zp[i] += 1e-6, zm[i] -= 1e-6;
    sys.Flow(zp, T0, fp), sys.Flow(zm, T0, fm);
    mono.col(i) = (fp - fm) / 2e-6;
  }
  ASSERT_EQ(solver.Solve(flow, Eigen::VectorXd::Ones(6), circle, T0, rho0, res, precondition ? &mono : nullptr), 0);
  if (krylov) *krylov = res.krylov_iterations;
  EXPECT_TRUE(res.converged) << res.reason;
  EXPECT_NEAR(res.T * f1, 1.0, 1e-9);
  const double rho = res.rho - std::floor(res.rho);
  EXPECT_NEAR(std::min(rho, 1 - rho), std::min(rho_exact, 1 - rho_exact), 1e-9);
  // Every point on the torus r1 = r2 = 1, the damped coordinates zero (the circle is kept on rank 0).
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank != 0) return;
  ASSERT_EQ((PetscInt)res.circle.size(), 6 * res.M);
  for (PetscInt j = 0; j < res.M; ++j) {
    const Eigen::VectorXd v = sys.Ainv * Eigen::Map<const Eigen::VectorXd>(res.circle.data() + 6 * j, 6);
    EXPECT_NEAR(std::hypot(v[0], v[1]), 1.0, 1e-8);
    EXPECT_NEAR(std::hypot(v[2], v[3]), 1.0, 1e-8);
    EXPECT_NEAR(v[4], 0.0, 1e-8);
    EXPECT_NEAR(v[5], 0.0, 1e-8);
  }
}

} // namespace

TEST(Torus, ShiftMatrixShiftsTrigonometricPolynomialsExactly)
{
  const PetscInt  M = 7;
  const double    rho = 0.2371;
  Eigen::VectorXd u(M), ushift(M), du(M);
  auto            p  = [](double a) { return 0.3 + std::cos(a) - 0.4 * std::sin(2 * a) + 0.25 * std::cos(3 * a + 0.1); };
  auto            dp = [](double a) { return -std::sin(a) - 0.8 * std::cos(2 * a) - 0.75 * std::sin(3 * a + 0.1); };
  for (PetscInt j = 0; j < M; ++j) {
    const double a = 2 * M_PI * j / M;
    u[j] = p(a), ushift[j] = p(a + 2 * M_PI * rho), du[j] = dp(a);
  }
  EXPECT_LT((TorusSolver::ShiftMatrix(M, rho) * u - ushift).norm(), 1e-13);
  EXPECT_LT((TorusSolver::DerivativeMatrix(M) * u - du).norm(), 1e-12);
}

TEST(Torus, FitCircleOfASampledTrigonometricCurve)
{
  const PetscInt  M = 5, K = 40;
  const double    rho = 0.1234;
  Eigen::MatrixXd z(2, K), expect(2, M);
  auto            c = [](double a, Eigen::Ref<Eigen::VectorXd> out) { out << 1 + std::cos(a), std::sin(a) - 0.2 * std::cos(2 * a); };
  for (PetscInt k = 0; k < K; ++k) c(2 * M_PI * rho * k, z.col(k));
  for (PetscInt j = 0; j < M; ++j) c(2 * M_PI * j / M, expect.col(j));
  EXPECT_LT((TorusSolver::FitCircle(z, rho, M) - expect).norm(), 1e-12);
}

// A slow modulation, as on the small pad at V = 10 m/s (220 Hz on 8662 Hz): rho = 0.0254.
TEST(Torus, InvariantCircleOfTwoOscillatorsWithSlowModulation)
{
  SolveAndCheck(100.0, 102.54, 0.0254);
}

// An irrational rotation far from 0: rho = (sqrt 5 - 1) / 2 - 1/2 + ... (f2 / f1 = 1.381966).
TEST(Torus, InvariantCircleOfTwoOscillatorsGoldenRotation)
{
  SolveAndCheck(100.0, 138.1966011250105, 0.381966011250105);
}

// The block-circulant preconditioner from a monodromy taken at a single point: the same torus.
TEST(Torus, PreconditionedByTheMonodromyAtOnePoint)
{
  PetscInt plain = 0, pre = 0;
  SolveAndCheck(100.0, 102.54, 0.0254, false, &plain);
  SolveAndCheck(100.0, 102.54, 0.0254, true, &pre);
  EXPECT_LT(pre, plain);
}
