// Dense products through BLAS (core/dense_blas.h) against sums written out here.
#include "squeal/core/bordered_lu.h"
#include "squeal/core/dense_blas.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <limits>

using namespace squeal;

namespace {

// C = alpha op(A) B + beta C as the textbook triple loop, in long double.
Eigen::MatrixXd Reference(const Eigen::MatrixXd &A, bool t, const Eigen::MatrixXd &B, const Eigen::MatrixXd &C0, double alpha, double beta)
{
  const Eigen::Index m = t ? A.cols() : A.rows(), k = t ? A.rows() : A.cols();
  Eigen::MatrixXd C(m, B.cols());
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < B.cols(); ++j) {
      long double s = 0;
      for (Eigen::Index l = 0; l < k; ++l) s += (long double)(t ? A(l, i) : A(i, l)) * B(l, j);
      C(i, j) = (double)(alpha * s + (long double)beta * C0(i, j));
    }
  return C;
}

} // namespace

TEST(DenseBlas, ProductsOfBlocksMatchTheSumsInEitherOrientation)
{
  // Operands that are blocks of larger matrices (an outer stride other than their rows), C
  // accumulated (beta = 1) and overwritten (beta = 0, C holding NaNs), the sizes of the Floquet
  // blocks (16 columns) and of the fallbacks to Eigen (one column; a product below 8192
  // multiply-adds).
  std::srand(7);
  std::printf("BLAS behind libblas.so.3: %s\n", OptimizedBlas() ? "OpenBLAS (products of two or more columns through it)" : "not OpenBLAS (Eigen throughout)");
  struct Case {
    Eigen::Index m, k, n;
  };
  for (const Case c : {Case{131, 97, 16}, Case{131, 97, 1}, Case{12, 9, 5}, Case{40, 300, 3}})
    for (bool t : {false, true})
      for (double beta : {0.0, 1.0}) {
        const Eigen::MatrixXd Abig = Eigen::MatrixXd::Random(t ? c.k + 3 : c.m + 3, t ? c.m + 2 : c.k + 2);
        const Eigen::MatrixXd A    = t ? Abig.block(1, 1, c.k, c.m) : Abig.block(1, 1, c.m, c.k);
        const Eigen::MatrixXd Bbig = Eigen::MatrixXd::Random(c.k + 5, c.n + 1);
        Eigen::MatrixXd       Cbig = Eigen::MatrixXd::Random(c.m + 4, c.n + 2);
        const Eigen::MatrixXd C0   = Cbig.block(2, 1, c.m, c.n);
        if (beta == 0) Cbig.block(2, 1, c.m, c.n).setConstant(std::numeric_limits<double>::quiet_NaN());
        Eigen::MatrixXd around = Cbig;
        const Eigen::MatrixXd ref = Reference(A, t, Bbig.block(3, 0, c.k, c.n), C0, -0.75, beta);
        Gemm(t ? Abig.block(1, 1, c.k, c.m) : Abig.block(1, 1, c.m, c.k), t, Bbig.block(3, 0, c.k, c.n), Cbig.block(2, 1, c.m, c.n), -0.75, beta);
        const double err = (Cbig.block(2, 1, c.m, c.n) - ref).norm() / ref.norm();
        EXPECT_LT(err, 1e-13) << c.m << " x " << c.k << " x " << c.n << (t ? " transposed" : "") << ", beta " << beta;
        // Nothing outside C's block was written.
        Eigen::MatrixXd after = Cbig;
        around.block(2, 1, c.m, c.n).setZero(), after.block(2, 1, c.m, c.n).setZero();
        EXPECT_TRUE(after == around);
      }
}

TEST(DenseBlas, FloatProductsMatchTheSumsInEitherOrientation)
{
  // GemmFloat: op(A) B on blocks of larger float matrices, C overwritten (it holds NaNs), against
  // the long-double sums of the same float operands: float's round-off of sums of k terms.
  std::srand(5);
  struct Case {
    Eigen::Index m, k, n;
  };
  for (const Case c : {Case{131, 97, 16}, Case{131, 97, 1}, Case{12, 9, 5}, Case{525, 562, 4}})
    for (bool t : {false, true}) {
      const Eigen::MatrixXf Abig = Eigen::MatrixXf::Random(t ? c.k + 3 : c.m + 3, t ? c.m + 2 : c.k + 2);
      const Eigen::MatrixXf Bbig = Eigen::MatrixXf::Random(c.k + 5, c.n + 1);
      Eigen::MatrixXf       Cbig = Eigen::MatrixXf::Random(c.m + 4, c.n + 2);
      Cbig.block(2, 1, c.m, c.n).setConstant(std::numeric_limits<float>::quiet_NaN());
      Eigen::MatrixXf around = Cbig;
      const auto      A      = t ? Abig.block(1, 1, c.k, c.m) : Abig.block(1, 1, c.m, c.k);
      const Eigen::MatrixXd ref = Reference(A.cast<double>(), t, Bbig.block(3, 0, c.k, c.n).cast<double>(), Eigen::MatrixXd::Zero(c.m, c.n), 1.0, 0.0);
      GemmFloat(A, Bbig.block(3, 0, c.k, c.n), Cbig.block(2, 1, c.m, c.n), t);
      const double err = (Cbig.block(2, 1, c.m, c.n).cast<double>() - ref).norm() / ref.norm();
      EXPECT_LT(err, 1e-6) << c.m << " x " << c.k << " x " << c.n << (t ? " transposed" : "");
      Eigen::MatrixXf after = Cbig;
      around.block(2, 1, c.m, c.n).setZero(), after.block(2, 1, c.m, c.n).setZero();
      EXPECT_TRUE(after == around);
    }
}

// The bordered LU (core/bordered_lu.h): after the factor of one bordered matrix, solves with other
// borders (a rank-2 update) against Eigen's LU of each whole matrix, on an A like shooting's
// (a contraction minus I, one eigenvalue of the contraction near 1 so that A alone is ill-
// conditioned and the border regularises it). A border that makes J singular is refused.
TEST(BorderedLU, BorderUpdatesSolveAsTheWholeMatrixsLU)
{
  const Eigen::Index n = 60;
  std::srand(7);
  Eigen::MatrixXd Q = Eigen::MatrixXd::Random(n, n).householderQr().householderQ();
  Eigen::VectorXd lam = Eigen::VectorXd::LinSpaced(n, 0.1, 0.9);
  lam[0]              = 1 - 1e-6; // the weakly damped mode
  const Eigen::MatrixXd A = Q * lam.asDiagonal() * Q.transpose() - Eigen::MatrixXd::Identity(n, n);
  const auto bordered = [&](const Eigen::VectorXd &col, const Eigen::VectorXd &row) {
    Eigen::MatrixXd J(n + 1, n + 1);
    J.topLeftCorner(n, n) = A, J.col(n) = col, J.row(n) = row.transpose();
    return J;
  };
  Eigen::VectorXd col = Eigen::VectorXd::Zero(n + 1), row = Eigen::VectorXd::Zero(n + 1);
  col.head(n) = Q.col(0) + 0.1 * Eigen::VectorXd::Random(n); // nearly A's null direction, as dZ/dT is
  row.head(n) = Q.col(0) + 0.1 * Eigen::VectorXd::Random(n); // the phase row, corner 0
  BorderedLU lu;
  EXPECT_FALSE(lu.Factored());
  lu.Factor(bordered(col, row));
  ASSERT_TRUE(lu.Factored());
  const Eigen::MatrixXd z = Eigen::MatrixXd::Random(n + 1, 3);
  Eigen::MatrixXd       y;
  for (int k = 0; k < 5; ++k) {
    if (k > 0) {
      col.head(n) += 0.3 * Eigen::VectorXd::Random(n);
      row.head(n) = Q.col(0) + 0.2 * k * Eigen::VectorXd::Random(n);
      ASSERT_TRUE(lu.SetBorder(col, row)) << "border " << k;
    }
    const Eigen::MatrixXd J   = bordered(col, row);
    const Eigen::MatrixXd ref = J.partialPivLu().solve(z);
    lu.Solve(z, y);
    EXPECT_LT((y - ref).norm(), 1e-13 * ref.norm()) << "border " << k;
    EXPECT_LT((J * y - z).norm(), 1e-15 * (J.norm() * y.norm())) << "border " << k;
  }
  // A column and a row in other units (the state's: 1e6 and 1e-4 here), as shooting's period
  // column and phase row are: the same update, to the whole LU's accuracy.
  for (int k = 0; k < 3; ++k) {
    Eigen::VectorXd c2 = col, r2 = row;
    c2.head(n) = 1e6 * (col.head(n) + 0.2 * Eigen::VectorXd::Random(n));
    r2.head(n) = 1e-4 * (row.head(n) + 0.2 * Eigen::VectorXd::Random(n));
    ASSERT_TRUE(lu.SetBorder(c2, r2)) << "scaled border " << k;
    const Eigen::MatrixXd J   = bordered(c2, r2);
    const Eigen::MatrixXd ref = J.partialPivLu().solve(z);
    lu.Solve(z, y);
    EXPECT_LT((y - ref).norm(), 1e-10 * ref.norm()) << "scaled border " << k;
  }
  // The last row a combination of the rows above: J singular, the update refused.
  Eigen::VectorXd bad(n + 1);
  bad.head(n) = A.row(3).transpose() + A.row(5).transpose();
  bad[n]      = col[3] + col[5];
  col[n]      = bad[n];
  EXPECT_FALSE(lu.SetBorder(col, bad));
}
