#include "squeal/model/expansion.h"

#include <Eigen/Dense>

namespace squeal {

namespace {
using ColMajor = Eigen::Matrix<PetscReal, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor>;
using RowMajor = Eigen::Matrix<PetscReal, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
} // namespace

void Expansion::Apply(const PetscReal *Q, size_t count, std::vector<PetscReal> &U) const
{
  U.assign(count * (size_t)full_size, 0.0);
  if (!count || E.empty()) return;
  // Q row-major (count x n) is Q^T column-major (n x count); U row-major (count x full_size) is
  // U^T column-major (full_size x count) = E Q^T: one GEMM, no transposed copies.
  const Eigen::Map<const ColMajor> e(E.data(), full_size, n), qt(Q, n, (Eigen::Index)count);
  Eigen::Map<ColMajor>             ut(U.data(), full_size, (Eigen::Index)count);
  ut.noalias() = e * qt;
}

void Expansion::ApplyColumns(const PetscReal *Q, size_t columns, std::vector<PetscReal> &U) const
{
  U.assign(columns * (size_t)full_size, 0.0);
  if (!columns || E.empty()) return;
  const Eigen::Map<const ColMajor> e(E.data(), full_size, n);
  const Eigen::Map<const RowMajor> q(Q, n, (Eigen::Index)columns);
  Eigen::Map<RowMajor>             u(U.data(), full_size, (Eigen::Index)columns);
  u.noalias() = e * q;
}

} // namespace squeal
