// Step tangents in modal coordinates (ThetaIntegrator::ModalTangent): with U = Phi q, Phi^T M Phi = I
// and Phi^T K Phi = diag(k), a damping with Phi^T C Phi = diag(c) makes A = M + h theta C + h^2 theta^2 K
// and B diagonal in q, so P1 = A^-1 B and P2 = -h A^-1 K are the diagonals b / a and -h k / a. The
// contact terms become H^T Phi (3 n_c x N, dense) and Phi^-1 Y = diag(1 / a) (H^T Phi)^T, and W is
// unchanged. A tangent step then costs about 3 (3 n_c) N multiply-adds a column instead of
// 2 N^2 + 3 n_c N: on the reduced brake (N = 782, 3 n_c = 162) 0.38 M against 1.35 M.
#include "squeal/integration/theta.h"
#include "squeal/core/errors.h"

#include <Eigen/Eigenvalues>

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

PetscErrorCode ThetaIntegrator::ModalTangent(bool *on)
{
  PetscFunctionBeginUser;
  *on = false;
  if (!dense_ || modal_tangent_ == 1) {
    modal_on_  = false;
    modal_why_ = dense_ ? "-theta_modal_tangent false" : "sparse back end";
    PetscFunctionReturn(0);
  }
  if (!dense_sum_ok_) dense_sum_ = Checksum({&Md_, &Kd_, &Cd_}), dense_sum_ok_ = true;
  if (modal_state_ < 0 || dense_sum_ != modal_sum_) {
    modal_sum_ = dense_sum_, modal_h_ = -1;
    // K phi = lambda M phi, M symmetric positive definite (the model checks it).
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ges(Kd_, Md_);
    PetscCheck(ges.info() == Eigen::Success, comm_, PETSC_ERR_LIB, "modal tangent: the eigenproblem K phi = lambda M phi failed");
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
  }
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
  if (modal_h_ != h_) {
    const PetscReal h = h_, t = theta_;
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
  modal_why_.clear();
  *on = true;
  PetscFunctionReturn(0);
}

} // namespace squeal
