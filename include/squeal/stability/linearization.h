// Linearisation of steady sliding and its reduction to a regular QEP (docs/method.md §4.1-4.2).
//
// About the equilibrium (U_e, N), with the closed points held closed (H_n^T u = 0):
//     M u'' + (C + D_b) u' + K u = B_mu nu,      D_b = H_b diag(mu N_c / V_c) H_b^T (planar; 0 rectilinear)
// Eliminating nu with u = Q xi and the left annihilator L = Q^T (I - mu H_t D^{-1} H_n^T),
// D = H_n^T H_n, gives the regular QEP
//     (lambda^2 M_r + lambda C_r + K_r) xi = 0,   M_r = L M Q, C_r = L (C + D_b) Q, K_r = L K Q.   (4.5)
// Q eliminates, for each closed point, its pivot DOF (largest |n| component) in favour of the
// point's other DOFs: Q is sparse, exactly the deletion of the normal DOF for nodal contact in
// local frames (the 3-DOF case gives M_r = m I_2 as in docs/method.md), and valid for any frame.
// Released points carry no reaction and are not constrained.
#pragma once

#include "squeal/core/handle.h"
#include "squeal/model/model.h"
#include "squeal/stability/equilibrium.h"

#include <vector>

namespace squeal {

struct ReducedProblem {
  MatH                  Q;          // N x n_r, lifts xi to u
  MatH                  L;          // n_r x N
  MatH                  Mr, Cr, Kr; // n_r x n_r
  std::vector<PetscInt> active;     // closed points the reduction enforces
  PetscInt              n_r = 0;
};

PetscErrorCode BuildReducedProblem(const Model &model, const SlidingEquilibrium &eq, ReducedProblem &rp);

} // namespace squeal
