// Energy estimate of the limit-cycle amplitude (docs/method.md §7).
//
// For an unstable mode (lambda = sigma + i omega, phi normalised so that its largest tangential
// contact component is 1) and the imposed motion U = U_e + q Re(phi e^{i omega t}):
//   damping power      P_c(q) = 1/2 q^2 omega^2 phi^H C phi                               (7.1)
//   normal reactions   r_n,c  = max(0, N_c + q Re(psi_c e^{i omega t})),
//                      psi    = (H_n^T H_n)^-1 H_n^T (-omega^2 M + i omega C + K) phi        (7.2)
//   friction           planar: r_T = mu r_n (V_c - u_t, -u_b)/|.|; rectilinear: mu r_n sign(V_c - u_t)  (7.3)
//   reaction power     P_R(q) = < sum_c r_T,c . u_T,c >  (time mean over one period)        (7.4)
// q0 is the first q where P_R - P_c changes sign from + to -: a scan of n_scan points up to
// q_max = factor * q_sep (q_sep = min_c N_c / |psi_c|, the first lift-off), then bisection.
// Without a crossing the range doubles (-energy_extend times) before the estimate gives up and
// names the option to change.
// It gives the shooting guess Z0 = (U_e + q0 Re phi, -q0 omega Im phi), T0 = 2 pi / omega (7.5).
// Options prefix "energy_". Cost O(n_scan * samples * n_c) on replicated contact data.
#pragma once

#include "squeal/io/h5.h"
#include "squeal/stability/stability.h"

#include <vector>

namespace squeal {

struct EnergyEstimate {
  PetscInt               mode = -1; // index into the stability table
  PetscReal              omega = 0, sigma = 0, q_sep = 0, q0 = 0, T0 = 0;
  PetscReal              q_max_factor = 0;  // the factor finally scanned (after any doublings)
  PetscInt               extensions = 0;    // doublings of the scan range used
  bool                   found = false; // a + to - crossing exists in the scan range
  std::vector<PetscReal> q, P_damping, P_reactions;
  VecH                   U0, dU0; // the shooting guess Z0
};

class EnergyAnalysis {
public:
  explicit EnergyAnalysis(MPI_Comm comm) : comm_(comm) {}
  // -energy_mode, -energy_n_scan, -energy_samples, -energy_q_max_factor, -energy_bisections,
  // -energy_extend, -energy_all_modes
  PetscErrorCode SetFromOptions();
  // Estimates the amplitude for the chosen (default: most unstable) mode. A stable equilibrium is
  // not an error: est.mode stays -1.
  PetscErrorCode Estimate(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, EnergyEstimate &est);
  // P_R - P_c at amplitude q for the current mode data (after Estimate's set-up).
  PetscReal      PowerBalance(PetscReal q) const;
  PetscErrorCode View(const EnergyEstimate &est, PetscViewer viewer) const;
  PetscErrorCode Write(const EnergyEstimate &est, io::H5Writer &out) const;

  PetscInt  mode = -1, n_scan = 2000, samples = 4000, bisections = 60, extend = 4;
  PetscReal q_max_factor = 50;
  PetscBool all_modes = PETSC_FALSE; // estimate every unstable mode, not only the chosen one (app)
  // false: stop the scan at its first balance (the same q0; q, P_* hold the points up to it). The
  // app sets it when the estimate is only shooting's start (-analyses without energy): the full
  // curve to q_max is then 94 % of the cost on case 1 and nobody reads it.
  bool      full_scan = true;

private:
  PetscReal Reactions(PetscReal q) const;
  // Scan (0, factor q_sep] and bisect the first + to - crossing; *found false if there is none.
  // Collective: polls the interrupt (every rank scans the same replicated points).
  PetscErrorCode Scan(PetscReal factor, EnergyEstimate &est, bool *found) const;

  MPI_Comm                            comm_;
  const ContactSet                   *cs_ = nullptr;
  PetscReal                           omega_ = 0, cphi_ = 0;
  std::vector<PetscReal>              N_, speed_;           // per point: N_c, V_c
  std::vector<std::complex<PetscReal>> psi_, phit_, phib_; // per point
  std::vector<PetscReal>              cos_, sin_;           // samples of one period
};

} // namespace squeal
