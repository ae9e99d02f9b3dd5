// The steps of the Craig-Bampton reduction (include/squeal/reduction/craig_bampton.h) and the
// data they hand on, shared by its source files: craig_bampton.cpp (options, partition,
// factorisation, fixed-interface modes, projection, assembly), constraint_modes.cpp and
// interface_reduction.cpp. Not installed.
#pragma once

#include "squeal/core/handle.h"
#include "squeal/model/model.h"
#include "squeal/reduction/craig_bampton.h"

#include <Eigen/Dense>

#include <vector>

namespace squeal::cb {

using Dense = Eigen::Matrix<PetscReal, Eigen::Dynamic, Eigen::Dynamic>;

// The interface B (every translational DOF of every contact node, in contact order) and the
// interior I (the rest) of the full model.
struct Partition {
  PetscInt              N = 0, nB = 0, nI = 0;
  std::vector<PetscInt> where;   // full DOF -> position in the interface (contact order); -1: interior
  std::vector<PetscInt> Bsorted; // the interface DOFs, ascending
  Handle<IS>            isI, isB; // this rank's interior and interface rows
};

// The interior blocks and the one factorisation of K_II that the eigensolver (shift-and-invert
// at 0) and the constraint modes share.
struct Interior {
  MatH     Kii, Kib, Mii;
  EPSH     eps;
  EPSH     slice; // the modes by spectrum slicing, when many (CraigBampton::SliceModes); else eps holds them
  MatH     modes; // the modes by block Lanczos (BlockLanczosModes), n_I x nev, in lam's order; else slice or eps holds them
  Mat      Fct       = nullptr; // owned by the ST's PC
  bool     redundant = false;   // a sequential factor of the whole K_II on every rank
  PetscInt nev       = 0;       // modes asked of the eigensolver
  PetscInt ncv = PETSC_DEFAULT, mpd = PETSC_DEFAULT; // -<prefix>eps_ncv / _mpd as given (SetDimensions keeps them)
};

// W = [Psi Phi] (interior rows, N_I x (nB + m)) and the sizes and orders of the reduced model.
struct Basis {
  MatH                   W;
  PetscInt               nB = 0, m = 0, n2 = 0;
  std::vector<PetscReal> omega2; // Phi^T K_II Phi (rad^2/s^2), the m kept eigenvalues
  std::vector<PetscInt>  perm;   // reduced position (contact order) of each sorted position [Bsorted, modes]
};

// Psi = -K_II^{-1} K_IB into the first nB columns of W, in blocks of `block` right-hand sides
// (<= 0: one solve) with an interrupt poll between blocks; fails on a singular K_II.
PetscErrorCode ConstraintModes(MPI_Comm comm, Mat F, Mat Kib, bool redundant, PetscBool sparse_rhs, PetscInt block, Mat W);

// What BlockLanczosModes did, summed over its calls: the block size, the bases' columns, the block
// solves, the checks of the Ritz values (and of them, those with the residual estimates); the
// largest relative residual estimate of the last call's modes, and whether it converged them.
struct LanczosInfo {
  PetscInt  block = 0, columns = 0, block_solves = 0, checks = 0, full_checks = 0;
  PetscReal residual = 0;
  bool      converged = false;
};

// The nev modes of (K_II, M_II) in [lo, hi] (counted beforehand), by block shift-and-invert
// Lanczos at sigma (lo <= sigma < hi; F the factor of K_II - sigma M_II) with blocks of b columns
// and at most max_cols columns (8 n_I bytes each), to relative residual estimates below tol, on
// one rank. When info.converged: their eigenvalues appended to lam, their M_II-orthonormal vectors
// written to X(:, x0 : x0 + nev); else the caller takes another route.
PetscErrorCode BlockLanczosModes(Mat F, Mat Mii, PetscReal sigma, PetscReal lo, PetscReal hi, PetscInt nev, PetscInt b, PetscInt max_cols,
                                 PetscReal tol, std::vector<PetscReal> &lam, Mat X, PetscInt x0, LanczosInfo &info);

// Interface reduction of the Craig-Bampton matrices Mp, Kp (contact order): T (n2 x (n_c + k + m))
// maps [u_n, xi, eta] to the CB coordinates, k from k_max (< 0: no count limit) and fmax (Hz; <= 0:
// none), plus the interface's static response to each contact normal where statics is 1 (-1: for
// two-body points only; 0: never); contacts receives the reduced contact set, info the counts and
// the frequencies of the interface basis.
PetscErrorCode InterfaceReduction(MPI_Comm comm, const ContactSet &full, const Dense &Mp, const Dense &Kp, PetscInt k_max,
                                  PetscReal fmax, PetscInt statics, const char *prefix, PetscInt m, Dense &T, ContactSet &contacts,
                                  ReductionInfo &info);

} // namespace squeal::cb
