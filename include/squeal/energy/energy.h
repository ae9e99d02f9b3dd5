// Energy estimate of the limit-cycle amplitude (docs/method.md §7).
//
// For an unstable mode (lambda = sigma + i omega, phi normalised so that its largest tangential
// contact component is 1) and the imposed motion U = U_e + q Re(phi e^{i omega t}):
//   damping power      P_c(q) = 1/2 q^2 omega^2 phi^H C phi                               (7.1)
//   normal reactions   r_n,c  = max(0, N_c + q Re(psi_c e^{i omega t})),
//                      psi    = (H_n^T H_n)^-1 H_n^T (-omega^2 M + i omega C + K) phi        (7.2)
//   friction           planar: r_T = mu r_n (V_c - u_t, -u_b)/|.|; rectilinear: mu r_n sign(V_c - u_t)  (7.3)
//   reaction power     P_R(q) = < sum_c r_T,c . u_T,c >  (time mean over one period)        (7.4)
// Impact losses (-energy_impacts, default on): where the linear reaction would pull (N_c +
// q Re(psi_c e^{i omega t}) < 0) the point separates instead; the tensile impulse it misses,
//   J_c(q) = int_T max(0, -(N_c + q Re(psi_c e^{i omega t}))) dt,
// is the normal momentum the re-contact takes away, inelastically (restitution 0: the theta-scheme's
// modified normal displacement, §5). With the scheme's Delassus operator on the normal unknowns of
// the closed points, W_nn = H_n^T (M + h theta C + h^2 theta^2 K)^-1 H_n at h = T / N_s (the
// velocity an impulse gives them in one step), each period loses 1/2 J^T W_nn J:
//   impact power       P_I(q) = J(q)^T W_nn J(q) / (2 T)                                   (7.6)
// and the balance reads P_R - P_c - P_I. J vanishes up to q_sep and grows like (q - q_sep)^{3/2}
// past it, so a balance near lift-off (the 3-DOF cases) moves little; one far above it (a pad
// at V = 10 m/s, without P_I at ~80 q_sep) comes down by the losses.
// q0 is the first q where P_R - P_c (- P_I) changes sign from + to -: a scan of n_scan points up to
// q_max = factor * q_sep (q_sep = min_c N_c / |psi_c|, the first lift-off), then bisection.
// Without a crossing the range doubles (-energy_extend times) before the estimate gives up and
// names the option to change.
// It gives the shooting guess Z0 = (U_e + q0 Re phi, -q0 omega Im phi), T0 = 2 pi / omega (7.5).
// Options prefix "energy_". Cost O(n_scan * samples * n_c) on replicated contact data.
#pragma once

#include "squeal/io/h5.h"
#include "squeal/stability/stability.h"

#include <Eigen/SparseCore>

#include <functional>
#include <vector>

namespace squeal {

struct EnergyEstimate {
  PetscInt               mode = -1; // index into the stability table
  PetscReal              omega = 0, sigma = 0, q_sep = 0, q0 = 0, T0 = 0;
  PetscReal              q_max_factor = 0;  // the factor finally scanned (after any doublings)
  PetscInt               extensions = 0;    // doublings of the scan range used
  bool                   found = false; // a + to - crossing exists in the scan range
  std::vector<PetscReal> q, P_damping, P_reactions, P_impacts; // P_impacts empty with -energy_impacts false
  bool                   impacts = false; // the balance holds the impact losses (7.6)
  PetscInt               impact_steps = 0; // N_s of the Delassus operator W_nn
  PetscReal              P_R0 = 0, P_c0 = 0, P_I0 = 0; // the mean powers at q0 (W)
  // The estimate's motion in DOF terms, for comparison with a transient: the largest amplitude
  // q0 |phi_j| over all DOFs and its DOF j.
  PetscReal              dof_amplitude = 0;
  PetscInt               dof = -1;
  VecH                   U0, dU0; // the shooting guess Z0
};

// A root of f in [lo, hi] with f(lo) = f_lo > 0 >= f(hi) = f_hi: the bracket narrowed to
// 2^-halvings of its width (or to adjacent doubles) by regula falsi with the Illinois rule and a
// bisection every third step unless the two before it halved it; *evaluations: the calls of f.
PetscReal BracketedRoot(const std::function<PetscReal(PetscReal)> &f, PetscReal lo, PetscReal f_lo, PetscReal hi, PetscReal f_hi, PetscInt halvings,
                        PetscInt *evaluations = nullptr);

class EnergyAnalysis {
public:
  explicit EnergyAnalysis(MPI_Comm comm) : comm_(comm) {}
  // -energy_mode, -energy_n_scan, -energy_samples, -energy_q_max_factor, -energy_bisections,
  // -energy_extend, -energy_all_modes, -energy_impacts, -energy_impact_steps
  PetscErrorCode SetFromOptions();
  // Estimates the amplitude for the chosen (default: most unstable) mode. A stable equilibrium is
  // not an error: est.mode stays -1.
  PetscErrorCode Estimate(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab, EnergyEstimate &est);
  // P_R - P_c (- P_I with impacts) at amplitude q for the current mode data (after Estimate's set-up).
  PetscReal      PowerBalance(PetscReal q) const;
  // The mean powers at amplitude q: reactions P_R, impact losses P_I (0 without impacts), and the
  // tensile impulses J_c per closed point of the equilibrium (in eq.active's order) if J is given.
  void           Powers(PetscReal q, PetscReal *P_R, PetscReal *P_I, std::vector<PetscReal> *J = nullptr) const;
  // W_nn of (7.6) on the closed points (eq.active's order); empty without impacts.
  // Sparse: the integrator's W keeps its dropped entries out (-theta_delassus_drop) on many contacts.
  const Eigen::SparseMatrix<PetscReal> &NormalDelassus() const { return Wn_; }
  PetscErrorCode View(const EnergyEstimate &est, PetscViewer viewer) const;
  PetscErrorCode Write(const EnergyEstimate &est, io::H5Writer &out) const;

  PetscInt  mode = -1, n_scan = 2000, samples = 4000, bisections = 60, extend = 4;
  PetscReal q_max_factor = 50;
  PetscBool all_modes = PETSC_FALSE; // estimate every unstable mode, not only the chosen one (app)
  // Impact losses in the balance (7.6): within 1.4x of the settled level on the FE pads (without them
  // up to 69x) and the 3-DOF Newton counts unchanged (docs/user-guide.md).
  PetscBool impacts = PETSC_TRUE;
  // N_s of W_nn (h = T / N_s); PETSC_DECIDE: shooting's default for the model (Shooting::DefaultSteps)
  PetscInt  impact_steps = PETSC_DECIDE;
  // false: stop the scan at its first balance (the same q0; q, P_* hold the points up to it). The
  // app sets it when the estimate is only shooting's start (-analyses without energy): the full
  // curve to q_max is then 94 % of the cost on case 1 and nobody reads it.
  bool      full_scan = true;

private:
  PetscErrorCode SetUpImpacts(const Model &model, const SlidingEquilibrium &eq, EnergyEstimate &est);
  // Scan (0, factor q_sep] and bisect the first + to - crossing; *found false if there is none.
  // Collective: polls the interrupt (every rank scans the same replicated points).
  PetscErrorCode Scan(PetscReal factor, EnergyEstimate &est, bool *found) const;
  PetscErrorCode AgreeOnScan(EnergyEstimate &est) const; // rank 0's scan, q0 and found on every rank

  MPI_Comm                            comm_;
  const ContactSet                   *cs_ = nullptr;
  PetscReal                           omega_ = 0, cphi_ = 0, period_ = 0;
  Eigen::SparseMatrix<PetscReal>      Wn_; // W_nn on the closed points; empty: no impact losses
  mutable std::vector<PetscReal>      J_;  // work: the tensile impulses
  std::vector<PetscReal>              N_, speed_;           // per point: N_c, V_c
  std::vector<std::complex<PetscReal>> psi_, phit_, phib_; // per point
  std::vector<PetscReal>              cos_, sin_;           // samples of one period
};

} // namespace squeal
