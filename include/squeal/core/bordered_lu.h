// The LU of a bordered matrix J = [A b; g^T d] whose border (b, g, d) changes while A does not:
// shooting's linear preconditioner (A = the sliding linearisation's monodromy - I, fixed for a
// Newton run; b the period column and g the phase row of the iterate). Factorised once, later
// borders are a rank-2 update of that factor (Sherman-Morrison-Woodbury): a solve then costs one
// solve with the first factor and O(n) more, instead of a new O(n^3) LU at every Newton iteration
// (0.4 s on the 1420-DOF pad's order 2841).
#pragma once

#include <Eigen/Dense>

namespace squeal {

class BorderedLU {
public:
  // Factorises J ((n + 1) x (n + 1), its last row and column the border); J is moved in.
  void Factor(Eigen::MatrixXd &&J);
  // The border of the matrix to solve with from now on: its last column and last row (n + 1
  // entries each, the corner d in both). False, and nothing changed, when the update's 2 x 2
  // capacitance matrix is too ill-conditioned to trust (the caller factorises the whole matrix).
  bool SetBorder(const Eigen::VectorXd &col, const Eigen::VectorXd &row);
  // y = J^-1 z for the present border (z may have several columns).
  void Solve(const Eigen::MatrixXd &z, Eigen::MatrixXd &y) const;
  bool Factored() const { return n_ > 0; }
  void Reset() { *this = BorderedLU(); }

private:
  Eigen::Index                         n_ = 0; // order of A
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;    // of J0, the matrix factorised
  Eigen::VectorXd                      col0_, row0_; // J0's border
  // J = J0 + U V^T, U = [e_n, c], V = [r, e_n] (c = col - col0 with c_n = 0, r = row - row0);
  // Z = J0^-1 U, Cinv = (I + V^T Z)^-1. Empty while J = J0.
  Eigen::MatrixXd                      Z_, V_;
  Eigen::Matrix2d                      Cinv_ = Eigen::Matrix2d::Identity();
};

} // namespace squeal
