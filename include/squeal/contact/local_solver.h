// The one-step contact problem on the local reactions (method.md §2, §5 (S6)-(S7)).
//
// Given the Delassus matrix W = H^T A^-1 H (3 n_c x 3 n_c, local (t, b, n) per point), the local
// free velocity w_f = H^T v_f and the modified gap at the start of the step g~^i_n, find r with
//   v = w_f + h W r,   g~_n = g~^i_n + h v_n,
//   r_n = max(0, r_n - rho_n g~_n),   r_T = proj_{D(mu r_n)}(r_T - rho_t s),   s = (v_t - V_c, v_b)
// (rectilinear: r_t clamped to [-mu r_n, mu r_n], r_b = 0), by block Gauss-Seidel passes over the
// points (v updated after each point; with one point this is the reference's Jacobi pass).
// Stop when sum_c ||r_c^(k+1) - r_c^(k)||_1 <= tol (R_ref + sum_c r_n,c).
// The problem is small and dense, so it is replicated on every rank: no communication, and every
// rank takes identical decisions. All storage is sized in Setup; Solve allocates nothing.
#pragma once

#include "squeal/contact/contact_set.h"

#include <Eigen/Core>

#include <vector>

namespace squeal {

enum ContactStatus : int { kOpen = 0, kStick = 1, kSlip = 2 };

struct LocalSolveInfo {
  PetscInt  iterations = 0;
  PetscReal residual   = 0; // last sum ||dr||_1 / (R_ref + sum r_n)
  bool      converged  = false;
};

class LocalContactSolver {
public:
  // W is 3n_c x 3n_c; rho_scale multiplies the rules (2.4) (1 = method.md).
  void Setup(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, PetscReal rho_scale);
  void SetTolerances(PetscReal tol, PetscInt max_it, PetscReal r_ref)
  {
    tol_    = tol;
    max_it_ = max_it;
    r_ref_  = r_ref;
  }
  // r holds the starting guess (the previous step's reaction) and returns the solution.
  LocalSolveInfo Solve(const Eigen::VectorXd &w_f, const Eigen::VectorXd &gap0, Eigen::VectorXd &r);
  // Local velocity at the end of the step for the last solution: v = w_f + h W r.
  const Eigen::VectorXd &Velocity() const { return v_; }
  // Status of each point for reaction r: open (r_n = 0), stick (|r_T| < mu r_n), slip.
  void Status(const Eigen::VectorXd &r, std::vector<int> &status) const;

  PetscReal RhoN(PetscInt c) const { return rho_n_[c]; }
  PetscReal RhoT(PetscInt c) const { return rho_t_[c]; }

private:
  const ContactSet      *cs_ = nullptr;
  Eigen::MatrixXd        hW_; // h W
  Eigen::VectorXd        v_, rho_n_, rho_t_, speed_;
  PetscReal              h_ = 0, tol_ = 1e-12, r_ref_ = 1.0;
  PetscInt               max_it_ = 500;
};

} // namespace squeal
