// The transient's bookkeeping (transient_ledger.h): the energy ledgers, the records on rank 0.
#include "transient_ledger.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace squeal {
namespace transient {

namespace {

// The dense ledger for the step kernel's fixed sizes, else null.
std::unique_ptr<Ledger> MakeDenseLedger(const Model &model, const PetscReal *u, const PetscReal *du, PetscReal h)
{
  const PetscInt n = model.Size(), nc = model.contacts.Size();
  if (n == 3 && nc == 1) return std::make_unique<DenseLedger<3, 1>>(model, u, du, h);
  if (n == 12 && nc == 4) return std::make_unique<DenseLedger<12, 4>>(model, u, du, h);
  return nullptr;
}

// The quadratic form x^T A x of a symmetric part, from its lower triangle packed column by column
// (A_jj, A_{j+1,j}, ..., A_{N-1,j}): half the words of the full matrix, read as contiguous dots.
// A reduced FE model's M, K, C are dense but stored as AIJ: three AIJ products (12 bytes and an
// index per entry) were 10 of the 38 ms a step of the 1420-DOF pad's transient.
class PackedForm {
public:
  // Packs sym(A) = (A + A^T) / 2 (one rank): the form is the same, as x^T A x = x^T sym(A) x.
  PetscErrorCode Set(Mat A, PetscInt n)
  {
    PetscFunctionBeginUser;
    n_ = n;
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(n, n);
    for (PetscInt i = 0; i < n; ++i) {
      PetscInt           nc;
      const PetscInt    *cj;
      const PetscScalar *v;
      PetscCall(MatGetRow(A, i, &nc, &cj, &v));
      for (PetscInt k = 0; k < nc; ++k) D(i, cj[k]) += PetscRealPart(v[k]);
      PetscCall(MatRestoreRow(A, i, &nc, &cj, &v));
    }
    PetscCallCXX(lower_.resize((size_t)n * (size_t)(n + 1) / 2));
    size_t o = 0;
    for (PetscInt j = 0; j < n; ++j) {
      lower_[o++] = D(j, j);
      for (PetscInt i = j + 1; i < n; ++i) lower_[o++] = 0.5 * (D(i, j) + D(j, i));
    }
    PetscFunctionReturn(0);
  }
  bool      Empty() const { return lower_.empty(); }
  PetscReal operator()(const PetscReal *x) const
  {
    using Map    = Eigen::Map<const Eigen::VectorXd>;
    PetscReal s  = 0;
    size_t    o  = 0;
    for (PetscInt j = 0; j < n_; ++j) {
      const PetscInt m = n_ - j - 1;
      s += x[j] * (lower_[o] * x[j] + 2 * Map(lower_.data() + o + 1, m).dot(Map(x + j + 1, m)));
      o += (size_t)m + 1;
    }
    return s;
  }
  // Packed when the matrix is dense enough that reading half of it beats its AIJ product: AIJ
  // streams 12 bytes an entry, the packed triangle 4 bytes per entry of the full matrix.
  static PetscErrorCode Pays(Mat A, PetscInt n, bool *pays)
  {
    MatInfo info;
    PetscFunctionBeginUser;
    PetscCall(MatGetInfo(A, MAT_LOCAL, &info));
    *pays = 3 * info.nz_used >= (double)n * (double)n;
    PetscFunctionReturn(0);
  }

private:
  PetscInt               n_ = 0;
  std::vector<PetscReal> lower_;
};

// Any other case (other sizes, run-time-sized kernel, sparse back end, several ranks): the same sums
// with PETSc's products, dots over this rank's rows only (no reduction), and H r from this rank's
// rows of H (no communication). On one rank a matrix dense enough (a reduced model's) gives its
// form from its packed lower triangle instead (PackedForm).
class VecLedger final : public Ledger {
public:
  static PetscErrorCode Create(const Model &model, Vec U, Vec dU, PetscReal h, std::unique_ptr<Ledger> &out)
  {
    PetscInt    lo, hi;
    PetscMPIInt size;
    PetscFunctionBeginUser;
    auto l = std::make_unique<VecLedger>();
    l->model_ = &model, l->U_ = U, l->dU_ = dU, l->h_ = h, l->n_ = model.Size();
    PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)U), &size));
    if (size == 1) {
      const std::pair<Mat, PackedForm *> mats[3] = {{model.M, &l->pM_}, {model.K, &l->pK_}, {model.HasDamping() ? (Mat)model.C : nullptr, &l->pC_}};
      for (const auto &[A, form] : mats) {
        bool pays = false;
        if (A) PetscCall(PackedForm::Pays(A, l->n_, &pays));
        if (pays) PetscCall(form->Set(A, l->n_));
      }
    }
    PetscCall(VecDuplicate(U, l->U0_.out()));
    PetscCall(VecCopy(U, l->U0_));
    PetscCall(VecDuplicate(U, l->start_.out()));
    PetscCall(VecCopy(U, l->start_));
    PetscCall(VecDuplicate(U, l->dq_.out()));
    PetscCall(VecDuplicate(U, l->cq_.out()));
    PetscCall(VecGetOwnershipRange(U, &lo, &hi));
    for (PetscInt c = 0; c < model.contacts.Size(); ++c)
      for (int d = 0; d < 3; ++d)
        model.contacts.ForEachEntry(c, d, [&](PetscInt j, PetscReal v) {
          if (j >= lo && j < hi) l->h_rows_.push_back({j - lo, 3 * c + d, v});
        });
    out = std::move(l);
    PetscFunctionReturn(0);
  }

  PetscErrorCode Work(const Eigen::VectorXd &r) override
  {
    const PetscScalar *dq;
    PetscReal          w = 0; // LocalDot sets it; the compiler cannot see that through PetscCall
    PetscFunctionBeginUser;
    PetscCall(VecWAXPY(dq_, -1.0, U0_, U_)); // h ub
    PetscCall(VecCopy(U_, U0_));
    if (model_->HasDamping()) {
      PetscCall(Form(model_->C, pC_, dq_, &w));
      damping_ += w / h_;
    }
    PetscCall(VecGetArrayRead(dq_, &dq));
    w = 0;
    for (const HEntry &e : h_rows_) w += PetscRealPart(dq[e.row]) * e.value * r[e.col];
    PetscCall(VecRestoreArrayRead(dq_, &dq));
    reactions_ += w;
    PetscFunctionReturn(0);
  }

  PetscErrorCode Totals(PetscReal s[5]) override
  {
    PetscFunctionBeginUser;
    PetscCall(Form(model_->M, pM_, dU_, &s[0]));
    PetscCall(Form(model_->K, pK_, U_, &s[1]));
    s[0] *= 0.5, s[1] *= 0.5;
    s[2] = damping_, s[3] = reactions_;
    PetscCall(VecWAXPY(cq_, -1.0, start_, U_));
    PetscCall(LocalDot(cq_, model_->F, &s[4]));
    PetscFunctionReturn(0);
  }

private:
  // This rank's part of x^T A x.
  PetscErrorCode Form(Mat A, const PackedForm &packed, Vec x, PetscReal *d)
  {
    PetscFunctionBeginUser;
    if (packed.Empty()) {
      PetscCall(MatMult(A, x, cq_));
      PetscCall(LocalDot(x, cq_, d));
      PetscFunctionReturn(0);
    }
    const PetscScalar *a;
    PetscCall(VecGetArrayRead(x, &a));
    *d = packed(a);
    PetscCall(VecRestoreArrayRead(x, &a));
    PetscFunctionReturn(0);
  }
  static PetscErrorCode LocalDot(Vec x, Vec y, PetscReal *d)
  {
    const PetscScalar *a, *b;
    PetscInt           n;
    PetscFunctionBeginUser;
    PetscCall(VecGetLocalSize(x, &n));
    PetscCall(VecGetArrayRead(x, &a));
    PetscCall(VecGetArrayRead(y, &b));
    PetscReal s = 0;
    for (PetscInt i = 0; i < n; ++i) s += PetscRealPart(a[i] * PetscConj(b[i]));
    PetscCall(VecRestoreArrayRead(y, &b));
    PetscCall(VecRestoreArrayRead(x, &a));
    *d = s;
    PetscFunctionReturn(0);
  }

  struct HEntry {
    PetscInt  row, col; // local row of U, local reaction index 3 c + direction
    PetscReal value;
  };
  const Model        *model_ = nullptr;
  Vec                 U_ = nullptr, dU_ = nullptr;
  PetscReal           h_ = 0;
  VecH                U0_, start_, dq_, cq_;
  std::vector<HEntry> h_rows_;
  PackedForm          pM_, pK_, pC_; // empty: the AIJ product
};

// For a caller that reads no energy (the statistical steady state): the works and energies cost three
// products with M, C, K per step, 21 % of a step of the 782-DOF reduced brake, for numbers nobody
// reads. Only the NaN test of the records is kept, on the state itself: Totals gives a NaN kinetic
// energy when U or dU has a non-finite entry on this rank, zeros otherwise.
class StateLedger final : public Ledger {
public:
  StateLedger(Vec U, Vec dU, PetscInt n) : U_(U), dU_(dU) { n_ = n; }
  PetscErrorCode Work(const Eigen::VectorXd &) override { return 0; }
  PetscErrorCode Totals(PetscReal s[5]) override
  {
    const PetscScalar *a;
    PetscInt           n;
    PetscReal          sum = 0;
    PetscFunctionBeginUser;
    for (Vec x : {U_, dU_}) {
      PetscCall(VecGetLocalSize(x, &n));
      PetscCall(VecGetArrayRead(x, &a));
      for (PetscInt i = 0; i < n; ++i) sum += 0 * PetscRealPart(a[i]); // NaN or inf anywhere: NaN
      PetscCall(VecRestoreArrayRead(x, &a));
    }
    s[0] = sum, s[1] = s[2] = s[3] = s[4] = 0;
    PetscFunctionReturn(0);
  }

private:
  Vec U_, dU_;
};

// Copies v, gathered on rank 0, to out (rank 0 only).
PetscErrorCode Gather(VecScatter sc, Vec v, Vec z, PetscReal *out)
{
  PetscInt           n;
  const PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(sc, v, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, v, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetLocalSize(z, &n));
  PetscCall(VecGetArrayRead(z, &a));
  for (PetscInt i = 0; i < n; ++i) out[i] = PetscRealPart(a[i]);
  PetscCall(VecRestoreArrayRead(z, &a));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode CreateLedger(const Model &model, const PetscReal *u, const PetscReal *du, bool fixed_size, Vec U, Vec dU, PetscReal h,
                            std::unique_ptr<Ledger> &out, bool energy)
{
  PetscFunctionBeginUser;
  out.reset();
  if (!energy) {
    out = std::make_unique<StateLedger>(U, dU, model.Size());
    PetscFunctionReturn(0);
  }
  if (u && du && fixed_size) out = MakeDenseLedger(model, u, du, h);
  if (!out) PetscCall(VecLedger::Create(model, U, dU, h, out));
  PetscFunctionReturn(0);
}

PetscErrorCode Bookkeeping::SetUp(const Model &model, bool fixed_size, Vec U, Vec dU, const PetscReal *u, const PetscReal *du,
                                  const Eigen::VectorXd &r)
{
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank_));
  PetscCallMPI(MPI_Comm_size(comm_, &size_));
  U_ = U, dU_ = dU, u_ = u, du_ = du;
  PetscCall(CreateLedger(model, u, du, fixed_size, U, dU, res_.h, ledger_, energy_));
  if (size_ > 1) PetscCall(VecScatterCreateToZero(U, sc_.out(), z_.out()));
  status_.assign(model.contacts.Size(), kSlip);
  PetscCall(Totals());
  E0_ = tot_[0] + tot_[1];
  PetscCall(Record(0, 0.0, r));
  PetscFunctionReturn(0);
}

PetscErrorCode Bookkeeping::Totals()
{
  PetscFunctionBeginUser;
  PetscCall(ledger_->Totals(tot_));
  if (size_ > 1) PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, tot_, 5, MPIU_REAL, MPIU_SUM, comm_));
  PetscFunctionReturn(0);
}

PetscErrorCode Bookkeeping::Record(PetscInt step, PetscReal t, const Eigen::VectorXd &r)
{
  const PetscInt   N = recs_.N, nc = recs_.nc;
  TransientResult &res = res_;
  PetscFunctionBeginUser;
  const size_t k = recs_.n, s = recs_.Slot(k);
  if (size_ > 1) {
    PetscCall(Gather(sc_, U_, z_, res.U.data() + s * N));
    PetscCall(Gather(sc_, dU_, z_, res.V.data() + s * N));
    if (rank_ == 0) std::copy_n(r.data(), 3 * nc, res.R.data() + s * 3 * nc);
  } else ledger_->Copy(u_, du_, r, res.U.data() + s * N, res.V.data() + s * N, res.R.data() + s * 3 * nc);
  if (rank_ == 0) {
    res.t[k]        = t;
    PetscInt *st    = res.status.data() + s * nc;
    for (PetscInt c = 0; c < nc; ++c) st[c] = status_[c];
    PetscReal *e = res.energy.data() + 4 * k;
    if (energy_) e[0] = tot_[0] + tot_[1], e[1] = tot_[2], e[2] = tot_[3], e[3] = tot_[4];
    else std::fill_n(e, 4, NAN); // not computed
    recs_.n++;
    if (hook_) {
      TransientRecord rec;
      rec.index = k, rec.step = step, rec.t = t, rec.energy = e, rec.status = st;
      rec.U = res.U.data() + s * N, rec.V = res.V.data() + s * N, rec.R = res.R.data() + s * 3 * nc;
      PetscCall(hook_(res, rec));
    }
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Bookkeeping::Monitor(PetscInt i, PetscInt fp_its) const
{
  PetscInt cnt[3] = {0, 0, 0};
  PetscFunctionBeginUser;
  for (int s : status_) cnt[s]++;
  const PetscReal E = tot_[0] + tot_[1], bal = (E - E0_) - (tot_[3] + tot_[4] - tot_[2]);
  if (!energy_) {
    PetscCall(PetscPrintf(comm_,
                          "  step %8" PetscInt_FMT " t = %.6e s  open/stick/slip %" PetscInt_FMT "/%" PetscInt_FMT "/%" PetscInt_FMT
                          "  fp its %3" PetscInt_FMT "\n",
                          i, (double)(i * res_.h), cnt[0], cnt[1], cnt[2], fp_its));
    PetscFunctionReturn(0);
  }
  PetscCall(PetscPrintf(comm_,
                        "  step %8" PetscInt_FMT " t = %.6e s  open/stick/slip %" PetscInt_FMT "/%" PetscInt_FMT "/%" PetscInt_FMT
                        "  fp its %3" PetscInt_FMT "  E = %.6e J  balance %.3e J\n",
                        i, (double)(i * res_.h), cnt[0], cnt[1], cnt[2], fp_its, (double)E, (double)bal));
  PetscFunctionReturn(0);
}

} // namespace transient
} // namespace squeal
