#include "squeal/stability/linearization.h"
#include "squeal/core/errors.h"
#include "squeal/core/sparse.h"

#include <algorithm>
#include <map>

namespace squeal {

namespace {

// Nonzero entries of one local direction column of point c: DOF -> value.
std::map<PetscInt, PetscReal> Column(const ContactSet &cs, PetscInt c, int dir)
{
  std::map<PetscInt, PetscReal> col;
  cs.ForEachEntry(c, dir, [&](PetscInt j, PetscReal v) { col[j] += v; });
  for (auto it = col.begin(); it != col.end();) it = (it->second == 0) ? col.erase(it) : std::next(it);
  return col;
}

// L A Q, with L = Q^T P. On one rank as L (A Q): SeqAIJ's symbolic product is fast. On several
// ranks, PETSc 3.18's symbolic product of two MPIAIJ matrices (and PtAP's default algorithm, which
// forms A Q too) merges every row of the right factor that a row of the left one touches into a
// sorted list, so A Q with the dense rows of a reduced model costs the square of the row length per
// row: 2.0 s of the 1420-DOF pad's 2.6 s stability on 2 ranks, against 0.8 s for all of it on
// one. There it is Q^T (P A) Q: P's rows are short (the identity and a friction row per point), and
// PtAP's "allatonce_merged" does not form A Q. (SeqAIJ's PtAP is as slow as the MPI one.)
PetscErrorCode Restrict(Mat L, Mat P, Mat A, Mat Q, Mat *out)
{
  MatH        X;
  PetscMPIInt size;
  PetscBool   mpiaij;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)A), &size));
  PetscCall(PetscObjectTypeCompare((PetscObject)A, MATMPIAIJ, &mpiaij));
  if (size == 1 || !mpiaij) {
    PetscCall(MatMatMult(A, Q, MAT_INITIAL_MATRIX, PETSC_DEFAULT, X.out()));
    PetscCall(MatMatMult(L, X, MAT_INITIAL_MATRIX, PETSC_DEFAULT, out));
    PetscFunctionReturn(0);
  }
  PetscCall(MatMatMult(P, A, MAT_INITIAL_MATRIX, PETSC_DEFAULT, X.out()));
  PetscCall(MatProductCreate(X, Q, nullptr, out));
  PetscCall(MatProductSetType(*out, MATPRODUCT_PtAP));
  PetscCall(MatProductSetAlgorithm(*out, "allatonce_merged"));
  PetscCall(MatProductSetFill(*out, PETSC_DEFAULT));
  PetscCall(MatProductSetFromOptions(*out));
  PetscCall(MatProductSymbolic(*out));
  PetscCall(MatProductNumeric(*out));
  PetscCall(MatProductClear(*out));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode BuildReducedProblem(const Model &model, const SlidingEquilibrium &eq, ReducedProblem &rp)
{
  const ContactSet &cs = model.contacts;
  const MPI_Comm    comm = model.comm();
  const PetscInt    N    = model.Size();
  const PetscReal   mu   = cs.Mu();
  PetscInt          rstart, rend;
  PetscFunctionBeginUser;
  PetscCall(VecGetOwnershipRange(model.F, &rstart, &rend));
  rp.active = eq.active;

  // Pivots and reduced numbering.
  std::vector<PetscInt> pivots;
  for (PetscInt c : rp.active) pivots.push_back(cs.PivotDof(c));
  std::vector<PetscInt> sorted = pivots;
  std::sort(sorted.begin(), sorted.end());
  auto reduced_index = [&](PetscInt j) {
    return j - (PetscInt)(std::lower_bound(sorted.begin(), sorted.end(), j) - sorted.begin());
  };
  const PetscInt n_r       = N - (PetscInt)pivots.size();
  rp.n_r                = n_r;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCheck(n_r >= size, comm, kErrInput,
             "stability: the reduced problem has %" PetscInt_FMT " DOF(s), fewer than the %d MPI ranks; run on at most %" PetscInt_FMT
             " ranks",
             n_r, size, n_r);

  Triplets q, pm, hbs, hbt; // hbs: columns coef_c h_{b,c}, hbt: columns h_{b,c}; D_b = hbs hbt^T
  for (PetscInt j = rstart; j < rend; ++j)
    if (!std::binary_search(sorted.begin(), sorted.end(), j)) q.Add(j, reduced_index(j), 1.0);
  for (PetscInt i = rstart; i < rend; ++i) pm.Add(i, i, 1.0);
  for (size_t a = 0; a < rp.active.size(); ++a) {
    const PetscInt c  = rp.active[a];
    const auto     hn = Column(cs, c, kN), ht = Column(cs, c, kT), hb = Column(cs, c, kB);
    const PetscInt p  = pivots[a];
    PetscReal      D  = 0;
    for (auto &e : hn) D += e.second * e.second;
    if (p >= rstart && p < rend)
      for (auto &e : hn)
        if (e.first != p) q.Add(p, reduced_index(e.first), -e.second / hn.at(p));
    if (mu > 0) {
      for (auto &ei : ht)
        if (ei.first >= rstart && ei.first < rend)
          for (auto &ej : hn) pm.Add(ei.first, ej.first, -mu * ei.second * ej.second / D);
      if (cs.law == FrictionLaw::Planar) {
        const PetscReal coef = mu * eq.N[c] / cs.Speed(c);
        for (auto &ei : hb)
          if (ei.first >= rstart && ei.first < rend) {
            hbs.Add(ei.first, (PetscInt)a, coef * ei.second);
            hbt.Add(ei.first, (PetscInt)a, ei.second);
          }
      }
    }
  }
  MatH P, Db, Cd;
  // The reduced problem gets its own balanced layout: following U's would leave a rank whose
  // rows are all pivots with an empty share, which SLEPc 3.18's TOAR does not survive in parallel.
  PetscCall(MatCreateFromTriplets(comm, rend - rstart, PETSC_DECIDE, N, n_r, q, rp.Q.out()));
  PetscCall(MatCreateFromTriplets(comm, rend - rstart, rend - rstart, N, N, pm, P.out()));
  // D_b = sum_c coef_c h_b h_b^T as one sparse product: with explicit (dense) columns over k
  // interface modes, the sum of n_c rank-one k x k blocks as triplets cost seconds.
  PetscInt nb = (PetscInt)hbt.rows.size();
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &nb, 1, MPIU_INT, MPI_SUM, comm));
  if (nb > 0) {
    MatH Hbs, Hb;
    const PetscInt na = (PetscInt)rp.active.size();
    PetscCall(MatCreateFromTriplets(comm, rend - rstart, PETSC_DECIDE, N, na, hbs, Hbs.out()));
    PetscCall(MatCreateFromTriplets(comm, rend - rstart, PETSC_DECIDE, N, na, hbt, Hb.out()));
    PetscCall(MatMatTransposeMult(Hbs, Hb, MAT_INITIAL_MATRIX, PETSC_DEFAULT, Db.out()));
  } else {
    Triplets none;
    PetscCall(MatCreateFromTriplets(comm, rend - rstart, rend - rstart, N, N, none, Db.out()));
  }
  PetscCall(MatTransposeMatMult(rp.Q, P, MAT_INITIAL_MATRIX, PETSC_DEFAULT, rp.L.out()));

  // C + D_b, with either part possibly absent.
  if (model.HasDamping()) {
    PetscCall(MatDuplicate(model.C, MAT_COPY_VALUES, Cd.out()));
    PetscCall(MatAXPY(Cd, 1.0, Db, DIFFERENT_NONZERO_PATTERN));
  } else {
    PetscCall(MatDuplicate(Db, MAT_COPY_VALUES, Cd.out()));
  }
  PetscCall(Restrict(rp.L, P, model.M, rp.Q, rp.Mr.out()));
  PetscCall(Restrict(rp.L, P, Cd, rp.Q, rp.Cr.out()));
  PetscCall(Restrict(rp.L, P, model.K, rp.Q, rp.Kr.out()));
  PetscFunctionReturn(0);
}

} // namespace squeal
