// Test helpers: dense copies of distributed PETSc objects, and an independent dense reference
// for the linearised stability problem that shares no code with the library's reduction.
#pragma once

#include "squeal/integration/theta.h"
#include "squeal/model/model.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <petscmat.h>

#include <algorithm>
#include <complex>
#include <vector>

namespace squeal::test {

// One integrator with its state (U, dU) and reactions r, for tests that step several side by side.
struct Integration {
  ThetaIntegrator ti{PETSC_COMM_WORLD};
  Vec             U = nullptr, dU = nullptr;
  Eigen::VectorXd r;
  ~Integration()
  {
    VecDestroy(&U);
    VecDestroy(&dU);
  }
};

// C = diag(c_i), c_i varying: a damping that (K, M)'s modes do not diagonalise where K couples the
// cells (a chain's), so modal steps and tangents need the dense G = A_m^-1.
inline PetscErrorCode NonProportionalDamping(Model &model)
{
  Vec      d;
  PetscInt lo, hi;
  PetscFunctionBeginUser;
  PetscCall(MatCreateVecs(model.C, &d, nullptr));
  PetscCall(VecGetOwnershipRange(d, &lo, &hi));
  for (PetscInt i = lo; i < hi; ++i) PetscCall(VecSetValue(d, i, 20.0 * (1.0 + 0.05 * (double)i), INSERT_VALUES));
  PetscCall(VecAssemblyBegin(d));
  PetscCall(VecAssemblyEnd(d));
  PetscCall(MatDiagonalSet(model.C, d, INSERT_VALUES));
  PetscCall(VecDestroy(&d));
  PetscFunctionReturn(0);
}

// Full copy of A on every rank.
inline Eigen::MatrixXd ToDense(Mat A)
{
  PetscInt m, n;
  PetscCallAbort(PETSC_COMM_SELF, MatGetSize(A, &m, &n));
  IS   rows, cols;
  Mat *sub;
  PetscCallAbort(PETSC_COMM_SELF, ISCreateStride(PETSC_COMM_SELF, m, 0, 1, &rows));
  PetscCallAbort(PETSC_COMM_SELF, ISCreateStride(PETSC_COMM_SELF, n, 0, 1, &cols));
  PetscCallAbort(PETSC_COMM_SELF, MatCreateSubMatrices(A, 1, &rows, &cols, MAT_INITIAL_MATRIX, &sub));
  Eigen::MatrixXd D = Eigen::MatrixXd::Zero(m, n);
  for (PetscInt i = 0; i < m; ++i) {
    PetscInt           nc;
    const PetscInt    *cj;
    const PetscScalar *v;
    PetscCallAbort(PETSC_COMM_SELF, MatGetRow(sub[0], i, &nc, &cj, &v));
    for (PetscInt k = 0; k < nc; ++k) D(i, cj[k]) = PetscRealPart(v[k]);
    PetscCallAbort(PETSC_COMM_SELF, MatRestoreRow(sub[0], i, &nc, &cj, &v));
  }
  PetscCallAbort(PETSC_COMM_SELF, MatDestroySubMatrices(1, &sub));
  PetscCallAbort(PETSC_COMM_SELF, ISDestroy(&rows));
  PetscCallAbort(PETSC_COMM_SELF, ISDestroy(&cols));
  return D;
}

inline Eigen::VectorXd ToDense(Vec v)
{
  VecScatter sc;
  Vec        all;
  PetscCallAbort(PETSC_COMM_SELF, VecScatterCreateToAll(v, &sc, &all));
  PetscCallAbort(PETSC_COMM_SELF, VecScatterBegin(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscCallAbort(PETSC_COMM_SELF, VecScatterEnd(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscInt           n;
  const PetscScalar *a;
  PetscCallAbort(PETSC_COMM_SELF, VecGetSize(all, &n));
  PetscCallAbort(PETSC_COMM_SELF, VecGetArrayRead(all, &a));
  Eigen::VectorXd d(n);
  for (PetscInt i = 0; i < n; ++i) d(i) = PetscRealPart(a[i]);
  PetscCallAbort(PETSC_COMM_SELF, VecRestoreArrayRead(all, &a));
  PetscCallAbort(PETSC_COMM_SELF, VecDestroy(&all));
  PetscCallAbort(PETSC_COMM_SELF, VecScatterDestroy(&sc));
  return d;
}

// Dense H_dir (N x n_c) straight from the contact table.
inline Eigen::MatrixXd DenseColumns(const ContactSet &cs, PetscInt N, int dir)
{
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(N, cs.Size());
  for (PetscInt c = 0; c < cs.Size(); ++c)
    cs.ForEachEntry(c, dir, [&](PetscInt j, PetscReal v) { H(j, c) += v; });
  return H;
}

// Finite eigenvalues of the bordered QEP (4.4), by QZ on its 2(N + n_c) companion pencil:
//   lambda^2 [M 0; 0 0] + lambda [C + D_b 0; 0 0] + [K -B_mu; H_n^T 0]
// with every point closed and steady-sliding reactions N (given). Sorted by imag part.
inline std::vector<std::complex<double>> BorderedReference(const Eigen::MatrixXd &M, const Eigen::MatrixXd &C,
                                                           const Eigen::MatrixXd &K, const ContactSet &cs,
                                                           const std::vector<double> &N)
{
  const Eigen::Index n = M.rows(), nc = cs.Size(), s = n + nc;
  const Eigen::MatrixXd Ht = DenseColumns(cs, n, kT), Hb = DenseColumns(cs, n, kB), Hn = DenseColumns(cs, n, kN);
  Eigen::MatrixXd Db = Eigen::MatrixXd::Zero(n, n);
  if (cs.law == FrictionLaw::Planar)
    for (Eigen::Index c = 0; c < nc; ++c) Db += cs.Mu() * N[c] / cs.Speed(c) * Hb.col(c) * Hb.col(c).transpose();
  Eigen::MatrixXd M2 = Eigen::MatrixXd::Zero(s, s), C2 = M2, K2 = M2;
  M2.topLeftCorner(n, n)   = M;
  C2.topLeftCorner(n, n)   = C + Db;
  K2.topLeftCorner(n, n)   = K;
  K2.topRightCorner(n, nc) = -(Hn + cs.Mu() * Ht);
  K2.bottomLeftCorner(nc, n) = Hn.transpose();
  // [0 I; -K2 -C2] z = lambda [I 0; 0 M2] z
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(2 * s, 2 * s), B = A;
  A.topRightCorner(s, s)    = Eigen::MatrixXd::Identity(s, s);
  A.bottomLeftCorner(s, s)  = -K2;
  A.bottomRightCorner(s, s) = -C2;
  B.topLeftCorner(s, s)     = Eigen::MatrixXd::Identity(s, s);
  B.bottomRightCorner(s, s) = M2;
  Eigen::GeneralizedEigenSolver<Eigen::MatrixXd> qz(A, B);
  std::vector<std::complex<double>> out;
  const auto alpha = qz.alphas();
  const auto beta  = qz.betas();
  for (Eigen::Index i = 0; i < alpha.size(); ++i) {
    if (std::abs(beta(i)) < 1e-10 * std::abs(alpha(i))) continue; // infinite
    const std::complex<double> l = alpha(i) / beta(i);
    if (std::abs(l) > 1e8) continue;
    out.push_back(l);
  }
  std::sort(out.begin(), out.end(), [](auto a, auto b) { return a.imag() != b.imag() ? a.imag() < b.imag() : a.real() < b.real(); });
  return out;
}

} // namespace squeal::test
