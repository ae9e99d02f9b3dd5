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

#include <Eigen/Eigenvalues>

#include <cstdio>
#include <cstring>

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
  // K phi = lambda M phi, M symmetric positive definite (the model checks it).
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ges(Kd_, Md_);
  PetscCheck(ges.info() == Eigen::Success, comm_, PETSC_ERR_LIB, "modal basis: the eigenproblem K phi = lambda M phi failed");
  Phi_    = ges.eigenvectors();
  mk_     = ges.eigenvalues();
  PhiInv_ = Phi_.transpose() * Md_;
  mc_.setZero(n_);
  modal_offdiag_ = 0;
  if (model_->HasDamping()) {
    const Eigen::MatrixXd D = Phi_.transpose() * Cd_ * Phi_;
    mc_                     = D.diagonal();
    const PetscReal dmax    = mc_.cwiseAbs().maxCoeff();
    Eigen::MatrixXd off     = D;
    off.diagonal().setZero();
    modal_offdiag_ = dmax > 0 ? off.cwiseAbs().maxCoeff() / dmax : (off.size() ? off.cwiseAbs().maxCoeff() : 0.0);
  }
  // Off-diagonal entries of Phi^T C Phi up to 1e-9 of its largest diagonal are round-off of a
  // diagonal C: the tangent then ignores them (a Jacobian error of that order).
  modal_state_ = modal_offdiag_ <= 1e-9 ? 1 : 0;
  PetscCall(PetscInfo(nullptr, "theta-method: modal basis of (K, M), N = %" PetscInt_FMT ", largest off-diagonal of Phi^T C Phi %g of its diagonal\n",
                      n_, (double)modal_offdiag_));
  PetscFunctionReturn(0);
}

void ThetaIntegrator::ModalPerStepSize()
{
  if (modal_h_ == h_) return;
  const PetscReal      h = h_, t = theta_;
  const Eigen::ArrayXd a = 1.0 + h * t * mc_.array() + h * h * t * t * mk_.array();
  const Eigen::ArrayXd b = 1.0 - h * (1 - t) * mc_.array() - h * h * t * (1 - t) * mk_.array();
  p1m_                   = (b / a).matrix();
  p2m_                   = (-h * mk_.array() / a).matrix();
  if (ht_sparse_) Htm_ = Hts_ * Phi_;
  else Htm_ = Ht_ * Phi_;
  Htmn_.resize(nc_, n_);
  for (PetscInt c = 0; c < nc_; ++c) Htmn_.row(c) = Htm_.row(3 * c + kN);
  ainvm_   = a.inverse().matrix();
  modal_h_ = h_;
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
    char b[160];
    std::snprintf(b, sizeof b, "C is not diagonal in the modal basis (off-diagonal %.2g of its diagonal)", (double)modal_offdiag_);
    modal_why_ = b;
    PetscCheck(modal_tangent_ != 2, comm_, kErrInput, "option -%smodal_tangent true: %s", prefix_.c_str(), b);
    modal_on_ = false;
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
  ModalPerStepSize();
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
  if (want) {
    PetscCall(ModalBasisUpdate());
    // The step itself, unlike a tangent, sets the cycle: C must be diagonal to round-off there.
    modal_step_on_ = modal_state_ == 1 && modal_offdiag_ <= 1e-12;
    if (!modal_step_on_) {
      char b[160];
      std::snprintf(b, sizeof b, "C is not diagonal in the modal basis (off-diagonal %.2g of its diagonal)", (double)modal_offdiag_);
      modal_step_why_ = b;
      PetscCheck(modal_step_ != 2 || modal_state_ == 1, comm_, kErrInput, "option -%smodal_step true: %s", prefix_.c_str(), b);
      if (modal_step_ == 2) modal_step_on_ = true; // asked for, C diagonal to 1e-9: its off-diagonal ignored (said by View)
    }
  }
  if (!modal_step_on_) PetscFunctionReturn(0);
  ModalPerStepSize();
  // p3 = h A^-1 F = Phi (h diag(1/a) Phi^T F); W = H^T A^-1 H = (H^T Phi) diag(1/a) (H^T Phi)^T,
  // a product of 3 n_c x N by its transpose instead of the N^3-sized solves of the nodal set-up.
  p3m_.noalias() = Phi_.transpose() * Fd_;
  p3m_           = (h_ * ainvm_.array() * p3m_.array()).matrix();
  if (nc_ > 0) {
    Gt_ = ainvm_.array().sqrt().matrix().asDiagonal() * Htm_.transpose();
    W_.resize(3 * nc_, 3 * nc_);
    Gemm(Gt_, true, Gt_, W_);
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
    mf_    = (d_.p1m->array() * dq.array() + d_.p2m->array() * q.array() + d_.p3m->array()).matrix(); // (S4)
    if (nc_ > 0) {
      Eigen::Map<Eigen::VectorXd> R(r.data(), 3 * nc_);
      dU0_ = U + h * (1 - t) * dU;
      wf_.noalias() = *d_.Htm * mf_; // (S5)
      NormalGaps(d_.Hts, *d_.Ht, dU0_, *d_.g0, gap_);
      *info = d_.local->SolveSized<Eigen::Dynamic>(wf_, gap_, R); // (S6)-(S7)
      ry_.noalias() = d_.Htm->transpose() * R;                    // (S8): Phi^-1 h Y r = h diag(1/a) (H^T Phi)^T r
      mf_.array() += h * d_.ainv->array() * ry_.array();
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
