// Step tangents in modal coordinates (ThetaIntegrator::ModalTangent): with U = Phi q, Phi^T M Phi = I
// and Phi^T K Phi = diag(k), a damping with Phi^T C Phi = diag(c) makes A = M + h theta C + h^2 theta^2 K
// and B diagonal in q, so P1 = A^-1 B and P2 = -h A^-1 K are the diagonals b / a and -h k / a. The
// contact terms become H^T Phi (3 n_c x N, dense) and Phi^-1 Y = diag(1 / a) (H^T Phi)^T, and W is
// unchanged. A tangent step then costs about 3 (3 n_c) N multiply-adds a column instead of
// 2 N^2 + 3 n_c N: on the reduced brake (N = 782, 3 n_c = 162) 0.38 M against 1.35 M.
// The forward step in the same coordinates (ModalStepSetUp, ModalStepKernel): a step size's set-up
// is then W = (H^T Phi) diag(1/a) (H^T Phi)^T and a few diagonals, without the nodal set-up's
// solves for A^-1 B, A^-1 K and A^-1 H (0.44 s a set-up on the reduced 31119-DOF pad, N = 1420),
// which shooting paid at every new period.
#include "squeal/integration/theta.h"
#include "squeal/core/dense_blas.h"
#include "squeal/core/errors.h"

#include <petscblaslapack.h>

#include <vector>

#include <cstdio>
#include <cstring>

extern "C" {
// Not among PETSc's LAPACK wrappers (which have dsygv only); in every LAPACK PETSc links.
void dsygvd_(const PetscBLASInt *, const char *, const char *, const PetscBLASInt *, double *, const PetscBLASInt *, double *, const PetscBLASInt *,
             double *, double *, const PetscBLASInt *, PetscBLASInt *, const PetscBLASInt *, PetscBLASInt *);
}

namespace squeal {

namespace {

// FNV-1a over the 64-bit words of the matrices: the basis is kept while M, K and C are those it
// was computed for (SetUp copies them from the model at every step size). Summed once per SetUp,
// not per call: 3 N^2 serially dependent words are ~3 ms at N = 782, and shooting asks for the
// tangents hundreds of times per step size.
std::uint64_t Checksum(std::initializer_list<const Eigen::MatrixXd *> mats)
{
  std::uint64_t hsh = 1469598103934665603ull;
  for (const Eigen::MatrixXd *m : mats) {
    const Eigen::Index n = m->size();
    hsh = (hsh ^ (std::uint64_t)n) * 1099511628211ull;
    for (Eigen::Index i = 0; i < n; ++i) {
      std::uint64_t w;
      std::memcpy(&w, m->data() + i, sizeof w);
      hsh = (hsh ^ w) * 1099511628211ull;
    }
  }
  return hsh;
}

} // namespace

PetscErrorCode ThetaIntegrator::ModalBasisUpdate()
{
  PetscFunctionBeginUser;
  if (!dense_sum_ok_) dense_sum_ = Checksum({&Md_, &Kd_, &Cd_}), dense_sum_ok_ = true;
  if (modal_state_ >= 0 && dense_sum_ == modal_sum_) PetscFunctionReturn(0);
  modal_sum_ = dense_sum_, modal_h_ = -1;
  // K phi = lambda M phi, M symmetric positive definite (the model checks it), by LAPACK's divide
  // and conquer: 1.0 s at N = 1858 against 3.2 s for Eigen's solver and 4.2 s for dsygv's QR
  // iterations (the size-1 brake, where shooting asks for the basis once to learn that C is not
  // diagonal in it). Phi^T M Phi = I, eigenvalues ascending, as Eigen's.
  {
    Eigen::MatrixXd Mc = Md_;
    Phi_               = Kd_;
    mk_.resize(n_);
    PetscBLASInt n, itype = 1, lwork = -1, liwork = -1, iwq = 0, info = 0;
    PetscReal    wq = 0;
    PetscCall(PetscBLASIntCast(n_, &n));
    dsygvd_(&itype, "V", "L", &n, Phi_.data(), &n, Mc.data(), &n, mk_.data(), &wq, &lwork, &iwq, &liwork, &info);
    PetscCheck(info == 0, comm_, PETSC_ERR_LIB, "modal basis: LAPACK dsygvd's workspace query failed (info %d)", (int)info);
    std::vector<PetscReal>    work((size_t)wq + 1);
    std::vector<PetscBLASInt> iwork((size_t)iwq + 1);
    PetscCall(PetscBLASIntCast((PetscInt)work.size(), &lwork));
    PetscCall(PetscBLASIntCast((PetscInt)iwork.size(), &liwork));
    dsygvd_(&itype, "V", "L", &n, Phi_.data(), &n, Mc.data(), &n, mk_.data(), work.data(), &lwork, iwork.data(), &liwork, &info);
    PetscCheck(info == 0, comm_, PETSC_ERR_LIB, "modal basis: the eigenproblem K phi = lambda M phi failed (LAPACK dsygvd, info %d%s)", (int)info,
               info > n ? ": M is not positive definite" : "");
  }
  PhiInv_ = Phi_.transpose() * Md_;
  mc_.setZero(n_);
  modal_offdiag_ = 0;
  Cm_.resize(0, 0);
  if (model_->HasDamping()) {
    Eigen::MatrixXd D = Phi_.transpose() * Cd_ * Phi_;
    mc_                  = D.diagonal();
    const PetscReal dmax = mc_.cwiseAbs().maxCoeff();
    Eigen::MatrixXd off  = D;
    off.diagonal().setZero();
    modal_offdiag_ = dmax > 0 ? off.cwiseAbs().maxCoeff() / dmax : (off.size() ? off.cwiseAbs().maxCoeff() : 0.0);
    // Kept for the dense modal step and tangents (G = A_m^-1) where it is not diagonal to round-off.
    if (modal_offdiag_ > 1e-12) Cm_ = (D + D.transpose()) / 2;
  }
  // Off-diagonal entries of Phi^T C Phi up to 1e-9 of its largest diagonal are round-off of a
  // diagonal C: the diagonal tangent then ignores them (a Jacobian error of that order).
  modal_state_ = modal_offdiag_ <= 1e-9 ? 1 : 0;
  PetscCall(PetscInfo(nullptr, "theta-method: modal basis of (K, M), N = %" PetscInt_FMT ", largest off-diagonal of Phi^T C Phi %g of its diagonal\n",
                      n_, (double)modal_offdiag_));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::ModalPerStepSize(bool dense)
{
  PetscFunctionBeginUser;
  if (dense && !modal_dense_) modal_h_ = -1; // G_ and Ym_ not formed at this h yet
  if (modal_h_ == h_) PetscFunctionReturn(0);
  const PetscReal      h = h_, t = theta_;
  const Eigen::ArrayXd a = 1.0 + h * t * mc_.array() + h * h * t * t * mk_.array();
  const Eigen::ArrayXd b = 1.0 - h * (1 - t) * mc_.array() - h * h * t * (1 - t) * mk_.array();
  p1m_                   = (b / a).matrix();
  p2m_                   = (-h * mk_.array() / a).matrix();
  if (ht_sparse_) Htm_ = Hts_ * Phi_;
  else Htm_ = Ht_ * Phi_;
  Htmn_.resize(nc_, n_);
  for (PetscInt c = 0; c < nc_; ++c) Htmn_.row(c) = Htm_.row(3 * c + kN);
  ainvm_        = a.inverse().matrix();
  modal_dense_  = dense;
  modal_f_ready_ = false;
  if (dense) {
    // C is not diagonal in the basis: G = A_m^-1, A_m = I + h theta C_m + h^2 theta^2 diag(k), by
    // LAPACK's Cholesky and its inverse, N^3 multiply-adds against the nodal set-up's 4.3 N^3 (A^-1 B
    // and A^-1 K: 0.72 s a step size on the size-1 brake, N = 1858, against 0.25 s). With
    // B_m = I / theta - (1 - theta) / theta A_m: P1 = G / theta - (1 - theta) / theta I and
    // P2 = -h G diag(k), so a step or a tangent column costs one product with G instead of two.
    PetscCheck(Cm_.rows() == n_, comm_, PETSC_ERR_PLIB, "dense modal step without the modal damping matrix");
    G_ = (h * t) * Cm_;
    G_.diagonal().array() += a - h * t * Cm_.diagonal().array();
    PetscBLASInt n, info = 0;
    PetscCall(PetscBLASIntCast(n_, &n));
    PetscCallBLAS("LAPACKpotrf", LAPACKpotrf_("L", &n, G_.data(), &n, &info));
    PetscCheck(info == 0, comm_, kErrInput, "theta-method: A = M + h theta C + h^2 theta^2 K is not positive definite (h = %g; modal Cholesky, info %d)",
               (double)h, (int)info);
    PetscCallBLAS("LAPACKpotri", LAPACKpotri_("L", &n, G_.data(), &n, &info));
    PetscCheck(info == 0, comm_, PETSC_ERR_LIB, "theta-method: the inverse of the modal A failed (LAPACK dpotri, info %d)", (int)info);
    G_.triangularView<Eigen::StrictlyUpper>() = G_.transpose();
    // Phi^-1 Y = G (H^T Phi)^T, so W = (H^T Phi) G (H^T Phi)^T.
    Ym_.resize(n_, 3 * nc_);
    if (nc_ > 0) {
      const Eigen::MatrixXd HtmT = Htm_.transpose();
      Gemm(G_, false, HtmT, Ym_);
    }
  } else G_.resize(0, 0), Ym_.resize(0, 0), Gf_.resize(0, 0);
  modal_h_ = h_;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::ModalTangent(bool *on)
{
  PetscFunctionBeginUser;
  *on = false;
  if (!dense_ || modal_tangent_ == 1) {
    modal_on_  = false;
    modal_why_ = dense_ ? "-theta_modal_tangent false" : "sparse back end";
    PetscFunctionReturn(0);
  }
  PetscCall(ModalBasisUpdate());
  if (modal_state_ == 0) {
    // C is not diagonal in the basis: the dense G (ModalPerStepSize), one N x N product a column and
    // step against the nodal two, plus the contact terms through the dense H^T Phi. Taken where the
    // step is modal (G is formed, and a nodal tangent would need the nodal set-up), or where it costs
    // less than 0.8 x the nodal products.
    const double n = (double)n_, m3 = 3.0 * nc_, nc = (double)nc_;
    const double ht    = ht_sparse_ ? (double)(Hts_.nonZeros() + Htns_.nonZeros()) : (m3 + nc) * n;
    const double nodal = 2 * n * n + m3 * n + ht, modal = n * n + (2 * m3 + nc) * n + 2 * n;
    modal_on_          = modal_tangent_ == 2 || (modal_step_on_ && modal_dense_) || modal < 0.8 * nodal;
    if (!modal_on_) {
      char b[200];
      std::snprintf(b, sizeof b, "C is not diagonal in the modal basis (off-diagonal %.2g of its diagonal), no gain: %.3g multiply-adds a column and step against %.3g nodal",
                    (double)modal_offdiag_, modal, nodal);
      modal_why_ = b;
      PetscFunctionReturn(0);
    }
    PetscCall(ModalPerStepSize(true));
    modal_why_.clear();
    *on = true;
    PetscFunctionReturn(0);
  }
  // Multiply-adds a column and step: modal (2 (3 n_c) + n_c) N (H^T Phi, its normal rows, Phi^-1 Y)
  // against nodal 2 N^2 + 3 n_c N and H^T with its normal rows (their non-zeros, or dense). Taken
  // below 0.8: on the 562-DOF pad (3 n_c = 525, H^T sparse) modal tangents at 0.95 of the nodal
  // multiply-adds (before the normal rows alone) were 11 % faster with the same GMRES iterations,
  // but on a nearly singular bordered system (the half brake's) GMRES took 9 % more modal products.
  const double n = (double)n_, m3 = 3.0 * nc_, nc = (double)nc_;
  const double ht     = ht_sparse_ ? (double)(Hts_.nonZeros() + Htns_.nonZeros()) : (m3 + nc) * n;
  const double nodal  = 2 * n * n + m3 * n + ht, modal = (2 * m3 + nc) * n + 2 * n;
  modal_on_           = modal_tangent_ == 2 || modal < 0.8 * nodal;
  if (!modal_on_) {
    char b[160];
    std::snprintf(b, sizeof b, "no gain: %.3g multiply-adds a column and step against %.3g nodal", modal, nodal);
    modal_why_ = b;
    PetscFunctionReturn(0);
  }
  PetscCall(ModalPerStepSize(modal_dense_ && modal_h_ == h_));
  modal_why_.clear();
  *on = true;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::ModalStepSetUp()
{
  PetscFunctionBeginUser;
  modal_step_on_ = false;
  // Auto: where a step reads no more words than the nodal one (3 n_c <= N) and either the caller
  // sets up many step sizes (shooting: one per period) or a step reads at most 0.8 of them (a
  // transient then gains per step what the basis cost once). The basis is an O(N^3) eigensolve
  // (shared with the modal tangents), so models below 64 DOFs keep the nodal step.
  const double n = (double)n_, m3 = 3.0 * nc_;
  const double modal = 2 * m3 * n + n * n, nodal = 2 * n * n + m3 * n;
  modal_step_why_.clear();
  bool want = modal_step_ == 2;
  if (modal_step_ == 0) {
    if (n_ < 64) modal_step_why_ = "fewer than 64 DOFs";
    else if (delassus_only_) modal_step_why_ = "no steps (the Delassus matrix only)";
    else if (!(modal <= nodal && (many_setups_ || modal <= 0.8 * nodal))) {
      char b[160];
      std::snprintf(b, sizeof b, "no gain: %.3g words read a step against %.3g nodal%s", modal, nodal, many_setups_ ? "" : ", one step size");
      modal_step_why_ = b;
    } else want = true;
  }
  bool dense = false;
  if (want) {
    PetscCall(ModalBasisUpdate());
    // The step itself, unlike a tangent, sets the cycle: the diagonal step only where C is diagonal
    // to round-off there. Elsewhere (a lining's own damping, say) the step takes the dense G =
    // A_m^-1: its set-up is N^3 multiply-adds against the nodal 4.3 N^3, but a step reads
    // 2 N^2 + 2 (3 n_c) N words against 2 N^2 + 3 n_c N, so auto takes it only where the caller
    // sets up many step sizes (shooting: one per period).
    const bool diagonal = modal_state_ == 1 && modal_offdiag_ <= 1e-12;
    dense               = !diagonal;
    modal_step_on_      = diagonal || modal_step_ == 2 || many_setups_;
    if (!modal_step_on_) {
      char b[160];
      std::snprintf(b, sizeof b, "C is not diagonal in the modal basis (off-diagonal %.2g of its diagonal), one step size", (double)modal_offdiag_);
      modal_step_why_ = b;
    }
  }
  if (!modal_step_on_) PetscFunctionReturn(0);
  PetscCall(ModalPerStepSize(dense));
  // p3 = h A^-1 F = Phi (h diag(1/a) Phi^T F); W = H^T A^-1 H = (H^T Phi) diag(1/a) (H^T Phi)^T,
  // a product of 3 n_c x N by its transpose instead of the N^3-sized solves of the nodal set-up.
  // With the dense G: p3 = Phi (h G Phi^T F) and W = (H^T Phi) G (H^T Phi)^T = (H^T Phi) (Phi^-1 Y).
  p3m_.noalias() = Phi_.transpose() * Fd_;
  if (dense) p3m_ = h_ * (G_ * p3m_);
  else p3m_ = (h_ * ainvm_.array() * p3m_.array()).matrix();
  if (nc_ > 0) {
    W_.resize(3 * nc_, 3 * nc_);
    if (dense) {
      Gemm(Htm_, false, Ym_, W_);
      W_ = ((W_ + W_.transpose()) / 2).eval(); // symmetric to the bit, as the contact solver's sweeps read it
    } else {
      Gt_ = ainvm_.array().sqrt().matrix().asDiagonal() * Htm_.transpose();
      Gemm(Gt_, true, Gt_, W_);
    }
  } else W_.resize(0, 0);
  nodal_ready_ = false;
  P1_.resize(0, 0), P2_.resize(0, 0), Y_.resize(0, 0), p3_.resize(0);
  P12f_.resize(0, 0), Yf_.resize(0, 0), nodal_f_ready_ = false;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::EnsureNodal()
{
  PetscFunctionBeginUser;
  if (nodal_ready_) PetscFunctionReturn(0);
  const PetscReal       h = h_, t = theta_;
  const Eigen::MatrixXd A = Md_ + h * t * Cd_ + h * h * t * t * Kd_;
  const Eigen::MatrixXd B = Md_ - h * (1 - t) * Cd_ - h * h * t * (1 - t) * Kd_;
  llt_.compute(A);
  PetscCheck(llt_.info() == Eigen::Success, comm_, kErrInput,
             "theta-method: A = M + h theta C + h^2 theta^2 K is not positive definite (h = %g)", (double)h);
  P1_          = llt_.solve(B);
  P2_          = -h * llt_.solve(Kd_);
  p3_          = h * llt_.solve(Fd_);
  Y_           = llt_.solve(Ht_.transpose());
  nodal_ready_ = true;
  nodal_f_ready_ = false;
  PetscFunctionReturn(0);
}

namespace {

class ModalStepKernel final : public DenseStepKernel {
public:
  explicit ModalStepKernel(const ModalStepData &d)
    : n_(d.Phi->rows()), nc_(d.g0->size()), h_(d.h), t_(d.theta), d_(d)
  {
    QD_.setZero(n_, 2), Uo_.setZero(n_), dUo_.setZero(n_), mf_.resize(n_), dU0_.resize(n_), wf_.resize(3 * nc_), gap_.resize(nc_), ry_.resize(n_);
  }

  void Step(PetscReal *u, PetscReal *du, Eigen::VectorXd &r, LocalSolveInfo *info) override
  {
    const PetscReal  h = h_, t = t_;
    Eigen::Map<Eigen::VectorXd> U(u, n_), dU(du, n_);
    // q from U once per trajectory: a step continuing the last one's output keeps its own q (the
    // caller may have put any other state in between).
    const size_t bytes = sizeof(PetscReal) * (size_t)n_;
    if (!valid_ || std::memcmp(u, Uo_.data(), bytes) != 0 || std::memcmp(du, dUo_.data(), bytes) != 0) {
      QD_.col(0).noalias() = *d_.PhiInv * U;
      QD_.col(1).noalias() = *d_.PhiInv * dU;
      valid_               = true;
    }
    auto q = QD_.col(0), dq = QD_.col(1);
    if (d_.G) {
      // (S4) with the dense G: P1 q' + P2 q + p3 = G (q' / theta - h k q) - (1 - theta) / theta q' + p3.
      // G is symmetric: its lower half read (0.34 ms against 0.50 for the whole at N = 1858).
      ry_ = dq / t - h * (d_.mk->array() * q.array()).matrix();
      mf_.noalias() = d_.G->selfadjointView<Eigen::Lower>() * ry_;
      mf_ += *d_.p3m - ((1 - t) / t) * dq;
    } else mf_ = (d_.p1m->array() * dq.array() + d_.p2m->array() * q.array() + d_.p3m->array()).matrix(); // (S4)
    if (nc_ > 0) {
      Eigen::Map<Eigen::VectorXd> R(r.data(), 3 * nc_);
      dU0_ = U + h * (1 - t) * dU;
      wf_.noalias() = *d_.Htm * mf_; // (S5)
      NormalGaps(d_.Hts, *d_.Ht, dU0_, *d_.g0, gap_);
      *info = d_.local->SolveSized<Eigen::Dynamic>(wf_, gap_, R); // (S6)-(S7)
      if (d_.G) mf_.noalias() += h * (*d_.Ym * R); // (S8): Phi^-1 h Y r
      else {
        ry_.noalias() = d_.Htm->transpose() * R; // (S8): Phi^-1 h Y r = h diag(1/a) (H^T Phi)^T r
        mf_.array() += h * d_.ainv->array() * ry_.array();
      }
    }
    // (S9) in both coordinates: U from the nodal velocities (as the nodal step), so that only dU
    // needs a product by Phi (a second column would double the multiply-adds of a model whose
    // matrices stay in cache: the half brake's 300 000-step transient took longer than nodal).
    // U and Phi q then differ by the round-off of their own sums, which does not grow.
    q += h * (t * mf_ + (1 - t) * dq);
    dq = mf_;
    U += (h * (1 - t)) * dU;
    dU.noalias() = *d_.Phi * mf_;
    U += (h * t) * dU;
    Uo_ = U, dUo_ = dU;
  }
  bool FixedSize() const override { return false; }

private:
  const Eigen::Index  n_, nc_;
  const PetscReal     h_, t_;
  const ModalStepData d_;
  bool                valid_ = false;
  Eigen::MatrixXd     QD_;      // (q, dq)
  Eigen::VectorXd     Uo_, dUo_; // the (U, dU) last returned
  Eigen::VectorXd     mf_, dU0_, wf_, gap_, ry_;
};

} // namespace

std::unique_ptr<DenseStepKernel> MakeModalStepKernel(const ModalStepData &d) { return std::make_unique<ModalStepKernel>(d); }

} // namespace squeal
