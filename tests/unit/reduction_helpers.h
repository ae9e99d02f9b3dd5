// Test helpers shared by the reduction tests: the small generated pad, the unstable eigenvalues
// of a model by squeal's own equilibrium and stability solvers, and their distance to a reference.
#pragma once

#include "squeal/model/pad.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/stability.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <complex>
#include <string>
#include <vector>

namespace squeal::test {

inline PadParams SmallPad()
{
  PadParams p;
  p.n_r = 3, p.n_t = 12, p.n_fric = 1, p.n_steel = 1;
  p.mu = 0.3, p.V = 10;
  return p;
}

// The sliding equilibrium and the stability of a model by squeal's own solvers (nev > 0: that many
// eigenvalues asked of the PEP); false, with a test failure, when either fails.
inline bool SolveStability(Model &model, StabilityResult &res, PetscInt nev = 0)
{
  EquilibriumSolver  eqs(model.comm());
  StabilitySolver    stab(model.comm());
  SlidingEquilibrium eq;
  // MUMPS underestimates the workspace of the bordered equilibrium matrix of a dense reduced model.
  EXPECT_EQ(PetscOptionsSetValue(nullptr, "-eq_mat_mumps_icntl_14", "200"), 0);
  EXPECT_EQ(eqs.SetFromOptions(), 0);
  if (nev > 0) {
    EXPECT_EQ(PetscOptionsSetValue(nullptr, "-stab_pep_nev", std::to_string(nev).c_str()), 0);
  }
  EXPECT_EQ(stab.SetFromOptions(), 0);
  EXPECT_EQ(PetscOptionsClearValue(nullptr, "-stab_pep_nev"), 0);
  const bool failed = eqs.Solve(model, eq) || stab.Solve(model, eq, res);
  EXPECT_EQ(PetscOptionsClearValue(nullptr, "-eq_mat_mumps_icntl_14"), 0);
  if (failed) ADD_FAILURE() << "equilibrium or stability failed";
  return !failed;
}

// Unstable eigenvalues (sigma + i omega) of a model, most unstable first.
inline std::vector<std::complex<double>> Unstable(Model &model, PetscInt nev = 12)
{
  StabilityResult                   res;
  std::vector<std::complex<double>> out;
  if (!SolveStability(model, res, nev)) return out;
  for (PetscInt i : res.unstable) out.emplace_back(res.modes[i].sigma, res.modes[i].omega);
  return out;
}

// Largest relative distance from each reference eigenvalue to the nearest one of `got`.
inline double MaxRelError(const std::vector<std::complex<double>> &ref, const std::vector<std::complex<double>> &got)
{
  double worst = 0;
  for (auto r : ref) {
    double best = 1e300;
    for (auto g : got) best = std::min(best, std::abs(g - r) / std::abs(r));
    worst = std::max(worst, best);
  }
  return worst;
}

} // namespace squeal::test
