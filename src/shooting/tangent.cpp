// Flows and tangent flows of the shooting's period map (docs/method.md §6): the theta-method flow
// over one period from (Z0, T), with the trajectory stored for the tangents; the exact tangent of
// the period map along that stored flow; the dense bordered Jacobian built from it and the
// linearised-monodromy preconditioner. Used by Newton (newton.cpp) and by the Floquet multipliers
// (floquet/floquet.cpp).
#include "squeal/shooting/shooting.h"
#include "internal.h"
#include "squeal/integration/monodromy.h"
#include "squeal/core/dense_blas.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"

#include <algorithm>
#include <cmath>

namespace squeal {

PetscErrorCode Shooting::SetUpAt(PetscReal T)
{
  PetscFunctionBeginUser;
  // A new period means a new step size: (S1)-(S3) again. The one place shooting sets the step.
  if (T != T_setup_) {
    PetscCall(ti_->SetUp(*model_, T / steps));
    T_setup_ = T;
    ++setups_;
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Flow(Vec U, Vec dU, PetscReal T, Vec U1, Vec dU1, Eigen::VectorXd *r_end, std::vector<PetscInt> *transitions)
{
  Eigen::VectorXd r = r_init_;
  StepInfo        info;
  std::vector<int> prev, cur;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(shoot_ev::flow, 0, 0, 0, 0));
  PetscCall(SetUpAt(T));
  PetscCall(VecCopy(U, U1));
  PetscCall(VecCopy(dU, dU1));
  const PetscInt nc = model_->contacts.Size();
  // On several ranks the dense back end holds the whole model on each rank. Stepping it on every
  // rank at once made each step slower (the 31119-DOF pad's pre-periods 48.7 -> 71.8 s on 2 ranks:
  // the ranks' copies of the step matrices compete for the shared cache and memory), so rank 0 steps
  // the whole state and broadcasts it after each step; the others only keep their rows (and the
  // stored flow, which their share of a block of tangent columns reads).
  DenseStepKernel *kernel = size_ > 1 ? ti_->ReplicatedKernel() : nullptr;
  const PetscInt   nb     = 2 * N_ + r.size() + 2;
  PetscMPIInt      nbm;
  PetscCall(PetscMPIIntCast(nb, &nbm));
  if (kernel) {
    lead_.resize(nb);
    PetscCall(gather_(U1, lead_.head(N_)));
    PetscCall(gather_(dU1, lead_.segment(N_, N_)));
  }
  if (record_) {
    trU_.resize(N_, steps + 1), trdU_.resize(N_, steps + 1), trV_.resize(3 * nc, steps + 1), trR_.resize(3 * nc, steps);
    if (kernel) trU_.col(0) = lead_.head(N_), trdU_.col(0) = lead_.segment(N_, N_);
    else {
      PetscCall(Full(U1, trU_.col(0)));
      PetscCall(Full(dU1, trdU_.col(0)));
    }
    if (nc) {
      if (kernel) ti_->LocalOf(trdU_.col(0), vloc_);
      else PetscCall(ti_->Local(dU1, vloc_));
      trV_.col(0) = vloc_;
    }
  }
  if (transitions) {
    transitions->clear();
    ti_->Contact().Status(r, prev);
  }
  const PetscInt run = flow_stop_ > 0 ? std::min(flow_stop_, steps) : steps;
  flow_passes_       = 0;
  InterruptPacer pacer(comm_, "a period integration"); // one flow: minutes at FE scale
  for (PetscInt i = 0; i < run; ++i) {
    if (interruptible) PetscCall(pacer.Step());
    if (kernel) {
      if (rank_ == 0) {
        kernel->Step(lead_.data(), lead_.data() + N_, r, &info.contact);
        lead_.segment(2 * N_, r.size()) = r;
        lead_[nb - 2] = (PetscReal)info.contact.iterations, lead_[nb - 1] = info.contact.residual;
      }
      PetscCallMPI(MPI_Bcast(lead_.data(), nbm, MPIU_REAL, 0, comm_));
      if (rank_ != 0) {
        r                       = lead_.segment(2 * N_, r.size());
        info.contact.iterations = (PetscInt)lead_[nb - 2], info.contact.residual = lead_[nb - 1];
      }
      if (on_step_) { // it reads U1 and dU1
        PetscCall(SetOwnedRows(lead_.data(), U1));
        PetscCall(SetOwnedRows(lead_.data() + N_, dU1));
      }
    } else PetscCall(ti_->Step(U1, dU1, r, &info));
    flow_passes_ += info.contact.iterations;
    PetscCheck(r.size() == 0 || !std::isnan(info.contact.residual), comm_, PETSC_ERR_FP,
               "shooting: NaN in the flow at step %" PetscInt_FMT " of %" PetscInt_FMT " (T = %g s)", i + 1, steps, (double)T);
    if (on_step_) PetscCall(on_step_(i, U1, dU1, r));
    if (record_) {
      if (kernel) trU_.col(i + 1) = lead_.head(N_), trdU_.col(i + 1) = lead_.segment(N_, N_);
      else {
        PetscCall(Full(U1, trU_.col(i + 1)));
        PetscCall(Full(dU1, trdU_.col(i + 1)));
      }
      if (nc) {
        trR_.col(i) = r;
        if (kernel) ti_->LocalOf(trdU_.col(i + 1), vloc_);
        else PetscCall(ti_->Local(dU1, vloc_));
        trV_.col(i + 1) = vloc_;
      }
    }
    if (transitions) {
      ti_->Contact().Status(r, cur);
      for (size_t c = 0; c < cur.size(); ++c)
        if (cur[c] != prev[c]) transitions->insert(transitions->end(), {i, (PetscInt)c, (PetscInt)cur[c]});
      std::swap(prev, cur);
    }
  }
  if (kernel && !on_step_) {
    PetscCall(SetOwnedRows(lead_.data(), U1));
    PetscCall(SetOwnedRows(lead_.data() + N_, dU1));
  }
  // Rank 0's contact solver carried its predictor (and Newton's factor) through the flow, the others
  // none: the steps that every rank takes next (the dense monodromy, the phase bisection of the
  // Floquet multipliers) must start alike on every rank, or their reactions, statuses and collective
  // calls could part.
  if (kernel) ti_->ForgetContactHistory();
  CountSteps(run);
  if (r_end) *r_end = r;
  PetscCall(PetscLogEventEnd(shoot_ev::flow, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::VectorField(Vec U, Vec dU, const Eigen::VectorXd &r, Vec gU, Vec gdU)
{
  PetscFunctionBeginUser;
  // G(Z) = (dU, M^-1 (F + H r - C dU - K U))
  PetscCall(VecCopy(dU, gU));
  PetscCall(MatMult(model_->K, U, tmp_));
  PetscCall(VecAYPX(tmp_, -1.0, model_->F));
  if (model_->HasDamping()) {
    PetscCall(MatMult(model_->C, dU, gdU));
    PetscCall(VecAXPY(tmp_, -1.0, gdU));
  }
  if (r.size()) PetscCall(model_->contacts.AddForce(r.data(), tmp_));
  PetscCall(KSPSolve(mass_ksp_, tmp_, gdU));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::Full(Vec v, Eigen::Ref<Eigen::VectorXd> out)
{
  PetscFunctionBeginUser;
  if (size_ > 1) {
    PetscCall(gather_(v, out));
    PetscFunctionReturn(0);
  }
  const PetscScalar *a;
  PetscCall(VecGetArrayRead(v, &a));
  for (PetscInt i = 0; i < N_; ++i) out[i] = PetscRealPart(a[i]);
  PetscCall(VecRestoreArrayRead(v, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::ToNatural(Vec x, Eigen::VectorXd &z)
{
  PetscReal T;
  PetscFunctionBeginUser;
  z.resize(2 * N_ + 1);
  PetscCall(Unpack(x, wU_, wdU_, &T));
  PetscCall(Full(wU_, z.head(N_)));
  PetscCall(Full(wdU_, z.segment(N_, N_)));
  z[2 * N_] = T;
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::FromNatural(const Eigen::VectorXd &z, Vec x)
{
  PetscInt     lo, hi, nl;
  PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(VecGetOwnershipRange(model_->F, &lo, &hi));
  PetscCall(VecGetLocalSize(x, &nl));
  PetscCall(VecGetArray(x, &a));
  for (PetscInt i = 0; i < nloc_; ++i) a[i] = z[lo + i], a[nloc_ + i] = z[N_ + lo + i];
  if (nl > 2 * nloc_) a[2 * nloc_] = z[2 * N_];
  PetscCall(VecRestoreArray(x, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::EnsureTrajectory(Vec x)
{
  PetscBool same = PETSC_FALSE;
  PetscFunctionBeginUser;
  if (tr_valid_) PetscCall(VecEqual(x, trx_, &same));
  if (!same) {
    PetscCall(Residual(x, fp_));
    PetscCheck(tr_valid_, comm_, PETSC_ERR_PLIB, "shooting: no flow at this iterate (period outside (T0/2, 2 T0))");
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::TangentFlow(Vec x, const Eigen::MatrixXd &dZ0, const Eigen::RowVectorXd &dT, Eigen::MatrixXd &dZ1)
{
  const PetscInt N = N_;
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(shoot_ev::tangent, 0, 0, 0, 0));
  PetscCheck(ExactJacobian(), comm_, PETSC_ERR_SUP,
             "shooting: exact tangents need the dense theta back end (N = %" PetscInt_FMT " > -theta_dense_max) and -shoot_exact_jacobian",
             N);
  PetscCall(EnsureTrajectory(x));
  if (T_setup_ != trT_) { // a test or a difference product moved the step size since
    PetscCall(SetUpAt(trT_));
    for (auto &f : trF_) f.valid = false;
  }
  const PetscInt nc = model_->contacts.Size();
  bool           modal;
  PetscCall(ti_->ModalTangent(&modal));
  // Nodal tangents form their matrices at the first StepTangent, which on several ranks may run on
  // rank 0 alone (below): form them on every rank first, for StepTangentSources to agree.
  if (size_ > 1 && !modal) PetscCall(ti_->EnsureNodalTangent());
  if (!trC_ready_) {
    // The h-sources depend on the base flow only: once per stored trajectory, all steps in
    // matrix-matrix products (one step at a time, 6.2 s for 200 steps on the 400-cell chain).
    for (auto &f : trF_) f.valid = false;
    if (interruptible) PetscCall(InterruptPoint(comm_, "a tangent integration"));
    PetscCall(ti_->StepTangentSources(trU_.leftCols(steps), trdU_.leftCols(steps + 1), nc ? trR_.leftCols(steps) : trR_.leftCols(0), trC_));
    // The factors' memory along this flow, from each step's system order (a sliding point has 2
    // unknowns, not 3): 1.1 GB on the mostly sliding 451-point pad, where 9 n_c^2 words a step said 2.8.
    trF_mb_ = 0;
    for (PetscInt i = 0; i < steps && nc; ++i) {
      trF_mb_ += ti_->TangentFactorBytes(ti_->TangentSystemSize(trR_.col(i), trV_.col(i + 1))) / 1048576.0;
    }
    if (nc) PetscCall(PetscInfo(nullptr, "shooting: the step factors along this flow take %.1f MB (-shoot_tangent_cache_mb %g)\n", trF_mb_, (double)tangent_cache_mb));
    trCm_.resize(0, 0), trdUm_.resize(0, 0);
    trC_ready_ = true;
  }
  if (modal && trCm_.cols() != steps) {
    // Once per stored flow, as much as one column's nodal tangent integration.
    trCm_.noalias()  = ti_->ModalInverse() * trC_;
    trdUm_.noalias() = ti_->ModalInverse() * trdU_;
  }
  // On several ranks every rank holds the whole flow (the dense back end runs replicated) and the
  // columns are independent: each rank integrates its share and the shares are exchanged. Fewer
  // columns than ranks (the GMRES products) are integrated by rank 0 alone and broadcast, as the
  // forward flow is (Flow): the same work on every rank would only compete for memory.
  const Eigen::Index k     = dZ0.cols();
  const bool         split = size_ > 1 && k >= size_;
  dZ1.resize(2 * N, k);
  if (size_ == 1 || split) {
    const Eigen::Index c0 = split ? k * rank_ / size_ : 0, kc = split ? k * (rank_ + 1) / size_ - c0 : k;
    PetscCall(TangentColumns(comm_, c0, kc, dZ0, dT, modal, dZ1));
    if (split) PetscCall(ExchangeColumns(dZ1));
  } else {
    PetscErrorCode err = 0;
    if (rank_ == 0) err = TangentColumns(PETSC_COMM_SELF, 0, k, dZ0, dT, modal, dZ1);
    PetscCallMPI(MPI_Bcast(&err, 1, MPI_INT, 0, comm_));
    if (err && rank_ == 0) PetscCall(err);
    // On comm_, where this rank is not the first: rank 0 has said why (an interrupt, or the error).
    PetscCheck(!err, comm_, err, "shooting: the tangent integration on rank 0 failed");
    PetscMPIInt n;
    PetscCall(PetscMPIIntCast(dZ1.size(), &n));
    PetscCallMPI(MPI_Bcast(dZ1.data(), n, MPIU_REAL, 0, comm_));
  }
  ++evaluations_, ++tangents_;
  tangent_columns_ += dZ0.cols();
  PetscCall(PetscLogEventEnd(shoot_ev::tangent, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::TangentColumns(MPI_Comm poll, Eigen::Index c0, Eigen::Index kc, const Eigen::MatrixXd &dZ0, const Eigen::RowVectorXd &dT,
                                        bool modal, Eigen::MatrixXd &dZ1)
{
  const PetscInt N = N_, nc = model_->contacts.Size();
  PetscFunctionBeginUser;
  Eigen::MatrixXd dU, ddU;
  if (modal) {
    dU.resize(N, kc), ddU.resize(N, kc);
    Gemm(ti_->ModalInverse(), false, dZ0.middleCols(c0, kc).topRows(N), dU);
    Gemm(ti_->ModalInverse(), false, dZ0.middleCols(c0, kc).bottomRows(N), ddU);
  }
  else dU = dZ0.middleCols(c0, kc).topRows(N), ddU = dZ0.middleCols(c0, kc).bottomRows(N);
  Eigen::RowVectorXd dh = dT.segment(c0, kc) / (PetscReal)steps;
  ThetaIntegrator::StepData sd{&sdUi_, &sdUn_, &sc_, &svs_};
  sd.modal = modal;
  const Eigen::MatrixXd &dUs = modal ? trdUm_ : trdU_, &Cs = modal ? trCm_ : trC_;
  // One-column products (GMRES) would refactorise each step's closed-point system every time:
  // keep the factors along this flow while they fit in -shoot_tangent_cache_mb.
  const bool cache = nc > 0 && trF_mb_ <= tangent_cache_mb;
  if (cache && (PetscInt)trF_.size() != steps) trF_.assign(steps, {});
  InterruptPacer pacer(poll, "a tangent integration");
  for (PetscInt i = 0; i < steps; ++i) {
    if (interruptible) PetscCall(pacer.Step());
    sd.factor = cache ? &trF_[i] : nullptr;
    sdUi_ = dUs.col(i), sdUn_ = dUs.col(i + 1), sc_ = Cs.col(i);
    if (nc) sr_ = trR_.col(i), svs_ = trV_.col(i), sve_ = trV_.col(i + 1);
    else sr_.resize(0), svs_.resize(0), sve_.resize(0);
    PetscCall(ti_->StepTangent(sr_, sve_, sd, dh, dU, ddU));
  }
  if (modal) {
    Gemm(ti_->ModalBasis(), false, dU, dZ1.middleCols(c0, kc).topRows(N));
    Gemm(ti_->ModalBasis(), false, ddU, dZ1.middleCols(c0, kc).bottomRows(N));
  } else {
    dZ1.middleCols(c0, kc).topRows(N)    = dU;
    dZ1.middleCols(c0, kc).bottomRows(N) = ddU;
  }
  PetscFunctionReturn(0);
}

// Rank r computed columns [k r / p, k (r + 1) / p) of Z in place; every rank gets them all.
PetscErrorCode Shooting::ExchangeColumns(Eigen::MatrixXd &Z) const
{
  const Eigen::Index       k = Z.cols(), rows = Z.rows();
  std::vector<PetscMPIInt> counts(size_), displs(size_);
  PetscFunctionBeginUser;
  for (PetscMPIInt r = 0; r < size_; ++r) {
    const Eigen::Index a = k * r / size_, b = k * (r + 1) / size_;
    PetscCall(PetscMPIIntCast(rows * a, &displs[r]));
    PetscCall(PetscMPIIntCast(rows * (b - a), &counts[r]));
  }
  PetscCallMPI(MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_DATATYPE_NULL, Z.data(), counts.data(), displs.data(), MPIU_REAL, comm_));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::BuildDenseJacobian(Vec x)
{
  const PetscInt n2 = 2 * N_;
  PetscFunctionBeginUser;
  Eigen::MatrixXd    E = Eigen::MatrixXd::Identity(n2, n2 + 1), D;
  Eigen::RowVectorXd dT = Eigen::RowVectorXd::Zero(n2 + 1);
  dT[n2] = 1.0;
  PetscCall(TangentFlow(x, E, dT, D));
  Jd_.setZero(n2 + 1, n2 + 1);
  Jd_.topRows(n2) = D;
  Jd_.topLeftCorner(n2, n2).diagonal().array() -= 1.0;
  if (anchored_) {
    Eigen::VectorXd g(n2);
    PetscCall(Full(GaU_, g.head(N_)));
    PetscCall(Full(GadU_, g.tail(N_)));
    Jd_.row(n2).head(n2) = g.transpose();
  }
  jlu_.compute(Jd_);
  PetscCall(VecCopy(x, jx_));
  PetscFunctionReturn(0);
}

PetscErrorCode Shooting::BuildLinearPreconditioner(Vec x)
{
  const PetscInt n2 = 2 * N_;
  PetscFunctionBeginUser;
  // -log_view's ShootLinearPC: the monodromy (at the first Jacobian of a start) and the factor or
  // its update, not the period column's tangent integration between them (ShootTangentFlow). The
  // monodromy first: its temporaries (five matrices of order 2N) are gone before the tangent
  // integration keeps the step factors of the new flow (-shoot_tangent_cache_mb).
  if (Mlin_.rows() != n2) {
    // The steady-sliding linearisation's monodromy (integration/monodromy.h), at the equilibrium
    // reactions: every point closed and sliding, slip direction against V_c.
    PetscCall(PetscLogEventBegin(shoot_ev::linear_pc, 0, 0, 0, 0));
    // In single precision from 2N = 1024 on (-shoot_linear_pc_single), where its 9 products of order
    // 2N take seconds each (the size-1 brake, 2N = 3 716: 2.3 s in double); below, it costs little
    // and the small models keep their iterates.
    PetscCall(LinearMonodromy(*ti_, r_init_, steps, Mlin_, size_ > 1 ? comm_ : PETSC_COMM_SELF, interruptible ? "the linear preconditioner's monodromy" : nullptr,
                              linear_pc_single && n2 >= 1024));
    PetscCall(Unpack(x, aU_, adU_, &Mlin_T_));
    jpc_.Reset();
    PetscCall(PetscLogEventEnd(shoot_ev::linear_pc, 0, 0, 0, 0));
  }
  // The period column is exact (one tangent integration of one column); the border is the anchor's.
  Eigen::MatrixXd    dT1;
  if (ExactJacobian()) {
    Eigen::RowVectorXd dT = Eigen::RowVectorXd::Ones(1);
    PetscCall(TangentFlow(x, Eigen::MatrixXd::Zero(n2, 1), dT, dT1));
  } else {
    // Difference products: the period column by the same difference as the other products.
    Eigen::VectorXd e = Eigen::VectorXd::Zero(n2 + 1), out;
    e[n2]             = 1.0;
    Vec ev, jv;
    PetscCall(VecDuplicate(x, &ev));
    PetscCall(VecDuplicate(x, &jv));
    PetscCall(FromNatural(e, ev));
    PetscCall(JacobianProduct(x, ev, jv));
    PetscCall(ToNatural(jv, out));
    PetscCall(VecDestroy(&ev));
    PetscCall(VecDestroy(&jv));
    dT1 = out.head(n2);
  }
  PetscCall(PetscLogEventBegin(shoot_ev::linear_pc, 0, 0, 0, 0));
  Eigen::VectorXd col(n2 + 1), row = Eigen::VectorXd::Zero(n2 + 1);
  col.head(n2) = dT1.col(0);
  if (anchored_) {
    PetscCall(Full(GaU_, row.head(N_)));
    PetscCall(Full(GadU_, row.segment(N_, N_)));
    col[n2] = 0;
  } else row[n2] = col[n2] = 1.0; // no phase row yet: keep the preconditioner regular
  // Mlin - I is the same at every Newton iteration of a start; only the border moves. The first
  // Jacobian factorises the whole, the later ones update its border (BorderedLU). Not from a
  // factor without the phase row: Mlin - I alone can be nearly singular (a multiplier of the
  // linearisation near 1 close to the threshold), and the update would carry that into every solve.
  if (!jpc_.Factored() || !jpc_anchored_ || !jpc_.SetBorder(col, row)) {
    Eigen::MatrixXd J(n2 + 1, n2 + 1);
    J.topLeftCorner(n2, n2) = Mlin_;
    J.topLeftCorner(n2, n2).diagonal().array() -= 1.0;
    J.col(n2)               = col;
    J.row(n2)               = row.transpose();
    jpc_.Factor(std::move(J));
    jpc_anchored_ = anchored_;
  }
  PetscCall(PetscLogEventEnd(shoot_ev::linear_pc, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

} // namespace squeal
