// Dense matrix-matrix products through the BLAS behind libblas.so.3 where that is
// OpenBLAS, whose kernels are chosen at run time for the CPU (core/blas_core.cpp). Measured on the
// 1353 x 1420 H^T Phi of the reduced large pad times 16 columns (a Floquet block's product): Eigen
// 22.9 GF/s with AVX2 and FMA (SQUEAL_HOST_SIMD), 6.5 GF/s without, OpenBLAS 29.8 GF/s either way.
// One column stays in Eigen: there Eigen's matrix-vector product was 2.6 times as fast. Without
// OpenBLAS (the reference BLAS) everything stays in Eigen.
#pragma once

#include <Eigen/Dense>

namespace squeal {

// True when OpenBLAS stands behind libblas.so.3 (then the products below go to it).
bool OptimizedBlas();

// C = alpha op(A) B + beta C with op(A) = A or A^T; C has its size already (beta = 0: any content).
// Through BLAS when OptimizedBlas() and B has at least min_cols columns, else through Eigen.
void Gemm(const Eigen::Ref<const Eigen::MatrixXd> &A, bool transpose_a, const Eigen::Ref<const Eigen::MatrixXd> &B, Eigen::Ref<Eigen::MatrixXd> C,
          double alpha = 1.0, double beta = 0.0, Eigen::Index min_cols = 2);

// C = op(A) B in single precision (sgemm where OptimizedBlas(), else Eigen): half dgemm's time on
// the same sizes (order 3 716: 1.65 s against 3.51 s), for products that need no more than float's
// 1e-7 (a preconditioner's, a step tangent's).
void GemmFloat(const Eigen::Ref<const Eigen::MatrixXf> &A, const Eigen::Ref<const Eigen::MatrixXf> &B, Eigen::Ref<Eigen::MatrixXf> C,
               bool transpose_a = false);

} // namespace squeal
