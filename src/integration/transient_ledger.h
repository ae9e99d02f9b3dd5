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

// The ledger of a run: with u, du (one rank, the arrays behind U and dU) and a fixed-size step
// kernel, the dense ledger for the kernel's sizes when there is one; else the one on Vecs.
PetscErrorCode CreateLedger(const Model &model, const PetscReal *u, const PetscReal *du, bool fixed_size, Vec U, Vec dU, PetscReal h,
                            std::unique_ptr<Ledger> &out);

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
  Bookkeeping(MPI_Comm comm, TransientResult &res, PetscInt N, PetscInt nc, const Hook &on_record)
    : comm_(comm), res_(res), recs_(res, N, nc), hook_(on_record)
  {
    res.streamed = (bool)on_record;
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

private:
  MPI_Comm                comm_;
  TransientResult        &res_;
  RecordSink              recs_;
  const Hook             &hook_;
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
