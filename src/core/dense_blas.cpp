#include "squeal/core/dense_blas.h"

#include "squeal/core/blas_core.h"

#include <petscsys.h>
#include <petscblaslapack.h>

namespace squeal {

bool OptimizedBlas()
{
  static const bool openblas = BlasCoreName() != nullptr;
  return openblas;
}

namespace {

bool UseBlas(Eigen::Index cols, Eigen::Index min_cols, double work)
{
  // Small products stay in Eigen: there BLAS's call and packing cost more than they save, and the
  // 3-DOF and 4-cell models' results stay those of Eigen's kernels to the last bit.
  return cols >= min_cols && work >= 8192.0 && OptimizedBlas();
}

} // namespace

void Gemm(const Eigen::Ref<const Eigen::MatrixXd> &A, bool transpose_a, const Eigen::Ref<const Eigen::MatrixXd> &B, Eigen::Ref<Eigen::MatrixXd> C,
          double alpha, double beta, Eigen::Index min_cols)
{
  const Eigen::Index m = transpose_a ? A.cols() : A.rows(), k = transpose_a ? A.rows() : A.cols(), n = B.cols();
  eigen_assert(B.rows() == k && C.rows() == m && C.cols() == n);
  if (m == 0 || n == 0) return;
  if (!UseBlas(n, min_cols, (double)m * k * n) || k == 0) {
    if (beta == 0) C.setZero();
    else if (beta != 1) C *= beta;
    if (k == 0) return;
    if (transpose_a) C.noalias() += alpha * (A.transpose() * B);
    else C.noalias() += alpha * (A * B);
    return;
  }
  const PetscBLASInt bm = (PetscBLASInt)m, bn = (PetscBLASInt)n, bk = (PetscBLASInt)k;
  const PetscBLASInt lda = (PetscBLASInt)A.outerStride(), ldb = (PetscBLASInt)B.outerStride(), ldc = (PetscBLASInt)C.outerStride();
  BLASgemm_(transpose_a ? "T" : "N", "N", &bm, &bn, &bk, &alpha, A.data(), &lda, B.data(), &ldb, &beta, C.data(), &ldc);
}

extern "C" void sgemm_(const char *, const char *, const PetscBLASInt *, const PetscBLASInt *, const PetscBLASInt *, const float *, const float *,
                       const PetscBLASInt *, const float *, const PetscBLASInt *, const float *, float *, const PetscBLASInt *);

void GemmFloat(const Eigen::Ref<const Eigen::MatrixXf> &A, const Eigen::Ref<const Eigen::MatrixXf> &B, Eigen::Ref<Eigen::MatrixXf> C, bool transpose_a)
{
  const Eigen::Index m = transpose_a ? A.cols() : A.rows(), k = transpose_a ? A.rows() : A.cols(), n = B.cols();
  eigen_assert(B.rows() == k && C.rows() == m && C.cols() == n);
  if (m == 0 || n == 0) return;
  if (!UseBlas(n, 2, (double)m * k * n) || k == 0) {
    if (transpose_a) C.noalias() = A.transpose() * B;
    else C.noalias() = A * B;
    return;
  }
  const PetscBLASInt bm = (PetscBLASInt)m, bn = (PetscBLASInt)n, bk = (PetscBLASInt)k;
  const PetscBLASInt lda = (PetscBLASInt)A.outerStride(), ldb = (PetscBLASInt)B.outerStride(), ldc = (PetscBLASInt)C.outerStride();
  const float        one = 1, zero = 0;
  sgemm_(transpose_a ? "T" : "N", "N", &bm, &bn, &bk, &one, A.data(), &lda, B.data(), &ldb, &zero, C.data(), &ldc);
}

} // namespace squeal
