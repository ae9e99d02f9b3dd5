#include "squeal/core/bordered_lu.h"

#include <cmath>

namespace squeal {

void BorderedLU::Factor(Eigen::MatrixXd &&J)
{
  eigen_assert(J.rows() == J.cols() && J.rows() >= 2);
  n_    = J.rows() - 1;
  col0_ = J.col(n_);
  row0_ = J.row(n_).transpose();
  lu_.compute(J);
  J.resize(0, 0);
  Z_.resize(0, 0), V_.resize(0, 0);
}

bool BorderedLU::SetBorder(const Eigen::VectorXd &col, const Eigen::VectorXd &row)
{
  eigen_assert(Factored() && col.size() == n_ + 1 && row.size() == n_ + 1 && col[n_] == row[n_]);
  Eigen::MatrixXd U = Eigen::MatrixXd::Zero(n_ + 1, 2), V = Eigen::MatrixXd::Zero(n_ + 1, 2);
  U(n_, 0)          = 1;
  U.col(1).head(n_) = col.head(n_) - col0_.head(n_);
  V.col(0)          = row - row0_;
  V(n_, 1)          = 1;
  if (U.col(1).isZero(0) && V.col(0).isZero(0)) {
    Z_.resize(0, 0), V_.resize(0, 0);
    return true;
  }
  const Eigen::MatrixXd Z = lu_.solve(U);
  const Eigen::Matrix2d C = Eigen::Matrix2d::Identity() + V.transpose() * Z;
  // The update is only as good as C is invertible: J and J0 both regular make it so, and a
  // near-singular C (rcond below 1e-10, by the 1-norm) means the new border made J nearly singular
  // where J0 was not, or the other way round; the caller then factorises J itself.
  const double det = C.determinant(), n1 = C.cwiseAbs().colwise().sum().maxCoeff();
  const double inv1 = (det != 0 ? (C.inverse().cwiseAbs().colwise().sum().maxCoeff()) : INFINITY);
  if (!(std::isfinite(inv1) && 1 / (n1 * inv1) > 1e-10)) return false;
  Z_ = Z, V_ = V, Cinv_ = C.inverse();
  return true;
}

void BorderedLU::Solve(const Eigen::MatrixXd &z, Eigen::MatrixXd &y) const
{
  y = lu_.solve(z);
  if (Z_.cols() > 0) y.noalias() -= Z_ * (Cinv_ * (V_.transpose() * y));
}

} // namespace squeal
