// Stability maps (docs/method.md §4.5): eigenvalues over a grid of mu (and V), and the critical
// friction coefficient mu_c, the first mu at which the largest growth rate of an oscillatory
// mode crosses zero, with the frequency at which the modes coalesce.
//
// The grid is a batch of independent problems: each rank solves a round-robin share of the points
// with the SweepPoint it is given (the pipeline's: its own copy of the model on PETSC_COMM_SELF,
// equilibrium recomputed for every mu, since D_b depends on mu N_c); one reduction gathers the
// table on every rank. mu_c is
// bracketed on the grid and refined by bisection (-sweep_bisect_tol), one V per rank.
// Every point uses the band-complete stability solver (-stab_fmax); points whose band was not
// covered are flagged (/sweep/band_covered) and a critical mu found above such a point is marked
// as not certified (an unstable mode may have been missed below it).
#pragma once

#include "squeal/core/handle.h"
#include "squeal/io/h5.h"
#include "squeal/model/model.h"
#include "squeal/stability/stability.h"

#include <functional>

#include <string>
#include <vector>

namespace squeal {

struct SweepResult {
  std::vector<PetscReal> mu, V;
  PetscInt               k = 0;       // eigenvalue slots per point (omega >= 0 members)
  std::vector<PetscReal> eigenvalues; // [iv][imu][slot][re, im], NaN where absent
  std::vector<PetscInt>  failed;      // per point: 0 solved, 1 no equilibrium or no eigenvalues, 2 not computed (interrupted)
  bool                   interrupted = false; // a signal stopped the sweep: points marked 2, no critical mu
  // Per point: the stability solver's completeness (Hz, inf: all eigenvalues) and whether it
  // reached the band -stab_fmax; a point not covered may have missed an unstable mode.
  std::vector<PetscReal> complete_up_to;
  std::vector<PetscInt>  covered;
  PetscReal              fmax = 0;
  std::vector<PetscInt>  critical_certified; // per V: every point up to the crossing covered its band
  std::vector<PetscReal> critical_mu, coalescence_frequency; // per V; NaN if no crossing in range

  PetscReal MaxSigma(size_t iv, size_t imu) const;
};

// One grid point on this rank alone: the stability of the sliding equilibrium at (mu, V). A point
// without steady sliding is a result (*ok = false), not an error.
using SweepPoint = std::function<PetscErrorCode(PetscReal mu, PetscReal V, StabilityResult &res, bool *ok)>;

class SweepSolver {
public:
  explicit SweepSolver(MPI_Comm comm) : comm_(comm) {}
  PetscErrorCode SetOptionsPrefix(const char *prefix)
  {
    prefix_ = prefix ? prefix : "";
    return 0;
  }
  // -sweep_mu_min/max/n, -sweep_v_min/max/n, -sweep_bisect_tol, -sweep_monitor.
  PetscErrorCode SetFromOptions(PetscReal default_V);
  PetscErrorCode Solve(const SweepPoint &point, SweepResult &res); // collective
  PetscErrorCode View(const SweepResult &res, PetscViewer viewer) const;
  PetscErrorCode Write(const SweepResult &res, io::H5Writer &out) const;

private:
  MPI_Comm    comm_;
  std::string prefix_ = "sweep_";
  PetscReal   mu_min_ = 0.0, mu_max_ = 0.6, v_min_ = 1.0, v_max_ = 1.0;
  PetscInt    mu_n_ = 61, v_n_ = 1;
  PetscReal   bisect_tol_ = 1e-8;
  PetscBool   monitor_    = PETSC_FALSE;
};

} // namespace squeal
