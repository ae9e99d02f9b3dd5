// The bookkeeping of a transient run (TransientAnalysis::Run, transient.cpp): the energy ledger and
// the records on rank 0 (the points' statuses in them set by Run). Shared by transient.cpp and
// transient_ledger.cpp; not installed.
//
// Two paths. One rank: the state lives in arrays of Run that the integrator updates in place, and
// the ledger and the records read them with no PETSc call per step (the dense ledger, with loops
// of compile-time length, for the step kernel's fixed sizes). Several ranks: the sums are each
// rank's parts, reduced only where a record or a monitor line needs them (no step makes a
// collective call), and the records are gathered to rank 0.
#pragma once

#include "squeal/integration/transient.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <vector>

namespace squeal {
namespace transient {

// The energy bookkeeping of a run (see transient.h): the works after every step, the energies at
// the records. The sums are this rank's parts. With ub = (U1 - U0) / h:
//   W_damping += h ub^T C ub,  W_reactions += h ub^T H r,  E = dU^T M dU / 2 + U^T K U / 2,
//   W_load = F^T (U - U_start), the sum of the steps' h ub^T F (a constant F: it telescopes).
class Ledger {
public:
  virtual ~Ledger() = default;
  // Adds the works of the step that just ended (previous state to the current one, reactions r:
  // 3 n_c local values, the same on every rank).
  virtual PetscErrorCode Work(const Eigen::VectorXd &r) = 0;
  // This rank's parts of E_kinetic, E_elastic, W_damping, W_reactions, W_load at the current state.
  virtual PetscErrorCode Totals(PetscReal s[5]) = 0;
  // One rank: the state (U, dU: N values each, from the arrays of Run) and r (3 n_c) into a record.
  virtual void Copy(const PetscReal *u, const PetscReal *du, const Eigen::VectorXd &r, PetscReal *U, PetscReal *V, PetscReal *R)
  {
    std::copy_n(u, n_, U);
    std::copy_n(du, n_, V);
    std::copy_n(r.data(), r.size(), R);
  }

protected:
  PetscReal damping_ = 0, reactions_ = 0; // cumulative works, this rank's part (J)
  PetscInt n_ = 0;
};

// Loops of compile-time length unrolled in full: GCC's -O2 keeps a 3-iteration loop, at several
// times the instructions of its body on 3 x 3 data (run-time lengths are unrolled in blocks).
#if defined(__clang__)
  #define SQUEAL_UNROLL _Pragma("clang loop unroll_count(16)")
#elif defined(__GNUC__)
  #define SQUEAL_UNROLL _Pragma("GCC unroll 16")
#else
  #define SQUEAL_UNROLL
#endif

// One rank, dense back end, the sizes the step kernel is compiled for (integration/step_kernel.h):
// the state lives in arrays that the integrator updates in place (Vecs over them, see Run), and the
// bookkeeping reads them as a hand-written loop would, with dense copies of M, C, K (row-major), F
// and H^T and loops of compile-time length: no PETSc call per step. Products row by row and sums
// in index order, as PETSc's MatMult and VecDot (round-off apart: FMA). Any other model takes
// VecLedger: dense N x N products per step cost far more than sparse ones for larger N (a 180-DOF
// chain's transient took 12.4 s against 5.1 s). Here, not in transient_ledger.cpp, so that Run's
// loop for these sizes (transient.cpp) inlines WorkAt and TotalsAt: the virtual Work and Totals
// cost a call, a frame and the reloads of every member per step.
template <int N, int NC>
class DenseLedger final : public Ledger {
public:
  static constexpr int kN = N, kNC = NC; // for Run's loop on one rank (transient.cpp)

private:
  static constexpr int M = NC == Eigen::Dynamic ? Eigen::Dynamic : 3 * NC;
  using MatN             = Eigen::Matrix<PetscReal, N, N, N == 1 ? Eigen::ColMajor : Eigen::RowMajor>;
  using MatH             = Eigen::Matrix<PetscReal, M, N, N == 1 ? Eigen::ColMajor : Eigen::RowMajor>;
  using VecN             = Eigen::Matrix<PetscReal, N, 1>;

public:
  DenseLedger(const Model &model, const PetscReal *u, const PetscReal *du, PetscReal h)
    : nc_(model.contacts.Size()), h_(h), damped_(model.HasDamping()), u_(u), du_(du)
  {
    n_ = model.Size();
    M_ = DenseOf(model.M);
    C_ = damped_ ? DenseOf(model.C) : MatN::Zero(n_, n_);
    K_ = DenseOf(model.K);
    Ht_.setZero(3 * nc_, n_);
    for (PetscInt c = 0; c < nc_; ++c)
      for (int d = 0; d < 3; ++d) model.contacts.ForEachEntry(c, d, [&](PetscInt j, PetscReal v) { Ht_(3 * c + d, j) += v; });
    F_.resize(n_);
    const PetscScalar *f;
    PetscCallAbort(PETSC_COMM_SELF, VecGetArrayRead(model.F, &f));
    for (PetscInt i = 0; i < n_; ++i) F_[i] = PetscRealPart(f[i]);
    PetscCallAbort(PETSC_COMM_SELF, VecRestoreArrayRead(model.F, &f));
    diag_m_ = IsDiagonal(M_), diag_c_ = IsDiagonal(C_);
    ht_identity_ = Ht_.rows() == Ht_.cols() && Ht_ == MatH::Identity(Ht_.rows(), Ht_.cols());
    fidx_.resize(n_);
    for (PetscInt i = 0; i < n_; ++i)
      if (F_[i] != 0) fidx_[nf_++] = (int)i;
    prev_  = Eigen::Map<const VecN>(u_, n_);
    start_ = prev_;
    dq_.resize(n_);
  }

  PetscErrorCode Work(const Eigen::VectorXd &r) override
  {
    WorkAt(u_, r.data());
    return 0;
  }
  PetscErrorCode Totals(PetscReal s[5]) override
  {
    TotalsAt(u_, du_, s);
    return 0;
  }

  // The works of the step that ended at state u with reactions r (Work on any state array).
  EIGEN_ALWAYS_INLINE void WorkAt(const PetscReal *u, const PetscReal *r)
  {
    const PetscInt n = Size(), m = 3 * NcSize();
    VecN           dq_l;
    PetscReal     *dq = N == Eigen::Dynamic ? dq_.data() : dq_l.data();
    SQUEAL_UNROLL
    for (PetscInt i = 0; i < n; ++i) dq[i] = u[i] - prev_[i], prev_[i] = u[i]; // h ub
    if (damped_) damping_ += (diag_c_ ? Diagonal(C_, dq) : Quadratic(C_, dq)) / h_;
    PetscReal wr = 0;
    if (ht_identity_) { // H = I (the 3-DOF model): Row(Ht_, k, dq) is dq[k], exactly
      SQUEAL_UNROLL
      for (PetscInt k = 0; k < m; ++k) wr += dq[k] * r[k];
    } else {
      SQUEAL_UNROLL
      for (PetscInt k = 0; k < m; ++k) wr += Row(Ht_, k, dq) * r[k];
    }
    reactions_ += wr;
  }

  // Totals at the state (u, du).
  EIGEN_ALWAYS_INLINE void TotalsAt(const PetscReal *u, const PetscReal *du, PetscReal s[5]) const
  {
    PetscReal wf = 0;
    for (int q = 0; q < nf_; ++q) { // F's non-zeros only, in index order: the zeros add nothing to a finite sum
      const int i = fidx_[q];
      wf += F_[i] * (u[i] - start_[i]);
    }
    s[0] = 0.5 * (diag_m_ ? Diagonal(M_, du) : Quadratic(M_, du));
    s[1] = 0.5 * Quadratic(K_, u);
    s[2] = damping_, s[3] = reactions_, s[4] = wf;
  }

  void Copy(const PetscReal *u, const PetscReal *du, const Eigen::VectorXd &r, PetscReal *U, PetscReal *V, PetscReal *R) override
  {
    CopyAt(u, du, r.data(), U, V, R);
  }
  EIGEN_ALWAYS_INLINE void CopyAt(const PetscReal *u, const PetscReal *du, const PetscReal *r, PetscReal *U, PetscReal *V, PetscReal *R) const
  {
    // memcpy: the compiler may not assume that the record's slots and the state do not overlap,
    // so the loops copied a value at a time (fixed sizes: a few vector moves here).
    std::memcpy(U, u, sizeof(PetscReal) * Size());
    std::memcpy(V, du, sizeof(PetscReal) * Size());
    std::memcpy(R, r, sizeof(PetscReal) * 3 * NcSize());
  }

private:
  PetscInt Size() const { return N == Eigen::Dynamic ? n_ : N; }
  PetscInt NcSize() const { return NC == Eigen::Dynamic ? nc_ : NC; }
  template <class A>
  EIGEN_ALWAYS_INLINE PetscReal Row(const A &a, PetscInt i, const PetscReal *x) const
  {
    const PetscInt n = Size();
    PetscReal      s = 0;
    SQUEAL_UNROLL
    for (PetscInt j = 0; j < n; ++j) s += a(i, j) * x[j];
    return s;
  }
  EIGEN_ALWAYS_INLINE PetscReal Quadratic(const MatN &a, const PetscReal *x) const // x^T a x
  {
    const PetscInt n = Size();
    PetscReal      s = 0;
    SQUEAL_UNROLL
    for (PetscInt i = 0; i < n; ++i) s += x[i] * Row(a, i, x);
    return s;
  }
  // x^T a x for a diagonal a: Quadratic's sums without its products by the zeros, which change no
  // finite sum (fma(0, x, s) = s), so the same number in a third of the instructions (M and C of the
  // 3-DOF model are m I and c I).
  EIGEN_ALWAYS_INLINE PetscReal Diagonal(const MatN &a, const PetscReal *x) const
  {
    const PetscInt n = Size();
    PetscReal      s = 0;
    SQUEAL_UNROLL
    for (PetscInt i = 0; i < n; ++i) s += x[i] * (a(i, i) * x[i]);
    return s;
  }
  static bool IsDiagonal(const MatN &a)
  {
    for (Eigen::Index i = 0; i < a.rows(); ++i)
      for (Eigen::Index j = 0; j < a.cols(); ++j)
        if (i != j && a(i, j) != 0) return false;
    return true;
  }
  MatN DenseOf(Mat A) const
  {
    MatN D = MatN::Zero(n_, n_);
    for (PetscInt i = 0; i < n_; ++i) {
      PetscInt           nz;
      const PetscInt    *cj;
      const PetscScalar *v;
      PetscCallAbort(PETSC_COMM_SELF, MatGetRow(A, i, &nz, &cj, &v));
      for (PetscInt k = 0; k < nz; ++k) D(i, cj[k]) = PetscRealPart(v[k]);
      PetscCallAbort(PETSC_COMM_SELF, MatRestoreRow(A, i, &nz, &cj, &v));
    }
    return D;
  }

  const PetscInt   nc_;
  const PetscReal  h_;
  const bool       damped_;
  bool             diag_m_ = false, diag_c_ = false; // M, C diagonal: Diagonal for Quadratic
  bool             ht_identity_ = false;             // H^T = I: no product by it in the works
  Eigen::Matrix<int, N, 1> fidx_;                    // the indices of F's non-zeros, nf_ of them
  int              nf_ = 0;
  const PetscReal *u_, *du_;
  MatN             M_, C_, K_;
  MatH             Ht_;
  VecN             F_, prev_, start_, dq_;
};

// The ledger of a run: with u, du (one rank, the arrays behind U and dU) and a fixed-size step
// kernel, the dense ledger for the kernel's sizes when there is one; else the one on Vecs. Without
// energy, the ledger that only tests the state for NaN (no product with M, C or K).
PetscErrorCode CreateLedger(const Model &model, const PetscReal *u, const PetscReal *du, bool fixed_size, Vec U, Vec dU, PetscReal h,
                            std::unique_ptr<Ledger> &out, bool energy = true);

// The records on rank 0, sized for the whole run before it starts (a record is then a few stores,
// with no growth test per value) and cut to the records written when Run leaves, by any path.
// Streamed (res.streamed): t and energy for every record, the state arrays for one, overwritten.
struct RecordSink {
  TransientResult &res;
  const PetscInt   N, nc;
  bool             on = false; // rank 0
  size_t           n  = 0;     // records written
  RecordSink(TransientResult &r, PetscInt N_, PetscInt nc_) : res(r), N(N_), nc(nc_) {}
  ~RecordSink() { Cut(); }
  void Size(size_t records)
  {
    on = true;
    Resize(records);
  }
  void Cut()
  {
    if (on) Resize(n);
  }
  // Where record k's state goes.
  size_t Slot(size_t k) const { return res.streamed ? 0 : k; }
  void   Resize(size_t records)
  {
    const size_t states = res.streamed ? std::min<size_t>(records, 1) : records;
    res.t.resize(records);
    res.U.resize(states * N);
    res.V.resize(states * N);
    res.R.resize(states * 3 * nc);
    res.status.resize(states * nc);
    res.energy.resize(records * 4);
  }
};

// The energies, works and records of a run on every rank: the totals over all ranks (one
// reduction), the record on rank 0 (gathered there from several ranks), the monitor line. Run
// calls them after the steps that are recorded or monitored, and sets the statuses in between
// (Status(): the points' statuses that the next record takes).
class Bookkeeping {
public:
  using Hook = std::function<PetscErrorCode(const TransientResult &, const TransientRecord &)>;
  // Before anything in Run that may return: the records are cut on the way out. on_record
  // (TransientAnalysis::on_record, may be empty): each record is handed to it on rank 0, and res
  // keeps the state of the last one only.
  // energy false: the caller reads no energy (TransientAnalysis::energy), so the ledger only checks
  // that the state is finite and the records' energies are NaN.
  Bookkeeping(MPI_Comm comm, TransientResult &res, PetscInt N, PetscInt nc, const Hook &on_record, bool energy = true)
    : comm_(comm), res_(res), recs_(res, N, nc), hook_(on_record), energy_(energy)
  {
    res.streamed = (bool)on_record;
    res.energy_kept = energy;
  }
  // Rank 0: room for this many records.
  void SizeRecords(size_t records) { recs_.Size(records); }
  // The ledger (see CreateLedger) from the state at the start, its energy E0, and record 0 (every
  // point sliding, with the reactions r).
  PetscErrorCode SetUp(const Model &model, bool fixed_size, Vec U, Vec dU, const PetscReal *u, const PetscReal *du, const Eigen::VectorXd &r);
  Ledger        *GetLedger() const { return ledger_.get(); }
  // The energies and works at the current state, over all ranks; Finite(): the energy is finite.
  PetscErrorCode Totals();
  bool           Finite() const { return std::isfinite(tot_[0] + tot_[1]); }
  int           *Status() { return status_.data(); }
  // The current state after `step` steps, reactions r, the statuses and the last totals as the record at time t.
  PetscErrorCode Record(PetscInt step, PetscReal t, const Eigen::VectorXd &r);
  // The monitor line after step i, which took fp_its fixed-point passes (the last totals).
  PetscErrorCode Monitor(PetscInt i, PetscInt fp_its) const;
  void           Cut() { recs_.Cut(); }
  // Rank 0: the next record's slots, filled by the caller (Run's loop for the dense ledger's
  // sizes), then Commit() (the statuses and energies as Record would write them).
  struct Slot {
    PetscReal *t, *U, *V, *R, *energy;
    PetscInt  *status;
  };
  Slot Next()
  {
    const size_t k = recs_.n;
    const PetscInt N = recs_.N, nc = recs_.nc;
    return {res_.t.data() + k, res_.U.data() + k * N, res_.V.data() + k * N, res_.R.data() + k * 3 * nc, res_.energy.data() + 4 * k,
            res_.status.data() + k * nc};
  }
  void Commit() { recs_.n++; }

private:
  MPI_Comm                comm_;
  TransientResult        &res_;
  RecordSink              recs_;
  const Hook             &hook_;
  const bool              energy_;
  PetscMPIInt             rank_ = 0, size_ = 1;
  std::unique_ptr<Ledger> ledger_;
  std::vector<int>        status_;
  Vec                     U_ = nullptr, dU_ = nullptr;
  const PetscReal        *u_ = nullptr, *du_ = nullptr;
  Handle<VecScatter>      sc_; // several ranks: the records gathered on rank 0
  VecH                    z_;
  PetscReal               tot_[5] = {0, 0, 0, 0, 0}; // E_kinetic, E_elastic, W_damping, W_reactions, W_load over all ranks
  PetscReal               E0_     = 0;
};

} // namespace transient
} // namespace squeal
