// The exact tangent of the theta-method's step (ThetaIntegrator::StepTangent, StepTangentSource(s);
// docs/method.md §6, "Exact tangent of the discrete step"): the derivative of (S4)-(S9) at the
// converged reactions with every status held fixed, for shooting's Jacobian and monodromy matrix.
// Dense back end only; the step itself is in theta.cpp.
#include "squeal/integration/theta.h"

#include "squeal/core/dense_blas.h"
#include "squeal/core/interrupt.h"

#include <algorithm>
#include <cmath>
#include <optional>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif
#include <type_traits>
#include <vector>

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
  Eigen::MatrixXd dU(n_, 2), C;
  PetscFunctionBeginUser;
  dU.col(0) = dUi, dU.col(1) = dUn;
  PetscCall(StepTangentSources(Ui, dU, r, C));
  c = C.col(0);
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::StepTangentSources(const Eigen::Ref<const Eigen::MatrixXd> &U, const Eigen::Ref<const Eigen::MatrixXd> &dU,
                                                   const Eigen::Ref<const Eigen::MatrixXd> &R, Eigen::MatrixXd &C)
{
  const PetscReal    h = h_, t = theta_;
  const Eigen::Index s = U.cols();
  PetscFunctionBeginUser;
  PetscCheck(dense_, comm_, PETSC_ERR_SUP, "the exact step tangent needs the dense back end (N <= -theta_dense_max)");
  PetscCheck(dU.cols() == s + 1 && (nc_ == 0 || R.cols() == s), comm_, PETSC_ERR_ARG_SIZ, "StepTangentSources: %" PetscInt_FMT " steps need %" PetscInt_FMT " velocities and reactions",
             (PetscInt)s, (PetscInt)(s + 1));
  // All the steps' columns at once, matrix-matrix products: one step at a time they were
  // matrix-vector products reading K, C and the modal basis (or the Cholesky factor) from memory
  // for each step, 0.1 s a flow of 200 steps on the 562-DOF pad (records.md, "Step factors in float").
  const auto      dUi = dU.leftCols(s), dUn = dU.rightCols(s);
  Eigen::MatrixXd Q   = Fd_.replicate(1, s), X = U + (2 * h * t * (1 - t)) * dUi + (2 * h * t * t) * dUn;
  Gemm(Kd_, false, X, Q, -1.0, 1.0);
  if (model_->HasDamping()) {
    X = (1 - t) * dUi + t * dUn;
    Gemm(Cd_, false, X, Q, -1.0, 1.0);
  }
  C.resize(n_, s);
  if (!nodal_ready_) {
    // The modal step's set-up: A^-1 = Phi diag(1/a) Phi^T and Y r = Phi diag(1/a) (H^T Phi)^T r.
    Eigen::MatrixXd Ym(n_, s);
    Gemm(Phi_, true, Q, Ym);
    if (modal_dense_) {
      // The dense G: A^-1 = Phi G Phi^T and Y r = Phi Ym r.
      X.resize(n_, s);
      X.noalias() = G_.selfadjointView<Eigen::Lower>() * Ym;
      if (nc_ > 0) Gemm(Ym_, false, R, X, 1.0, 1.0);
      Ym.swap(X);
    } else {
      if (nc_ > 0) Gemm(Htm_, true, R, Ym, 1.0, 1.0);
      Ym.array().colwise() *= ainvm_.array();
    }
    Gemm(Phi_, false, Ym, C);
    PetscFunctionReturn(0);
  }
  C = llt_.solve(Q);
  if (nc_ > 0) Gemm(Y_, false, R, C, 1.0, 1.0);
  PetscFunctionReturn(0);
}

void ThetaIntegrator::TangentUnknowns(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end)
{
  const ContactSet &cs = model_->contacts;
  local_.Status(r, tstatus_);
  const bool      rect = cs.law == FrictionLaw::Rectilinear;
  const PetscReal mu   = cs.Mu();
  tunk_.clear();
  for (PetscInt c = 0; c < nc_; ++c) {
    if (tstatus_[c] == kOpen) continue;
    const Eigen::Index o = 3 * c;
    TangentUnknown     un{o, {0, 0, 0}, {0, 0, 0}, 0, true};
    un.g[kN] = un.e[kN] = 1;
    bool            stick_rows = tstatus_[c] == kStick;
    Eigen::Vector2d sp(0, 0);
    PetscReal       alpha = 0;
    if (!stick_rows && rect) un.g[kT] = -mu * (r[o + kT] > 0 ? -1.0 : 1.0); // r_t = -mu r_n sign(s_t)
    else if (!stick_rows) {
      // Slip, r_T = -mu r_n s/|s| with s = v_T - V_c.
      const Eigen::Vector2d sv(v_end[o + kT] - cs.Speed(c), v_end[o + kB]);
      const PetscReal       ns = sv.norm();
      if (!(ns > 1e-14 * (std::abs(cs.Speed(c)) + 1.0))) stick_rows = true; // slipping at zero speed: the stick rows
      else {
        const Eigen::Vector2d sh = sv / ns;
        un.g[kT] = -mu * sh[0], un.g[kB] = -mu * sh[1];
        sp       = Eigen::Vector2d(-sh[1], sh[0]);
        alpha    = mu * r[o + kN] / ns;
      }
    }
    tunk_.push_back(un);
    if (stick_rows) {
      for (int j : {kT, kB}) { // delta v_j = 0 (rectilinear: delta r_b = 0, no unknown)
        if (rect && j == kB) continue;
        TangentUnknown s{o, {0, 0, 0}, {0, 0, 0}, 0, false};
        s.g[j] = s.e[j] = 1;
        tunk_.push_back(s);
      }
    } else if (!rect) {
      TangentUnknown s{o, {0, 0, 0}, {0, 0, 0}, 1, false};
      s.g[kT] = sp[0], s.g[kB] = sp[1];
      s.e[kT] = alpha * sp[0], s.e[kB] = alpha * sp[1];
      tunk_.push_back(s);
    }
  }
}

Eigen::Index ThetaIntegrator::TangentSystemSize(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end)
{
  if (nc_ == 0) return 0;
  TangentUnknowns(r, v_end);
  return (Eigen::Index)tunk_.size();
}

PetscErrorCode ThetaIntegrator::StepTangentImpl(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, const StepData *step,
                                                const Eigen::RowVectorXd *dh, Eigen::MatrixXd &dU, Eigen::MatrixXd &ddU)
{
  const PetscReal   h = h_, t = theta_;
  PetscFunctionBeginUser;
  PetscCheck(dense_, comm_, PETSC_ERR_SUP, "the exact step tangent needs the dense back end (N <= -theta_dense_max)");
  const Eigen::Index k     = dU.cols();
  const bool         modal = step && step->modal;
  PetscCheck(!modal || (modal_on_ && modal_h_ == h_), comm_, PETSC_ERR_ARG_WRONGSTATE,
             "modal step tangent without ModalTangent at this step size");
  // Modal tangents in float: H^T Phi and its normal rows (the contact products, 3 (3 n_c) N of a
  // diagonal step's multiply-adds), and with the dense G also G - I and Ym.
  const bool modal_f = modal && TangentSingle();
  if (modal_f && !modal_f_ready_) {
    Htmf_ = Htm_.cast<float>(), Htmnf_ = Htmn_.cast<float>();
    if (modal_dense_) {
      Gf_ = G_.cast<float>();
      Gf_.diagonal().array() -= 1.0f;
      Ymf_ = Ym_.cast<float>();
    }
    modal_f_ready_ = true;
  }
  if (modal && modal_dense_) {
    // P1 ddq + P2 dq = G x - (1 - theta) / theta ddq with x = ddq / theta - h k dq; in float as
    // ddq - h k dq + (G - I) x (the identity kept exact, as P1's in the nodal tangent below).
    tX_ = ddU / t - h * (dU.array().colwise() * mk_.array()).matrix();
    if (modal_f) {
      tXf_ = tX_.cast<float>(), tvff_.resize(n_, k);
      if (k == 1) tvff_.col(0).noalias() = Gf_ * tXf_.col(0);
      else GemmFloat(Gf_, tXf_, tvff_);
      tvf_ = tX_ - ((1 - t) / t) * ddU + tvff_.cast<double>(); // x - (1 - theta) / theta ddq = ddq - h k dq
    } else {
      tvf_.resize(n_, k);
      Gemm(G_, false, tX_, tvf_);
      tvf_ -= ((1 - t) / t) * ddU;
    }
  } else if (modal) tvf_ = (ddU.array().colwise() * p1m_.array() + dU.array().colwise() * p2m_.array()).matrix();
  else {
    PetscCall(EnsureNodal());
    tvf_.resize(n_, k);
    if (TangentSingle()) {
      // The two N x N products are most of a nodal tangent step (their 2 N^2 multiply-adds a column
      // against 3 n_c N for the contact terms; 1.4 of the 1.85 s of a Floquet block's integration on
      // the size-1 brake, N = 1858), and in float they take half the time. Only the tangent reads
      // them: the flow, and so the cycle and the residual Newton drives to zero, stay in double.
      // P1 = A^-1 B is I plus O(h omega): rounded as it is, its identity's round-off (6e-8 a step,
      // 1.2e-5 over a period of 200 steps) would be a sizeable share of a lightly damped mode's
      // decay a step (1.3e-6 on the brake's at 1.7 1/s), so only P1 - I is rounded.
      if (!nodal_f_ready_) {
        P12f_.resize(n_, 2 * n_);
        P12f_.leftCols(n_) = (P1_ - Eigen::MatrixXd::Identity(n_, n_)).cast<float>(), P12f_.rightCols(n_) = P2_.cast<float>();
        Yf_            = Y_.cast<float>();
        nodal_f_ready_ = true;
      }
      tXf_.resize(2 * n_, k), tvff_.resize(n_, k);
      tXf_.topRows(n_) = ddU.cast<float>(), tXf_.bottomRows(n_) = dU.cast<float>();
      if (k == 1) tvff_.col(0).noalias() = P12f_ * tXf_.col(0);
      else GemmFloat(P12f_, tXf_, tvff_);
      tvf_ = ddU + tvff_.cast<double>();
    } else {
      Gemm(P1_, false, ddU, tvf_);
      Gemm(P2_, false, dU, tvf_, 1.0, 1.0);
    }
  }
  if (dh) tvf_.noalias() += *step->c * *dh;
  if (nc_ > 0) {
    // The closed points' reaction changes in the fewest unknowns. Open points keep delta r = 0
    // and drop out. A sliding point's reaction along its slip direction s^ is -mu r_n, so with
    // P = (mu r_n / |s|) (I - s^ s^T) = alpha s_p s_p^T (s_p perpendicular to s^) its two slip
    // rows, projected on s^, read delta r_s + mu delta r_n = 0: delta r_T = -mu delta r_n s^ +
    // x_p s_p, and only the row along s_p remains. A rectilinear sliding point keeps delta r_n
    // alone. The system is then 3 n_stick + 2 n_slip (planar) instead of 3 n_closed: on the
    // 175-point pad, mostly sliding, 350 instead of 525 unknowns, 0.3 of the LU's cost.
    // Unknown q: delta r of its point (rows o..o+2) += g_q x_q; its row:
    // d_q x_q + h e_q^T (W delta r)_point = -e_q^T delta w_f (- delta g~_n / h on a normal row).
    TangentUnknowns(r, v_end);
    const Eigen::Index m = (Eigen::Index)tunk_.size();
    if (m > 0) {
      // delta w_f = H^T delta v_f on every row, delta g~_n = H_n^T (delta U + h (1 - theta) delta dU)
      // on the normal rows alone (a third of H^T: in modal coordinates, where H^T Phi is dense,
      // 2 (3 n_c) + n_c rows of products a step instead of 3 (3 n_c)).
      tX_ = dU + (h * (1 - t)) * ddU;
      tHv_.resize(3 * nc_, k), tGn_.resize(nc_, k);
      if (ht_sparse_ && !modal) tHv_.noalias() = Hts_ * tvf_, tGn_.noalias() = Htns_ * tX_;
      else if (modal_f) {
        tvff_ = tvf_.cast<float>(), tXf_ = tX_.cast<float>();
        if (k == 1) {
          // One column: H^T Phi read once for both products, as in double below (its normal rows
          // were a second read, 0.39 of the 3.2 MB a one-column step reads on the 562-DOF pad).
          constexpr Eigen::Index kBlock = 16;
          tHvf_.setZero(3 * nc_, 2);
          for (Eigen::Index j = 0; j < n_; j += kBlock) {
            const Eigen::Index b    = std::min(kBlock, n_ - j);
            const auto         cols = Htmf_.middleCols(j, b);
            tHvf_.col(0).noalias() += cols * tvff_.col(0).segment(j, b);
            tHvf_.col(1).noalias() += cols * tXf_.col(0).segment(j, b);
          }
          tHv_.col(0) = tHvf_.col(0).cast<double>();
          for (PetscInt c = 0; c < nc_; ++c) tGn_(c, 0) = tHvf_(3 * c + kN, 1);
        } else {
          tHvf_.resize(3 * nc_, k), tGnf_.resize(nc_, k);
          GemmFloat(Htmf_, tvff_, tHvf_), GemmFloat(Htmnf_, tXf_, tGnf_);
          tHv_ = tHvf_.cast<double>(), tGn_ = tGnf_.cast<double>();
        }
      } else if (modal && k == 1) {
        // One column (GMRES) in modal coordinates: H^T Phi (dense, 15 MB on the 1420-DOF pad) read
        // once for both products, kBlock columns at a time (the second product reads them from
        // L2), instead of H^T Phi and then its normal rows; the gap change takes the normal rows
        // of the second. With the step factor and the product by (H^T Phi)^T below, a step reads
        // 2 (3 n_c) N + m^2 words (docs/records.md, "Block tangents through BLAS"). Matrix-vector
        // products on the blocks rather than two axpys a column, which loaded and stored the 3 n_c
        // sums for every column: 5 s less of the large pad's ~100 s of tangent flows.
        constexpr Eigen::Index kBlock = 16;
        tG3_.setZero(3 * nc_);
        auto hv = tHv_.col(0);
        hv.setZero();
        for (Eigen::Index j = 0; j < n_; j += kBlock) {
          const Eigen::Index b    = std::min(kBlock, n_ - j);
          const auto         cols = Htm_.middleCols(j, b);
          hv.noalias() += cols * tvf_.col(0).segment(j, b);
          tG3_.noalias() += cols * tX_.col(0).segment(j, b);
        }
        for (PetscInt c = 0; c < nc_; ++c) tGn_(c, 0) = tG3_[3 * c + kN];
      } else if (k == 1) {
        // One column (GMRES): matrix-vector products; Eigen's matrix-matrix path would first copy
        // (pack) the whole matrix for one column.
        tHv_.col(0).noalias() = (modal ? Htm_ : Ht_) * tvf_.col(0);
        tGn_.col(0).noalias() = (modal ? Htmn_ : Htn_) * tX_.col(0);
      } else Gemm(modal ? Htm_ : Ht_, false, tvf_, tHv_), Gemm(modal ? Htmn_ : Htn_, false, tX_, tGn_);
      // With a valid factor of this step only the right-hand side is assembled.
      const bool reuse = step && step->factor && step->factor->valid;
      if (!reuse) {
        // A = diag(d) + h E^T W G: first W G (3 n_c x m, columns of W combined), then its rows.
        tWG_.resize(3 * nc_, m);
        for (Eigen::Index p = 0; p < m; ++p) {
          const TangentUnknown &u = tunk_[p];
          auto                  col = tWG_.col(p);
          col.setZero();
          for (int j = 0; j < 3; ++j)
            if (u.g[j] != 0) col.noalias() += u.g[j] * W_.col(u.o + j);
        }
        tAc_.resize(m, m);
        for (Eigen::Index p = 0; p < m; ++p)
          for (Eigen::Index q = 0; q < m; ++q) {
            const TangentUnknown &u = tunk_[q];
            tAc_(q, p)              = h * (u.e[0] * tWG_(u.o, p) + u.e[1] * tWG_(u.o + 1, p) + u.e[2] * tWG_(u.o + 2, p));
          }
        for (Eigen::Index q = 0; q < m; ++q) tAc_(q, q) += tunk_[q].d;
      }
      trc_.resize(m, k);
      for (Eigen::Index q = 0; q < m; ++q) {
        const TangentUnknown &u = tunk_[q];
        auto                  row = trc_.row(q);
        row.setZero();
        for (int j = 0; j < 3; ++j)
          if (u.e[j] != 0) row.noalias() -= u.e[j] * tHv_.row(u.o + j);
        if (u.normal) {
          // Divided by h, a velocity row like the stick rows: as a displacement row (h^2 W) it was
          // h times smaller than theirs, and partial pivoting on the unequilibrated rows made two
          // orders of the same triangular solves differ by 1e-9 on the chain's cycle. In h also
          // d g~_n / dh = (1 - theta) v_n(t_i) and d (h v_n) / dh = v_n(t_{i+1}).
          row.noalias() -= tGn_.row(u.o / 3) / h;
          if (dh) row.noalias() -= (((1 - t) * (*step->v_start)[u.o + kN] + v_end[u.o + kN]) / h) * *dh;
        }
      }
      if (step && step->factor) {
        StepData::Factor &f      = *step->factor;
        const bool        single = TangentSingle();
        if (!f.valid) {
          if (single) {
            // Factorised and kept in float, like the products above: on pad_cycle.yaml the same
            // Newton iterates (dT / T within 1e-4 of itself), multipliers within 2.5e-7, and the
            // factorisations, once per step of each Newton iterate's flow, take half the time.
            // In place in the step's own storage (the same size from one flow to the next).
            f.luf = tAc_.cast<float>();
            const Eigen::PartialPivLU<Eigen::Ref<Eigen::MatrixXf>> lu(f.luf);
            f.perm = lu.permutationP();
          } else f.lu.compute(tAc_);
          f.valid = true;
        }
        // Eigen's triangular solves, not BLAS's dtrsm: at m = 350 and 16 columns (a Floquet block on
        // the 2 625-DOF pad) dtrsm took 397 us against Eigen's 267, 230 in float (records.md).
        if (single) {
          tdrff_ = (f.perm * trc_).cast<float>();
          if (k == 1) {
            auto x = tdrff_.col(0); // the vector solves
            f.luf.triangularView<Eigen::UnitLower>().solveInPlace(x);
            f.luf.triangularView<Eigen::Upper>().solveInPlace(x);
          } else {
            f.luf.triangularView<Eigen::UnitLower>().solveInPlace(tdrff_);
            f.luf.triangularView<Eigen::Upper>().solveInPlace(tdrff_);
          }
          tdr_ = tdrff_.cast<double>();
        } else tdr_ = f.lu.solve(trc_);
      } else tdr_ = tAc_.partialPivLu().solve(trc_);
      // delta dU^{i+1} += h Y delta r, with delta r = 0 on the open points (Y read in place).
      tdrf_.setZero(3 * nc_, k);
      for (Eigen::Index q = 0; q < m; ++q) {
        const TangentUnknown &u = tunk_[q];
        for (int j = 0; j < 3; ++j)
          if (u.g[j] != 0) tdrf_.row(u.o + j).noalias() += u.g[j] * tdr_.row(q);
      }
      if (!modal && TangentSingle()) {
        tdrff_ = tdrf_.cast<float>(), tvff_.resize(n_, k);
        if (k == 1) tvff_.col(0).noalias() = Yf_ * tdrff_.col(0);
        else GemmFloat(Yf_, tdrff_, tvff_);
        tvf_ += h * tvff_.cast<double>();
      } else if (!modal) Gemm(Y_, false, tdrf_, tvf_, h, 1.0);
      else if (modal_f && modal_dense_) {
        tdrff_ = tdrf_.cast<float>(), tvff_.resize(n_, k);
        if (k == 1) tvff_.col(0).noalias() = Ymf_ * tdrff_.col(0);
        else GemmFloat(Ymf_, tdrff_, tvff_);
        tvf_ += h * tvff_.cast<double>();
      } else if (modal_f) {
        // Phi^-1 Y = diag(1/a) (H^T Phi)^T, read from its float copy in place.
        tdrff_ = tdrf_.cast<float>(), tvff_.resize(n_, k);
        if (k == 1) tvff_.col(0).noalias() = Htmf_.transpose() * tdrff_.col(0);
        else GemmFloat(Htmf_, tdrff_, tvff_, true); // sgemm: Eigen's transposed product packed H^T Phi, twice the time
        tvf_.array() += h * (tvff_.cast<double>().array().colwise() * ainvm_.array());
      } else if (modal && modal_dense_) Gemm(Ym_, false, tdrf_, tvf_, h, 1.0);
      else {
        // Phi^-1 Y = diag(1/a) (H^T Phi)^T, read from H^T Phi in place (one copy of it, not two).
        tYr_.resize(n_, k);
        if (k == 1) tYr_.col(0).noalias() = Htm_.transpose() * tdrf_.col(0);
        else Gemm(Htm_, true, tdrf_, tYr_);
        tvf_.array() += h * (tYr_.array().colwise() * ainvm_.array());
      }
    }
  }
  dU += h * (t * tvf_ + (1 - t) * ddU);
  if (dh) dU.noalias() += (t * *step->dUn + (1 - t) * *step->dUi) * *dh;
  ddU = tvf_;
  PetscFunctionReturn(0);
}

} // namespace squeal

namespace squeal {

PetscErrorCode LinearMonodromy(ThetaIntegrator &ti, const Eigen::VectorXd &r0, PetscInt steps, Eigen::MatrixXd &P, MPI_Comm comm, const char *poll, bool single)
{
  const Eigen::Index N = ti.GetModel().Size(), n2 = 2 * N;
  PetscMPIInt        size, rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  // On several ranks rank q forms columns [n2 q / p, n2 (q + 1) / p) of each product and the blocks
  // are exchanged (column-major: each block is contiguous).
  std::vector<PetscMPIInt> counts(size), displs(size);
  for (PetscMPIInt q = 0; q < size; ++q) {
    PetscCall(PetscMPIIntCast(n2 * (n2 * q / size), &displs[q]));
    PetscCall(PetscMPIIntCast(n2 * (n2 * (q + 1) / size - n2 * q / size), &counts[q]));
  }
  const Eigen::Index c0 = n2 * rank / size, kc = n2 * (rank + 1) / size - c0;
  // Polled: each rank's block in the same number of slices of at most kSlice columns (the polls
  // are collective), 2 (2N)^2 kSlice flops each, about 0.1 s at N = 1594.
  constexpr Eigen::Index kSlice  = 256;
  const Eigen::Index     slices  = poll ? (n2 / size + 1 + kSlice - 1) / kSlice : 1;
  std::optional<InterruptPacer> pacer;
  if (poll) pacer.emplace(comm, poll);
  // The step's tangent of the 2N unit columns, S = [dU; ddU]: polled too, in slices of at most
  // kSlice columns on every rank (whole, it took 1.3 s on the 400-cell chain, 2N = 2 400: longer
  // than the second mpiexec leaves between its SIGTERM and the kill).
  Eigen::MatrixXd S(n2, n2), tmp(n2, n2);
  {
    const Eigen::Index    ns = poll ? (n2 + kSlice - 1) / kSlice : 1;
    const Eigen::VectorXd v0 = Eigen::VectorXd::Zero(r0.size());
    Eigen::MatrixXd       dU, ddU;
    for (Eigen::Index s = 0; s < ns; ++s) {
      const Eigen::Index a = n2 * s / ns, b = n2 * (s + 1) / ns;
      if (pacer) PetscCall(pacer->Step());
      dU.setZero(N, b - a), ddU.setZero(N, b - a);
      for (Eigen::Index j = a; j < b; ++j) {
        if (j < N) dU(j, j - a) = 1;
        else ddU(j - N, j - a) = 1;
      }
      PetscCall(ti.StepTangent(r0, v0, dU, ddU));
      S.block(0, a, N, b - a) = dU;
      S.block(N, a, N, b - a) = ddU;
    }
  }
  auto product = [&](const auto &A, const auto &B, auto &C) -> PetscErrorCode {
    constexpr bool is_float = std::is_same_v<typename std::decay_t<decltype(C)>::Scalar, float>;
    PetscFunctionBeginUser;
    for (Eigen::Index s = 0; s < slices; ++s) {
      const Eigen::Index a = kc * s / slices, b = kc * (s + 1) / slices;
      if (pacer) PetscCall(pacer->Step());
      if (b > a) {
        if constexpr (is_float) GemmFloat(A, B.middleCols(c0 + a, b - a), C.middleCols(c0 + a, b - a));
        else Gemm(A, false, B.middleCols(c0 + a, b - a), C.middleCols(c0 + a, b - a));
      }
    }
    if (size > 1)
      PetscCallMPI(MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_DATATYPE_NULL, C.data(), counts.data(), displs.data(), is_float ? MPI_FLOAT : MPIU_REAL, comm));
    PetscFunctionReturn(0);
  };
  // Binary powering; P starts as the first power it needs (a copy, not a product by the identity):
  // 9 products of order 2N for 200 steps, each 2 (2N)^3 flops, through BLAS (core/dense_blas.h) on
  // the larger models (the 1420-DOF pad: 0.9 s a product against 1.1 s in Eigen).
  auto power = [&](auto &S, auto &P, auto &tmp) -> PetscErrorCode {
    PetscFunctionBeginUser;
    bool first = true;
    for (PetscInt e = steps; e > 0; e >>= 1) {
      if (e & 1) {
        if (first) P = S, first = false;
        else {
          PetscCall(product(P, S, tmp));
          P.swap(tmp);
        }
      }
      if (e > 1) {
        PetscCall(product(S, S, tmp));
        S.swap(tmp);
      }
    }
    if (first) P.setIdentity(n2, n2); // steps = 0
    PetscFunctionReturn(0);
  };
  if (!single) PetscCall(power(S, P, tmp));
  else {
    // Subnormal floats flushed to zero (FTZ, DAZ) for the products: a step tangent's entries far
    // along a structure fall below 1e-38 (the 400-cell chain), and on subnormal operands sgemm ran
    // 16 times slower (1.5 s a slice of 240 columns against 0.09 s). A preconditioner loses nothing.
    Eigen::MatrixXf Sf = S.cast<float>(), Pf, tf(n2, n2);
    S.resize(0, 0), tmp.resize(0, 0);
#if defined(__SSE2__)
    const unsigned int csr = _mm_getcsr();
    _mm_setcsr(csr | 0x8040); // FTZ (bit 15) and DAZ (bit 6)
    const PetscErrorCode ierr = power(Sf, Pf, tf);
    _mm_setcsr(csr);
    PetscCall(ierr);
#else
    PetscCall(power(Sf, Pf, tf));
#endif
    P = Pf.cast<double>();
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
