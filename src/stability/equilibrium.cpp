#include "squeal/stability/equilibrium.h"
#include "squeal/core/errors.h"
#include "squeal/core/solvers.h"
#include "squeal/core/sparse.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace squeal {

PetscErrorCode EquilibriumSolver::SetMaxPasses(PetscInt n)
{
  PetscFunctionBeginUser;
  PetscCheck(n >= 1, comm_, kErrInput, "equilibrium: max passes %" PetscInt_FMT " must be >= 1", n);
  max_passes_ = n;
  PetscFunctionReturn(0);
}

PetscErrorCode EquilibriumSolver::SetFromOptions()
{
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, prefix_.c_str(), "Sliding equilibrium", "EquilibriumSolver");
  PetscCall(PetscOptionsInt("-max_passes", "Passes of the active-set loop (points released / re-closed)",
                            "EquilibriumSolver::SetMaxPasses", max_passes_, &max_passes_, nullptr));
  PetscCall(PetscOptionsName("-view", "Print the equilibrium (ascii viewer)", "EquilibriumSolver::View", nullptr));
  PetscOptionsEnd();
  PetscCall(SetMaxPasses(max_passes_));
  PetscCall(KSPCreate(comm_, ksp_.out()));
  PetscCall(KSPSetOptionsPrefix(ksp_, prefix_.c_str()));
  // The bordered matrix has a zero block: a factorisation that pivots is needed.
  PetscCall(UseDirectSolver(ksp_, Factorisation::General));
  PetscCall(KSPSetFromOptions(ksp_));
  PetscFunctionReturn(0);
}

PetscErrorCode EquilibriumSolver::SolveBordered(const Model &model, const std::vector<PetscInt> &active, PetscReal mu,
                                                Vec U, std::vector<PetscReal> &N, bool *ok)
{
  const ContactSet &cs = model.contacts;
  const PetscInt    n  = model.Size(), na = (PetscInt)active.size();
  PetscInt          rstart, rend;
  PetscMPIInt       rank, size;
  Triplets          t;
  MatH              A;
  VecH              x, b;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  PetscCall(VecGetOwnershipRange(model.F, &rstart, &rend));
  const bool     last = rank == size - 1; // owns the multiplier rows, appended after row n-1
  const PetscInt mloc = (rend - rstart) + (last ? na : 0);

  PetscCall(AppendLocalRows(model.K, 1.0, 0, 0, t));
  for (PetscInt a = 0; a < na; ++a) {
    // Column n + a is -B_mu = -(h_n + mu h_t) (entries on one DOF add up), row n + a is h_n^T.
    cs.ForEachEntry(active[a], kN, [&](PetscInt j, PetscReal bn) {
      if (j >= rstart && j < rend) t.Add(j, n + a, -bn);
      if (last) t.Add(n + a, j, bn);
    });
    if (mu != 0)
      cs.ForEachEntry(active[a], kT, [&](PetscInt j, PetscReal bt) {
        if (j >= rstart && j < rend) t.Add(j, n + a, -mu * bt);
      });
  }
  PetscCall(MatCreateFromTriplets(comm_, mloc, mloc, n + na, n + na, t, A.out()));

  PetscCall(MatCreateVecs(A, x.out(), b.out()));
  {
    const PetscScalar *f;
    PetscScalar       *bb;
    PetscCall(VecGetArrayRead(model.F, &f));
    PetscCall(VecGetArray(b, &bb));
    for (PetscInt i = 0; i < rend - rstart; ++i) bb[i] = f[i];
    if (last)
      for (PetscInt a = 0; a < na; ++a) bb[rend - rstart + a] = -cs.points[active[a]].g0;
    PetscCall(VecRestoreArray(b, &bb));
    PetscCall(VecRestoreArrayRead(model.F, &f));
  }
  // A new matrix every pass, and its size changes when points are released: start afresh.
  PetscCall(KSPReset(ksp_));
  PetscCall(KSPSetOperators(ksp_, A, A));
  {
    // The multiplier block is zero, so MUMPS delays pivots that its structural analysis did not
    // foresee; on a reduced (dense) model the whole matrix is one front and the default 20 % extra
    // workspace runs out (INFOG(1) = -9 on the 232 x 232 reduced small pad). 200 % unless the user
    // sets -eq_mat_mumps_icntl_14; the matrix is small wherever it is dense.
    PC        pc;
    PetscBool lu, mumps = PETSC_FALSE, set;
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCLU, &lu));
    if (lu) {
      MatSolverType st;
      PetscCall(PCFactorGetMatSolverType(pc, &st));
      if (st) PetscCall(PetscStrcmp(st, MATSOLVERMUMPS, &mumps));
    }
    PetscCall(PetscOptionsHasName(nullptr, prefix_.c_str(), "-mat_mumps_icntl_14", &set));
    if (mumps && !set) {
      Mat Fm;
      PetscCall(PCFactorSetUpMatSolverType(pc));
      PetscCall(PCFactorGetMatrix(pc, &Fm));
      PetscCall(MatMumpsSetIcntl(Fm, 14, 200));
    }
  }
  PetscCall(KSPSolve(ksp_, b, x));
  KSPConvergedReason reason;
  PetscCall(KSPGetConvergedReason(ksp_, &reason));
  *ok = reason >= 0;
  if (!*ok) {
    // Out of memory is not singular: say so and name the knob (MUMPS INFOG(1) = -8, -9, -13).
    PC             pc;
    Mat            Fm;
    MatFactorError ferr = MAT_FACTOR_NOERROR;
    PetscBool      factor, mumps = PETSC_FALSE;
    PetscInt       icntl14 = 20;
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PetscObjectTypeCompareAny((PetscObject)pc, &factor, PCLU, PCCHOLESKY, ""));
    if (factor) {
      PetscCall(PCFactorGetMatrix(pc, &Fm));
      PetscCall(MatFactorGetError(Fm, &ferr));
      MatSolverType st;
      PetscCall(PCFactorGetMatSolverType(pc, &st));
      PetscCall(PetscStrcmp(st, MATSOLVERMUMPS, &mumps));
      if (mumps) PetscCall(MatMumpsGetIcntl(Fm, 14, &icntl14));
    }
    PetscCheck(ferr != MAT_FACTOR_OUTMEMORY, comm_, PETSC_ERR_MEM,
               "sliding equilibrium: the factorisation of the %" PetscInt_FMT " x %" PetscInt_FMT
               " bordered matrix ran out of memory%s; raise -%smat_mumps_icntl_14 (extra workspace in %%, now %" PetscInt_FMT
               ") or give the run more memory",
               n + na, n + na, mumps ? " (MUMPS INFOG(1) = -9: workspace too small)" : "", prefix_.c_str(), icntl14);
    PetscFunctionReturn(0);
  }

  const PetscScalar *xx;
  PetscScalar       *u;
  std::vector<PetscReal> Na(na, 0.0);
  PetscCall(VecGetArrayRead(x, &xx));
  PetscCall(VecGetArray(U, &u));
  for (PetscInt i = 0; i < rend - rstart; ++i) u[i] = xx[i];
  if (last)
    for (PetscInt a = 0; a < na; ++a) Na[a] = PetscRealPart(xx[rend - rstart + a]);
  PetscCall(VecRestoreArray(U, &u));
  PetscCall(VecRestoreArrayRead(x, &xx));
  if (na) PetscCallMPI(MPI_Bcast(Na.data(), (int)na, MPIU_REAL, size - 1, comm_));
  N.assign(cs.Size(), 0.0);
  for (PetscInt a = 0; a < na; ++a) N[active[a]] = Na[a];
  PetscFunctionReturn(0);
}

PetscErrorCode EquilibriumSolver::Solve(const Model &model, SlidingEquilibrium &eq)
{
  const ContactSet &cs = model.contacts;
  const PetscInt    nc = cs.Size();
  std::vector<char> closed(nc, 1);
  std::vector<PetscReal> comp;
  bool              ok = true;
  PetscFunctionBeginUser;
  if (!ksp_) PetscCall(SetFromOptions());
  PetscCall(VecDuplicate(model.F, eq.U.out()));
  PetscCall(PetscObjectSetName((PetscObject)(Vec)eq.U, "U"));
  eq.mu = cs.Mu();
  for (eq.passes = 1; eq.passes <= max_passes_; ++eq.passes) {
    eq.active.clear();
    for (PetscInt c = 0; c < nc; ++c)
      if (closed[c]) eq.active.push_back(c);
    PetscCall(SolveBordered(model, eq.active, cs.Mu(), eq.U, eq.N, &ok));
    if (!ok) {
      // Singular at mu: friction-induced divergence only if the frictionless matrix is regular.
      bool ok0 = false;
      if (cs.Mu() != 0) {
        VecH                   U0;
        std::vector<PetscReal> N0;
        PetscCall(VecDuplicate(model.F, U0.out()));
        PetscCall(SolveBordered(model, eq.active, 0.0, U0, N0, &ok0));
      }
      PetscCheck(!ok0, comm_, kErrInput,
                 "no steady sliding: friction-induced divergence at mu = %g (the bordered equilibrium matrix "
                 "[K -B_mu; H_n^T 0] is singular at this mu and regular at mu = 0)",
                 (double)cs.Mu());
      char mu[32]; // PETSc's %g would print "0." for 0
      std::snprintf(mu, sizeof mu, "%g", (double)cs.Mu());
      SETERRQ(comm_, kErrInput,
              "the bordered equilibrium matrix [K -B_mu; H_n^T 0] is singular at mu = %s%s: K with the %zu closed contact(s) "
              "leaves a rigid-body motion free (missing support or zero stiffness)",
              mu, cs.Mu() != 0 ? " and at mu = 0" : "", eq.active.size());
    }
    PetscCall(cs.LocalComponents(eq.U, comp));
    eq.gap.resize(nc);
    PetscReal scale = 0;
    for (PetscInt c = 0; c < nc; ++c) {
      eq.gap[c] = comp[3 * c + kN] + cs.points[c].g0;
      scale     = PetscMax(scale, PetscMax(std::abs(comp[3 * c + kT]), std::abs(comp[3 * c + kB])));
    }
    const PetscReal gap_tol = 1e-12 * PetscMax(scale, 1e-12);
    bool            changed = false;
    for (PetscInt c = 0; c < nc; ++c) {
      if (closed[c] && eq.N[c] <= 0) closed[c] = 0, changed = true;
      else if (!closed[c] && eq.gap[c] < -gap_tol) closed[c] = 1, changed = true;
    }
    if (!changed || std::none_of(closed.begin(), closed.end(), [](char x) { return x; })) break;
  }
  PetscCheck(eq.passes <= max_passes_, comm_, PETSC_ERR_NOT_CONVERGED,
             "sliding equilibrium: the active-set loop did not settle in %" PetscInt_FMT " passes (-%smax_passes)", max_passes_,
             prefix_.c_str());
  eq.active.clear();
  eq.released.clear();
  for (PetscInt c = 0; c < nc; ++c) (closed[c] ? eq.active : eq.released).push_back(c);

  if (eq.active.empty()) {
    // Tell a lifted structure from friction-induced divergence: does a state exist without friction?
    std::vector<PetscInt>  all(nc);
    std::vector<PetscReal> N0;
    VecH                   U0;
    for (PetscInt c = 0; c < nc; ++c) all[c] = c;
    PetscCall(VecDuplicate(model.F, U0.out()));
    PetscCall(SolveBordered(model, all, 0.0, U0, N0, &ok));
    const bool frictionless_closed = ok && std::any_of(N0.begin(), N0.end(), [](PetscReal x) { return x > 0; });
    PetscCheck(!(cs.Mu() > 0 && frictionless_closed), comm_, kErrInput,
               "no steady sliding: friction-induced divergence at mu = %g (friction drives the structure into the surface; "
               "an equilibrium exists only with less friction)",
               (double)cs.Mu());
    SETERRQ(comm_, kErrInput,
            "no closed contact at equilibrium: the load lifts all %" PetscInt_FMT " point(s) off the surface "
            "(check the sign of the preload)",
            nc);
  }

  // R = B_mu N: the contact force the equilibrium rests on.
  PetscCall(VecDuplicate(model.F, eq.R.out()));
  PetscCall(PetscObjectSetName((PetscObject)(Vec)eq.R, "R"));
  PetscCall(MatMult(model.K, eq.U, eq.R));
  PetscCall(VecAXPY(eq.R, -1.0, model.F));
  PetscFunctionReturn(0);
}

PetscErrorCode EquilibriumSolver::View(const Model &model, const SlidingEquilibrium &eq, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  const ContactSet &cs = model.contacts;
  PetscCall(PetscViewerASCIIPrintf(viewer, "sliding equilibrium (mu = %g): %zu of %" PetscInt_FMT " point(s) closed, %" PetscInt_FMT
                                           " active-set pass(es)\n",
                                   (double)eq.mu, eq.active.size(), cs.Size(), eq.passes));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  if (!eq.released.empty()) {
    std::string list;
    for (size_t i = 0; i < eq.released.size() && i < 20; ++i) list += (i ? ", " : "") + std::to_string(eq.released[i]);
    if (eq.released.size() > 20) list += ", ...";
    PetscCall(PetscViewerASCIIPrintf(viewer, "loss of contact at points %s\n", list.c_str()));
  }
  PetscReal Nsum = 0;
  for (PetscReal x : eq.N) Nsum += x;
  PetscCall(PetscViewerASCIIPrintf(viewer, "total normal reaction %.6g N\n", (double)Nsum));
  for (size_t i = 0; i < eq.active.size() && i < 8; ++i) {
    const PetscInt c = eq.active[i];
    PetscCall(PetscViewerASCIIPrintf(viewer, "point %" PetscInt_FMT ": N = %.6g N, r = (%.6g, 0, %.6g) N\n", c,
                                     (double)eq.N[c], (double)(eq.mu * eq.N[c]), (double)eq.N[c]));
  }
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode EquilibriumSolver::ViewFromOptions(const Model &model, const SlidingEquilibrium &eq) const
{
  PetscFunctionBeginUser;
  PetscCall(squeal::ViewFromOptions(comm_, prefix_, [&](PetscViewer v) { return View(model, eq, v); }));
  PetscFunctionReturn(0);
}

} // namespace squeal
