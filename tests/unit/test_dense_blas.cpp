// Dense products and LU solves through BLAS (core/dense_blas.h) against sums written out here.
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

TEST(DenseBlas, LuSolveSolvesThePermutedSystem)
{
  // A with small leading entries, so that partial pivoting permutes rows: A X = B to round-off,
  // for 1, 2 and 24 right-hand sides (one column stays in Eigen).
  std::srand(11);
  const Eigen::Index m = 90;
  Eigen::MatrixXd    A = Eigen::MatrixXd::Random(m, m);
  A.diagonal() *= 1e-3;
  const Eigen::PartialPivLU<Eigen::MatrixXd> lu(A);
  ASSERT_TRUE((lu.permutationP().indices().array() != Eigen::ArrayXi::LinSpaced(m, 0, (int)m - 1)).any());
  for (Eigen::Index n : {1, 2, 24}) {
    const Eigen::MatrixXd B = Eigen::MatrixXd::Random(m, n);
    Eigen::MatrixXd       X = B;
    LuSolveInPlace(lu, X);
    const double res = (A * X - B).norm() / (A.norm() * X.norm());
    EXPECT_LT(res, 1e-14) << n << " right-hand sides";
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
