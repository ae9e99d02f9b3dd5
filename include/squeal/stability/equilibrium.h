// Steady sliding equilibrium (docs/method.md §3).
//
// With every point closed and sliding, r_T,c = (mu N_c, 0) and, with B_mu = H_n + mu H_t,
//     [ K      -B_mu ] { U_e }   {  F      }
//     [ H_n^T    0   ] {  N  } = { -g0_n   }                                        (3.1)
// one sparse bordered solve (LU; MUMPS by default, which pivots through the zero block and
// runs distributed). Points with N_c <= 0 are released and the system is solved again; released
// points must end with a non-negative gap (active-set loop). Failures are named: no closed point
// (the load lifts the structure off), friction-induced divergence (no sliding state exists with
// friction while one exists without), singular bordered matrix.
#pragma once

#include "squeal/core/handle.h"
#include "squeal/model/model.h"

#include <string>
#include <vector>

namespace squeal {

struct SlidingEquilibrium {
  VecH                   U;        // U_e, laid out like F
  VecH                   R;        // global contact force H r
  std::vector<PetscReal> N;        // normal reaction per point (0 where released)
  std::vector<PetscReal> gap;      // normal gap per point at U_e
  std::vector<PetscInt>  active;   // closed points
  std::vector<PetscInt>  released; // points that lift off
  PetscInt               passes = 0;
  PetscReal              mu     = 0; // friction coefficient it was computed for
};

class EquilibriumSolver {
public:
  explicit EquilibriumSolver(MPI_Comm comm) : comm_(comm) {}
  PetscErrorCode SetOptionsPrefix(const char *prefix)
  {
    prefix_ = prefix ? prefix : "";
    return 0;
  }
  PetscErrorCode SetMaxPasses(PetscInt n);
  // -eq_max_passes, -eq_view, and the bordered solver's -eq_ksp_*, -eq_pc_*.
  PetscErrorCode SetFromOptions();
  PetscErrorCode Solve(const Model &model, SlidingEquilibrium &eq);
  PetscErrorCode View(const Model &model, const SlidingEquilibrium &eq, PetscViewer viewer) const;
  // -eq_view, if given.
  PetscErrorCode ViewFromOptions(const Model &model, const SlidingEquilibrium &eq) const;

private:
  PetscErrorCode SolveBordered(const Model &model, const std::vector<PetscInt> &active, PetscReal mu, Vec U,
                               std::vector<PetscReal> &N, bool *ok);

  MPI_Comm    comm_;
  std::string prefix_     = "eq_";
  PetscInt    max_passes_ = 20;
  KSPH        ksp_;
};

} // namespace squeal
