// The exact tangent of the theta-method's step (ThetaIntegrator::StepTangent, StepTangentSource;
// docs/method.md §6, "Exact tangent of the discrete step"): the derivative of (S4)-(S9) at the
// converged reactions with every status held fixed, for shooting's Jacobian and monodromy matrix.
// Dense back end only; the step itself is in theta.cpp.
#include "squeal/integration/theta.h"

#include <cmath>

namespace squeal {

PetscErrorCode ThetaIntegrator::StepTangent(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, Eigen::MatrixXd &dU,
                                            Eigen::MatrixXd &ddU)
{
  PetscFunctionBeginUser;
  PetscCall(StepTangentImpl(r, v_end, nullptr, nullptr, dU, ddU));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::StepTangent(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, const StepData &step,
                                            const Eigen::RowVectorXd &dh, Eigen::MatrixXd &dU, Eigen::MatrixXd &ddU)
{
  PetscFunctionBeginUser;
  PetscCall(StepTangentImpl(r, v_end, &step, &dh, dU, ddU));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::StepTangentSource(const Eigen::VectorXd &Ui, const Eigen::VectorXd &dUi, const Eigen::VectorXd &dUn,
                                                  const Eigen::VectorXd &r, Eigen::VectorXd &c)
{
  const PetscReal h = h_, t = theta_;
  PetscFunctionBeginUser;
  PetscCheck(dense_, comm_, PETSC_ERR_SUP, "the exact step tangent needs the dense back end (N <= -theta_dense_max)");
  tq_ = Fd_;
  tq_.noalias() -= Kd_ * (Ui + 2 * h * t * (1 - t) * dUi + 2 * h * t * t * dUn);
  if (model_->HasDamping()) tq_.noalias() -= Cd_ * ((1 - t) * dUi + t * dUn);
  c = llt_.solve(tq_);
  if (nc_ > 0) c.noalias() += Y_ * r;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::StepTangentImpl(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, const StepData *step,
                                                const Eigen::RowVectorXd *dh, Eigen::MatrixXd &dU, Eigen::MatrixXd &ddU)
{
  const PetscReal   h = h_, t = theta_;
  const ContactSet &cs = model_->contacts;
  PetscFunctionBeginUser;
  PetscCheck(dense_, comm_, PETSC_ERR_SUP, "the exact step tangent needs the dense back end (N <= -theta_dense_max)");
  const Eigen::Index k     = dU.cols();
  const bool         modal = step && step->modal;
  PetscCheck(!modal || (modal_on_ && modal_h_ == h_), comm_, PETSC_ERR_ARG_WRONGSTATE,
             "modal step tangent without ModalTangent at this step size");
  if (modal) tvf_ = (ddU.array().colwise() * p1m_.array() + dU.array().colwise() * p2m_.array()).matrix();
  else {
    tvf_.noalias() = P1_ * ddU;
    tvf_.noalias() += P2_ * dU;
  }
  if (dh) tvf_.noalias() += *step->c * *dh;
  if (nc_ > 0) {
    local_.Status(r, tstatus_);
    // Open points keep delta r = 0 and drop out: the system couples the closed points only.
    tclosed_.clear();
    for (PetscInt c = 0; c < nc_; ++c)
      if (tstatus_[c] != kOpen)
        for (int j = 0; j < 3; ++j) tclosed_.push_back(3 * c + j);
    const Eigen::Index m = (Eigen::Index)tclosed_.size();
    if (m > 0) {
      tw_.resize(m, k), tg_.resize(m, k);
      // delta w_f = H^T delta v_f and delta g~^i = H_n^T (delta U + h (1 - theta) delta dU) in one
      // pass over the whole H^T (contiguous), the closed rows picked afterwards: copying the closed
      // rows of H^T, or reading its rows one by one, cost more than the product for few columns.
      tX_.resize(n_, 2 * k);
      tX_.leftCols(k)  = tvf_;
      tX_.rightCols(k) = dU + (h * (1 - t)) * ddU;
      // One column (GMRES): two matrix-vector products; Eigen's matrix-matrix path would first
      // copy (pack) the whole H^T for two columns.
      tHv_.resize(3 * nc_, 2 * k);
      const Eigen::MatrixXd &Ht = modal ? Htm_ : Ht_;
      if (ht_sparse_ && !modal) tHv_.noalias() = Hts_ * tX_;
      else if (k == 1) tHv_.col(0).noalias() = Ht * tX_.col(0), tHv_.col(1).noalias() = Ht * tX_.col(1);
      else tHv_.noalias() = Ht * tX_;
      for (Eigen::Index q = 0; q < m; ++q) tw_.row(q) = tHv_.row(tclosed_[q]).head(k);
      for (Eigen::Index q = 0; q < m; q += 3) tg_.row(q + kN) = tHv_.row(tclosed_[q] + kN).tail(k);
      // With a valid factor of this step only the right-hand side is assembled (the O(m^2) matrix
      // assembly then dominated one-column products).
      const bool reuse = step && step->factor && step->factor->valid;
      if (!reuse) tAc_.setZero(m, m);
      else if (tAc_.rows() != m) tAc_.resize(m, m);
      trc_.setZero(m, k);
      auto Wrow = [&](Eigen::Index row, Eigen::Index q, PetscReal a) { // tAc_.row(q) += a W(row, closed)
        if (reuse) return;
        for (Eigen::Index p = 0; p < m; ++p) tAc_(q, p) += a * W_(row, tclosed_[p]);
      };
      for (Eigen::Index q0 = 0; q0 < m; q0 += 3) {
        const PetscInt     c = tclosed_[q0] / 3;
        const Eigen::Index o = 3 * c, qn = q0 + kN;
        // Normal row: delta g~_n + h delta v_n = 0, delta v = delta w_f + h W delta r; in h also
        // d g~_n / dh = (1 - theta) v_n(t_i) and d (h v_n) / dh = v_n(t_{i+1}).
        // Divided by h, a velocity row like the stick rows: as a displacement row (h^2 W) it was
        // h times smaller than theirs, and partial pivoting on the unequilibrated rows made two
        // orders of the same triangular solves differ by 1e-9 on the chain's cycle (2.6e-14 now).
        Wrow(o + kN, qn, h);
        trc_.row(qn) = -tg_.row(qn) / h - tw_.row(qn);
        if (dh) trc_.row(qn) -= (((1 - t) * (*step->v_start)[o + kN] + v_end[o + kN]) / h) * *dh;
        const bool rect = cs.law == FrictionLaw::Rectilinear;
        if (tstatus_[c] == kStick) {
          for (int j : {kT, kB}) {
            if (rect && j == kB) {
              tAc_(q0 + j, q0 + j) = 1.0;                                 // delta r_b = 0
              continue;
            }
            Wrow(o + j, q0 + j, h);                                       // delta v_j = 0
            trc_.row(q0 + j) = -tw_.row(q0 + j);
          }
          continue;
        }
        // Slip, r_T = -mu r_n s/|s| with s = v_T - V_c.
        const PetscReal mu = cs.Mu(), rn = r[o + kN];
        if (rect) {
          const PetscReal sg = r[o + kT] > 0 ? -1.0 : 1.0; // sign(s_t), from r_t = -mu r_n sign(s_t)
          tAc_(q0 + kT, q0 + kT) = 1.0, tAc_(q0 + kT, qn) = mu * sg;
          tAc_(q0 + kB, q0 + kB) = 1.0;
          continue;
        }
        Eigen::Vector2d sv(v_end[o + kT] - cs.Speed(c), v_end[o + kB]);
        const PetscReal ns = sv.norm();
        if (!(ns > 1e-14 * (std::abs(cs.Speed(c)) + 1.0))) { // slipping at zero speed: the stick rows
          for (int j : {kT, kB}) {
            Wrow(o + j, q0 + j, h);
            trc_.row(q0 + j) = -tw_.row(q0 + j);
          }
          continue;
        }
        const Eigen::Vector2d sh = sv / ns;
        const Eigen::Matrix2d P  = (mu * rn / ns) * (Eigen::Matrix2d::Identity() - sh * sh.transpose());
        for (int a = 0; a < 2; ++a) {
          const int ra = a == 0 ? kT : kB;
          tAc_(q0 + ra, q0 + ra) += 1.0;
          tAc_(q0 + ra, qn) += mu * sh[a];
          for (int b = 0; b < 2; ++b) {
            const int rb = b == 0 ? kT : kB;
            Wrow(o + rb, q0 + ra, P(a, b) * h);
            trc_.row(q0 + ra) -= P(a, b) * tw_.row(q0 + rb);
          }
        }
      }
      if (step && step->factor) {
        if (!step->factor->valid) step->factor->lu.compute(tAc_), step->factor->valid = true;
        // One column through the vector triangular solves (the matrix ones pack the factor).
        tdr_.resize(m, k);
        if (k == 1) tdr_.col(0) = step->factor->lu.solve(trc_.col(0));
        else tdr_ = step->factor->lu.solve(trc_);
      } else tdr_ = tAc_.partialPivLu().solve(trc_);
      // delta dU^{i+1} += h Y delta r, with delta r = 0 on the open points (Y read in place).
      tdrf_.setZero(3 * nc_, k);
      for (Eigen::Index q = 0; q < m; ++q) tdrf_.row(tclosed_[q]) = tdr_.row(q);
      tvf_.noalias() += h * ((modal ? Ym_ : Y_) * tdrf_);
    }
  }
  dU += h * (t * tvf_ + (1 - t) * ddU);
  if (dh) dU.noalias() += (t * *step->dUn + (1 - t) * *step->dUi) * *dh;
  ddU = tvf_;
  PetscFunctionReturn(0);
}

} // namespace squeal

namespace squeal {

PetscErrorCode LinearMonodromy(ThetaIntegrator &ti, const Eigen::VectorXd &r0, PetscInt steps, Eigen::MatrixXd &P)
{
  const Eigen::Index N = ti.GetModel().Size(), n2 = 2 * N;
  PetscFunctionBeginUser;
  Eigen::MatrixXd dU = Eigen::MatrixXd::Zero(N, n2), ddU = Eigen::MatrixXd::Zero(N, n2);
  dU.leftCols(N).setIdentity();
  ddU.rightCols(N).setIdentity();
  PetscCall(ti.StepTangent(r0, Eigen::VectorXd::Zero(r0.size()), dU, ddU));
  Eigen::MatrixXd S(n2, n2), tmp(n2, n2);
  S.topRows(N)    = dU;
  S.bottomRows(N) = ddU;
  P               = Eigen::MatrixXd::Identity(n2, n2);
  for (PetscInt e = steps; e > 0; e >>= 1) {
    if (e & 1) tmp.noalias() = P * S, P.swap(tmp);
    if (e > 1) tmp.noalias() = S * S, S.swap(tmp);
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
