// The dense theta step (S4)-(S9) of ThetaIntegrator (docs/method.md §5), written once as a template on
// the sizes N (DOFs) and NC (contact points). Eigen::Dynamic gives the general kernel, used for any
// model; a few small sizes are also instantiated with compile-time dimensions (FixedSizes below),
// because on 3 x 3 data Eigen's run-time-sized products and vector expressions cost several times
// the instructions of fixed-size ones (benchmarks/bench_step.cpp). Same equations, same order of
// operations per row: the instantiations differ by round-off only.
// The kernel maps the integrator's matrices (no copies but h Y); ThetaIntegrator remakes it in SetUp.
#pragma once

#include "squeal/contact/local_solver.h"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <memory>

namespace squeal {

using SparseRowMatrix = Eigen::SparseMatrix<PetscReal, Eigen::RowMajor>;

// What a dense step reads, owned by ThetaIntegrator and valid until its next SetUp.
struct DenseStepData {
  const Eigen::MatrixXd *P1, *P2, *Y, *Ht; // A^-1 B, -h A^-1 K, A^-1 H, H^T
  // H^T with its non-zeros only, or null: the run-time-sized kernel then reads it for (S5) and the
  // gaps. With the contact DOFs kept physical (Craig-Bampton) a row of H^T has a few non-zeros of N.
  const SparseRowMatrix *Hts;
  const Eigen::VectorXd *p3, *g0;          // h A^-1 F, gaps at U = 0
  PetscReal              h, theta;
  LocalContactSolver    *local;
};

// (S5)'s gaps g~_n = H_n^T dU0 + g0 from H^T's normal rows: by their non-zeros (Hts) or dense (Ht).
// Shared by the nodal and the modal kernels, so that both sum in the same order.
template <class MatH, class VecU, class VecG0, class VecG>
EIGEN_ALWAYS_INLINE void NormalGaps(const SparseRowMatrix *Hts, const MatH &Ht, const VecU &dU0, const VecG0 &g0, VecG &gap)
{
  if (Hts)
    for (Eigen::Index c = 0; c < gap.size(); ++c) {
      PetscReal g = 0;
      for (SparseRowMatrix::InnerIterator it(*Hts, 3 * c + kN); it; ++it) g += it.value() * dU0[it.index()];
      gap[c] = g + g0[c];
    }
  else
    for (Eigen::Index c = 0; c < gap.size(); ++c) gap[c] = Ht.row(3 * c + kN).dot(dU0) + g0[c];
}

class DenseStepKernel {
public:
  virtual ~DenseStepKernel() = default;
  // One step in place on the N values of U and dU; r: 3 n_c reactions (warm start in, result out);
  // info is written only when there are contacts.
  virtual void Step(PetscReal *U, PetscReal *dU, Eigen::VectorXd &r, LocalSolveInfo *info) = 0;
  virtual bool FixedSize() const = 0;
};

template <int N, int NC>
class DenseStepKernelT final : public DenseStepKernel {
  static constexpr int M = NC == Eigen::Dynamic ? Eigen::Dynamic : 3 * NC;
  using VecN             = Eigen::Matrix<PetscReal, N, 1>;
  using VecM             = Eigen::Matrix<PetscReal, M, 1>;
  using VecC             = Eigen::Matrix<PetscReal, NC, 1>;
  template <int R, int C>
  using CMap = Eigen::Map<const Eigen::Matrix<PetscReal, R, C>>;

public:
  explicit DenseStepKernelT(const DenseStepData &d)
    : n_(d.P1->rows()), nc_(d.g0->size()), h_(d.h), t_(d.theta), P1_(d.P1->data(), n_, n_), P2_(d.P2->data(), n_, n_),
      hY_(d.h * *d.Y), Ht_(d.Ht->data(), 3 * nc_, n_), Hts_(N == Eigen::Dynamic ? d.Hts : nullptr), p3_(d.p3->data(), n_),
      g0_(d.g0->data(), nc_), local_(d.local)
  {
    vf_.resize(n_), dU0_.resize(n_), wf_.resize(3 * nc_), gap_.resize(nc_);
  }

  void Step(PetscReal *u, PetscReal *du, Eigen::VectorXd &r, LocalSolveInfo *info) override
  {
    const PetscReal  h = h_, t = t_;
    Eigen::Map<VecN> U(u, n_), dU(du, n_);
    // Fixed sizes: work vectors on the stack (registers); run-time sizes: the members sized once.
    VecN  vf_l, dU0_l;
    VecM  wf_l;
    VecC  gap_l;
    VecN &vf = Pick(vf_l, vf_), &dU0 = Pick(dU0_l, dU0_);
    VecM &wf = Pick(wf_l, wf_);
    VecC &gap = Pick(gap_l, gap_);
    vf.noalias() = P1_ * dU; // (S4)
    vf.noalias() += P2_ * U;
    vf += p3_;
    if (nc_ > 0) {
      Eigen::Map<VecM> R(r.data(), 3 * nc_);
      dU0        = U + h * (1 - t) * dU;
      bool local = false;
      if constexpr (N == Eigen::Dynamic) {
        if (Hts_) {
          wf.noalias() = *Hts_ * vf; // (S5)
          NormalGaps(Hts_, Ht_, dU0, g0_, gap);
          local = true;
        }
      }
      if (!local) {
        wf.noalias() = Ht_ * vf; // (S5)
        NormalGaps(nullptr, Ht_, dU0, g0_, gap);
      }
      *info = local_->SolveSized<NC>(wf, gap, R); // (S6)-(S7)
      dU0   = dU;
      dU    = vf;
      dU.noalias() += hY_ * R; // (S8)
    } else {
      dU0 = dU;
      dU  = vf;
    }
    U += h * (t * dU + (1 - t) * dU0); // (S9)
  }
  bool FixedSize() const override { return N != Eigen::Dynamic; }

private:
  template <class V>
  static V &Pick(V &local, V &member)
  {
    if constexpr (V::SizeAtCompileTime == Eigen::Dynamic) return member;
    else return local;
  }

  const Eigen::Index  n_, nc_;
  const PetscReal     h_, t_;
  const CMap<N, N>    P1_, P2_;
  const Eigen::Matrix<PetscReal, N, M> hY_; // h Y: Eigen's fixed-size h (Y R) multiplied Y by h at every step
  const CMap<M, N>    Ht_;
  const SparseRowMatrix *Hts_; // run-time sizes only
  const CMap<N, 1>    p3_;
  const CMap<NC, 1>   g0_;
  LocalContactSolver *local_;
  VecN                vf_, dU0_;
  VecM                wf_;
  VecC                gap_;
};

// The same step (S4)-(S9) in the modal coordinates q of (K, M), U = Phi q, where C is diagonal there
// too (ThetaIntegrator::ModalStep): A^-1 B and -h A^-1 K are the diagonals p1m and p2m, A^-1 F is
// Phi p3m, and A^-1 H = Phi diag(1/a) (H^T Phi)^T. A step reads H^T Phi twice (w_f, then the
// reactions' velocity) and Phi once (dU back from q; U by (S9) from the nodal velocities), as the
// nodal step reads A^-1 B, A^-1 K and Y: the same words when 3 n_c = N, fewer when 3 n_c < N. Its
// set-up has no O(N^3) part.
// Run-time sizes; implemented in theta_modal.cpp.
struct ModalStepData {
  const Eigen::MatrixXd *Phi, *PhiInv, *Htm;       // U = Phi q, q = Phi^T M U, H^T Phi
  const Eigen::VectorXd *p1m, *p2m, *p3m, *ainv;  // diagonals at h; p3m = h diag(1/a) Phi^T F
  const Eigen::MatrixXd *Ht;                       // H^T, for the gaps from the nodal U (or:)
  const SparseRowMatrix *Hts;                      // H^T by its non-zeros, or null
  const Eigen::VectorXd *g0;
  PetscReal              h, theta;
  LocalContactSolver    *local;
  // C not diagonal in the basis: G = A_m^-1 (dense), Phi^-1 Y = G (H^T Phi)^T and diag(k); else null
  // (p1m, p2m and ainv then hold the diagonal step).
  const Eigen::MatrixXd *G = nullptr, *Ym = nullptr;
  const Eigen::VectorXd *mk = nullptr;
};
std::unique_ptr<DenseStepKernel> MakeModalStepKernel(const ModalStepData &d);

// The compile-time sizes (N, n_c) that get their own instantiation: the 3-DOF reference model and
// the smallest multi-contact chain (4 cells, a contact on each, H not the identity), which keeps
// the fixed-size path under the chain tests too. Anything else runs the Eigen::Dynamic kernel.
template <int N, int NC>
struct KernelSize {};

template <class... Sizes>
struct FixedSizes;

template <>
struct FixedSizes<> {
  static std::unique_ptr<DenseStepKernel> Make(const DenseStepData &d, bool)
  {
    return std::make_unique<DenseStepKernelT<Eigen::Dynamic, Eigen::Dynamic>>(d);
  }
};

template <int N, int NC, class... Rest>
struct FixedSizes<KernelSize<N, NC>, Rest...> {
  static std::unique_ptr<DenseStepKernel> Make(const DenseStepData &d, bool fixed)
  {
    if (fixed && d.P1->rows() == N && d.g0->size() == NC) return std::make_unique<DenseStepKernelT<N, NC>>(d);
    return FixedSizes<Rest...>::Make(d, fixed);
  }
};

// The kernel for d's sizes: a fixed-size instantiation when one matches and fixed is true.
inline std::unique_ptr<DenseStepKernel> MakeDenseStepKernel(const DenseStepData &d, bool fixed)
{
  return FixedSizes<KernelSize<3, 1>, KernelSize<12, 4>>::Make(d, fixed);
}

} // namespace squeal
