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
  // near-singular C means the new border made J nearly singular where J0 was not, or the other way
  // round; the caller then factorises J itself. Measured by the cancellation in C's determinant,
  // which a scaling of C's rows or columns leaves alone: the border's column and row carry the
  // state's units, and C's off-diagonal entries then differ from its diagonal by 1e10 or more. Its
  // 1-norm condition number (refused below 1e-10 before) read 1e-21 on the size-1 brake's Newton
  // iterations, whose every border update was refused: 7 LUs of order 3 717, 4.5 s. A determinant
  // below 1e-6 of its terms (the update's error then above about 1e-10) is refused: the test's
  // singular J reads 3e-9 (J0 is ill-conditioned there, as shooting's is near a threshold).
  const double det = C.determinant(), terms = std::abs(C(0, 0) * C(1, 1)) + std::abs(C(0, 1) * C(1, 0));
  if (!(std::isfinite(det) && terms > 0 && std::abs(det) > 1e-6 * terms)) return false;
  Z_ = Z, V_ = V, Cinv_ = C.inverse();
  return true;
}

void BorderedLU::Solve(const Eigen::MatrixXd &z, Eigen::MatrixXd &y) const
{
  y = lu_.solve(z);
  if (Z_.cols() > 0) y.noalias() -= Z_ * (Cinv_ * (V_.transpose() * y));
}

} // namespace squeal
